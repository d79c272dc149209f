"""What every stage module provides, and the context a stage runs in."""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Protocol

from mpmfx.cache import Entry
from mpmfx.config import Shot


class StageError(RuntimeError):
    """A stage could not produce its output; the message says what to change. Exit code 1."""


@dataclass
class Context:
    """Everything one stage run may read. `frames` are the frames asked for (all for the shot)."""

    shot: Shot
    entry: Entry
    upstream: dict[str, Entry]
    frames: list[int]
    device: str | None = None
    quiet: bool = False
    notes: list[str] = field(default_factory=list)

    def progress(self, iterable, *, total: int | None = None, desc: str = "", unit: str = "frame"):
        """A progress bar over frames on stderr (silent when quiet or not a terminal in tests)."""
        if self.quiet:
            return iterable
        from tqdm import tqdm
        return tqdm(iterable, total=total, desc=f"{desc or self.entry.stage:>9}", unit=unit,
                    file=sys.stderr, leave=False, dynamic_ncols=True)

    def warn(self, message: str) -> None:
        self.notes.append(message)
        print(f"[{self.entry.stage}] warning: {message}", file=sys.stderr)


class Stage(Protocol):
    NAME: str
    VERSION: int
    PER_FRAME: bool          # output is one file per frame (else one result for the shot)
    FRAME_EXT: str
    CODE: tuple[str, ...]    # the modules its output depends on: the key hashes exactly these

    def params(self, shot: Shot) -> dict: ...               # the stage's own parameters (key inputs)
    def inputs(self, shot: Shot) -> dict[str, str]: ...     # input files: name -> sha256
    def run(self, ctx: Context) -> dict: ...                # writes into ctx.entry; returns manifest extras



def quiet_warp(device: str | None = None) -> None:
    """Silence Warp's start-up banner and per-module compile lines (the stage has its own progress
    bar), and check that the asked-for device exists before any kernel is built."""
    import warp as wp
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # Warp 1.19 prints module loads at INFO
    if device and device.startswith("cuda") and not wp.is_cuda_available():
        raise StageError("--device cuda: Warp finds no CUDA device or driver on this machine; "
                         "run with --device cpu (the same kernels, slower) or on a GPU machine")
