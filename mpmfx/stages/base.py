"""What every stage module provides, and the context a stage runs in."""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import tempfile
import threading
from dataclasses import dataclass, field
from typing import Protocol

import warp as wp
from tqdm import tqdm

from mpmfx.cache import Entry
from mpmfx.config import Shot
from mpmfx.stages.parallel import FrameJob, Frames


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
    warnings: list[str] = field(default_factory=list)  # `warn`'s: the closing table repeats them
    executor: Frames | None = None  # where independent frames run (None: here, one by one)
    state: str = "ran"  # "ran" (a new entry) or "resumed" (complete frames were there)
    followed: list = field(default_factory=list)  # frames' results made while upstream ran (stages.follow)

    def job(self) -> FrameJob:
        return FrameJob.of(self.shot, self.entry, self.upstream, self.device)

    def map_frames(self, fn, frames: list[int], *, desc: str = "", auto: bool = True, serial=None) -> list:
        """fn(self.job(), f) for each frame, serially or as Dask tasks (`mpmfx.stages.parallel`;
        auto=False: tasks only when workers or a scheduler were asked for; serial: how they run
        here then, see Frames.map)."""
        job = self.job()
        return (self.executor or Frames(workers=1)).map(
            fn, [(job, f) for f in frames], auto=auto, serial=serial, desc=desc or self.entry.stage, quiet=self.quiet
        )

    def progress(self, iterable, *, total: int | None = None, desc: str = "", unit: str = "frame"):
        """A progress bar over frames on stderr (silent when quiet or not a terminal in tests)."""
        if self.quiet:
            return iterable
        return tqdm(
            iterable,
            total=total,
            desc=f"{desc or self.entry.stage:>9}",
            unit=unit,
            file=sys.stderr,
            leave=False,
            dynamic_ncols=True,
        )

    def warn(self, message: str) -> None:
        """Say `message` now, on a line of its own above any progress bar, and keep it for the
        run's closing table (and the entry's manifest, so a cached run says it again)."""
        self.notes.append(message)
        self.warnings.append(message)
        tqdm.write(f"[{self.entry.stage}] warning: {message}", file=sys.stderr)


class Stage(Protocol):
    NAME: str
    VERSION: int
    PER_FRAME: bool  # output is one file per frame (else one result for the shot)
    FRAME_EXT: str
    CODE: tuple[str, ...]  # the modules its output depends on: the key hashes exactly these

    def params(self, shot: Shot) -> dict: ...  # the stage's own parameters (key inputs)
    def inputs(self, shot: Shot) -> dict[str, str]: ...  # input files: name -> sha256
    def run(self, ctx: Context) -> dict: ...  # writes into ctx.entry; returns manifest extras


class Turns:
    """A lock granted in the order it was asked for (threading.Lock is not fair: a thread that
    releases and asks again at once can keep it for ever while another waits)."""

    def __init__(self):
        self._cv = threading.Condition()
        self._next = self._serving = 0

    @contextlib.contextmanager
    def turn(self):
        with self._cv:
            ticket, self._next = self._next, self._next + 1
            self._cv.wait_for(lambda: self._serving == ticket)
        try:
            yield
        finally:
            with self._cv:
                self._serving += 1
                self._cv.notify_all()


# One thread at a time launches work on a GPU. Warp's current stream is the device's, not the
# thread's, and its array.numpy() swaps it for the null stream and back: two threads doing so at
# once can leave the device on the null stream, where the solver's next CUDA graph capture fails
# ("unknown stream"); a capture would also take in the other thread's launches. The simulate
# stage takes a turn for each frame's substeps and host copies, the frames that follow it
# (mpmfx.stages.follow) one for each frame's surfacing: host work (reading, deflating, writing,
# exporting) overlaps, the device's work alternates.
_GPU = Turns()


def device_turn(device: str | None):
    """A turn on `device` (a context manager): exclusive on a GPU, free on the CPU."""
    return _GPU.turn() if wp.get_device(device).is_cuda else contextlib.nullcontext()


NO_DRIVER = "Could not find or load the NVIDIA CUDA driver"  # Warp's native line on a CPU machine


def quiet_warp(device: str | None = None) -> None:
    """Silence Warp's start-up banner and per-module compile lines (the stage has its own progress
    bar), start it without its no-driver warning (a CPU machine is a supported one, not a fault),
    and check that the asked-for device exists before any kernel is built."""
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # Warp 1.19 prints module loads at INFO
    _init_without(NO_DRIVER)
    if device and device.startswith("cuda") and not wp.is_cuda_available():
        raise StageError(
            "--device cuda: Warp finds no CUDA device or driver on this machine; "
            "run with --device cpu (the same kernels, slower) or on a GPU machine"
        )


@functools.cache
def _init_without(line: str) -> None:
    """wp.init() with its native stderr captured, and written back less the lines holding
    `line` (the library prints them from C, past Python's sys.stderr and Warp's own settings).
    Once per process (cached): Warp starts once, and per-frame jobs call quiet_warp."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        text = captured.read().decode(errors="replace")
    sys.stderr.write("".join(s for s in text.splitlines(keepends=True) if line not in s))
