"""Where the first run's kernel compiles go: a shot at a small size (voxelise, simulate, surface)
with an empty Warp kernel cache, every Warp module's load timed, split into Python code
generation and the compiler (NVRTC on a GPU, clang on the CPU), each stage's time, and how long
after the start the first simulated frame was written (on a GPU the run's modules, the solver's
and the surfacer's, compile on threads from its start: mpmfx/stages/kernels.py, so their loads
overlap the stages and each other). One table, worst first.

    python lab/first_use.py [hero_castle] [--device cuda:0] [--grid 32] [--frames 2]
"""

import argparse
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

import warp as wp
import warp._src.build as wp_build
from warp._src.context import Module

import mpmfx.stages.simulate as simulate_stage
from mpmfx.bench.report import print_table
from mpmfx.bench.shots import run_shot, smoke_overrides

LOADS: dict[str, float] = defaultdict(float)
COMPILES: dict[str, float] = defaultdict(float)
CPU: dict[str, float] = defaultdict(float)  # the loading thread's CPU seconds (clang and NVRTC run in it)
_current = threading.local()  # the module a thread is loading (the surfacer's load on threads of their own)


def _timed(fn, book, name_of):
    def wrapper(*args, **kw):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kw)
        finally:
            book[name_of(args)] += time.perf_counter() - t0

    return wrapper


def _owner(name: str) -> str:
    """Whose module: the surfacer's, the solver's (its scene-specialised modules are named
    mpmfx_mpm_...), or another (Warp's own, the bench's)."""
    if name.startswith("mpmfx.surface"):
        return "surfacer"
    return "solver" if name.startswith(("mpmfx.mpm", "mpmfx_mpm")) else "other"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shot", nargs="?", default="hero_castle")
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--grid", type=int, default=32)
    ap.add_argument("--frames", type=int, default=2)
    a = ap.parse_args()
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="warp-cold-")  # nothing compiled yet
    wp.init()

    load = Module.load

    def load_named(self, *args, **kw):
        _current.name = self.name
        c0 = time.thread_time()
        try:
            return _timed(load, LOADS, lambda _a: self.name)(self, *args, **kw)
        finally:
            CPU[self.name] += time.thread_time() - c0

    Module.load = load_named
    for fn in ("build_cuda", "build_cpu"):
        setattr(wp_build, fn, _timed(getattr(wp_build, fn), COMPILES, lambda _a: getattr(_current, "name", "?")))
    t0 = time.perf_counter()
    first: list[float] = []  # when simulate's first frame (the initial state) went to its writer
    write = simulate_stage._write_frame

    def write_frame(*args):
        first.append(first[0] if first else time.perf_counter() - t0)
        return write(*args)

    simulate_stage._write_frame = write_frame
    with tempfile.TemporaryDirectory() as cache:
        row = run_shot(
            a.shot, [a.frames], overrides=smoke_overrides(a.grid, a.frames), cache=Path(cache), device=a.device
        )
    wall = time.perf_counter() - t0
    stages = {k: v["seconds"] for k, v in row["stages"].items()}
    rows = [
        {
            "module": n,
            "load_s": round(s, 2),
            "compiler_s": round(COMPILES[n], 2),
            "codegen_etc_s": round(s - COMPILES[n], 2),
            "cpu_s": round(CPU[n], 2),
        }
        for n, s in sorted(LOADS.items(), key=lambda kv: -kv[1])
        if s > 0.05
    ]
    print_table(rows, ["module", "load_s", "compiler_s", "codegen_etc_s", "cpu_s"])
    for owner in ("surfacer", "solver", "other"):
        names = [n for n in LOADS if _owner(n) == owner]
        print(
            f"{owner}: {len(names)} modules, load {sum(LOADS[n] for n in names):.1f} s, "
            f"compiler {sum(COMPILES[n] for n in names):.1f} s, CPU {sum(CPU[n] for n in names):.1f} s"
        )
    print(
        f"{a.shot} grid {a.grid}, {a.frames} frames on {a.device}: wall {wall:.1f} s, module loads "
        f"{sum(LOADS.values()):.1f} s ({len(LOADS)} modules, compiled ahead on threads on a GPU), "
        f"of which the compiler {sum(COMPILES.values()):.1f} s; the first frame after {first[0]:.1f} s; "
        f"stage seconds {stages}"
    )


if __name__ == "__main__":
    main()
