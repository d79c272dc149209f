"""The Warp kernels a run will launch, compiled ahead on threads from its start.

On a machine that has not run mpmfx, every Warp module is compiled when a kernel of it is first
launched, one module after another: on one H200 a small hero_castle run spent about 99 s so
(`lab/first_use.py`, docs/benchmarks.md). A GPU run starts compiling, when it starts, every module
its stages will launch on the device: the solver's (only the variants its scene uses:
mpmfx.mpm.modules) and, when it will surface, the surfacer's (all but the CPU-only ones:
mpmfx.surface.kernel_modules), each module on a thread of its own (NVRTC runs outside the GIL;
Warp generates each module's code under its own lock), so they are ready, or nearly, when each
stage starts: `wait(stage)` before its first launch. Compiled modules stay in Warp's kernel
cache: a later run loads them in well under a second, and says nothing. CPU runs keep Warp's lazy
compiles: their cores are busy with the solver. Instead, `bash setup.sh` compiles the surfacer's
CPU kernels once, on every core (`python -m mpmfx.stages.kernels`).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor

import warp as wp

import mpmfx.surface  # noqa: F401  (registers the surfacer's Warp modules)
from mpmfx.stages import simulate
from mpmfx.stages.base import quiet_warp
from mpmfx.surface.kernel_modules import device_modules

__all__ = ["ShotKernels"]

WORKERS = 16  # compiler threads at most (one module each; a run has about thirty)
GROUPS = ("simulate", "surface")  # the stages that launch Warp kernels of their own, in run order


class ShotKernels:
    """Compiles the Warp modules of a run's stages for `device` on threads from `start()`.

    groups: stage name -> [(warp.Module, block_dim or None)], the modules that stage launches
    (block_dim: the threads a block its kernels launch with, None for Warp's default).
    `wait(stage)` blocks until that stage's modules are ready; while it blocks it shows one
    progress line (first use only; nothing when every module came from the cache)."""

    def __init__(self, device: str | None, groups: dict[str, list]):
        self.device = device
        self.groups = {name: list(mods) for name, mods in groups.items() if mods}
        self._futures: dict[str, list[Future]] = {}
        self._pool: ThreadPoolExecutor | None = None
        self._done = 0  # modules ready, of every group
        self._lock = threading.Lock()
        self._announced = False
        self._failed: list[str] = []

    @classmethod
    def for_run(cls, shot, device: str | None, stages) -> "ShotKernels":
        """The modules of those of `stages` ("simulate", "surface") that will run kernels."""
        quiet_warp(device)
        groups = {}
        if not wp.get_device(device).is_cuda:  # (a CPU run compiles as it launches)
            return cls(device, groups)
        if "simulate" in stages:
            try:
                groups["simulate"] = simulate.kernel_modules(shot, device)
            except Exception:  # (a scene the solver refuses: the stage says why when it runs)
                pass
        if "surface" in stages:
            groups["surface"] = [(m, None) for m in device_modules(device)]
        return cls(device, groups)

    @property
    def total(self) -> int:
        return sum(len(mods) for mods in self.groups.values())

    def start(self, *, ahead: bool | None = None) -> "ShotKernels":
        """Start compiling; ahead: whether to (default: on a GPU only)."""
        quiet_warp(self.device)
        if ahead is None:
            ahead = wp.get_device(self.device).is_cuda
        if not self.groups or not ahead:
            return self
        dev = wp.get_device(self.device)
        self._pool = ThreadPoolExecutor(
            min(WORKERS, os.cpu_count() or 1, self.total), thread_name_prefix="mpmfx-kernels"
        )
        for name in GROUPS:  # the stage that runs first, first
            self._futures[name] = [self._pool.submit(self._load, dev, m, bd) for m, bd in self.groups.get(name, [])]
        self._pool.shutdown(wait=False)
        return self

    def _load(self, device, module, block_dim) -> None:
        try:
            wp.force_load(device=device, modules=[module], block_dim=block_dim, max_workers=0)
        except Exception as exc:  # said by wait(): the stage then compiles it as it launches
            self._failed.append(f"{module.name}: {exc}")
        with self._lock:
            self._done += 1

    def wait(self, stage: str) -> None:
        """Until `stage`'s modules are ready (at once where none were asked for, or on a CPU)."""
        futures = self._futures.pop(stage, [])
        if not futures:
            return
        if not all(f.done() for f in futures):
            t0, tty = time.perf_counter(), sys.stdout.isatty()
            said = f"[{stage}] " + (
                "waiting for the rest ..."
                if self._announced
                else f"compiling {self.total} GPU kernel modules (first use; cached after) ..."
            )
            self._announced = True  # announced once a run
            print(said, end="", flush=True)
            shown = -1
            while not all(f.done() for f in futures):
                time.sleep(0.25)
                if tty and self._done != shown:  # one line, rewritten as modules finish
                    shown = self._done
                    print(f"\r{said} {shown}/{self.total}", end="", flush=True)
            tail = "" if tty else f" {self._done}/{self.total}"
            print(f"{tail} (waited {time.perf_counter() - t0:.0f} s)", flush=True)
        for f in futures:
            f.result()
        if self._failed:
            print(
                f"[{stage}] compiling ahead failed ({'; '.join(self._failed)}); compiling as launched", file=sys.stderr
            )
            self._failed = []


def compile_now(device: str = "cpu") -> float:
    """The surfacer's modules for `device`, on every core; the seconds it took."""
    quiet_warp(device)
    t0 = time.perf_counter()
    wp.force_load(device=device, modules=device_modules(device), max_workers=os.cpu_count() or 1)
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"surfacer kernels ready for the CPU in {compile_now('cpu'):.0f} s (kept in Warp's kernel cache)")
