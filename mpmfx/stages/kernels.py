"""The surfacer's Warp kernels, compiled ahead on threads while the shot simulates.

On a machine that has not run mpmfx, every Warp module is compiled when a kernel of it is first
launched, one module after another. On one H200 a small hero_castle run spends about 99 s so, 88 s
of it in the surfacer's modules (the largest 32 s), none of which the solver needs
(`lab/first_use.py`, docs/benchmarks.md). A GPU run that will surface starts compiling all of them
at once when it starts, on threads (NVRTC runs outside the GIL; Warp generates each module's code
under its own lock), so they are ready, or nearly, when the surface stage starts. Compiled
modules stay in Warp's kernel cache: a later run loads them in well under a second. CPU runs keep
Warp's lazy compiles: their cores are busy with the solver. Instead, `bash setup.sh` compiles the
surfacer's CPU kernels once, on every core (`python -m mpmfx.stages.kernels`): on the 2-core CPU
they take about 170 s of clang one after another, which a first demo would otherwise wait for.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import warp as wp

import mpmfx.surface  # noqa: F401  (registers the surfacer's Warp modules)
from mpmfx.stages.base import quiet_warp

__all__ = ["SurfacerKernels"]

WORKERS = 16  # compiler threads at most (one module each; the surfacer has about twenty)


class SurfacerKernels:
    """Compiles the surfacer's modules for `device` on a background thread from `start()`;
    `wait()` blocks until they are ready and says how long it waited (first use only)."""

    def __init__(self, device: str | None):
        self.device = device
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def start(self) -> "SurfacerKernels":
        quiet_warp(self.device)
        if not wp.get_device(self.device).is_cuda:
            return self
        self._thread = threading.Thread(target=self._load, name="mpmfx-kernels", daemon=True)
        self._thread.start()
        return self

    def _load(self) -> None:
        try:
            _load_surfacer(self.device, min(WORKERS, os.cpu_count() or 1))
        except BaseException as exc:  # said by wait(): the surface stage then compiles as it goes
            self._error = exc

    def wait(self) -> None:
        if self._thread is None:
            return
        t0 = time.perf_counter()
        if self._thread.is_alive():
            print("[surface] waiting for its GPU kernels to finish compiling (first use on this machine) ...")
        self._thread.join()
        waited = time.perf_counter() - t0
        if waited > 1.0:
            print(f"[surface] kernels ready after {waited:.0f} s more; later runs load them from Warp's cache")
        if self._error is not None:
            print(f"[surface] compiling ahead failed ({self._error}); compiling as frames need them", file=sys.stderr)
        self._thread = None


def _load_surfacer(device: str | None, workers: int) -> None:
    """Compile (or load from Warp's cache) every surfacer module for `device`, `workers` at once."""
    wp.load_module("mpmfx.surface", device=wp.get_device(device), recursive=True, max_workers=workers)


def compile_now(device: str = "cpu") -> float:
    """The surfacer's modules for `device`, on every core; the seconds it took."""
    quiet_warp(device)
    t0 = time.perf_counter()
    _load_surfacer(device, os.cpu_count() or 1)
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"surfacer kernels ready for the CPU in {compile_now('cpu'):.0f} s (kept in Warp's kernel cache)")
