"""What a first GPU run compiles before its stages can start, measured without a GPU: the Warp
modules a shot's run compiles ahead (mpmfx.stages.kernels: the solver's for its scene, the
surfacer's for a GPU), each compiled once by NVRTC for a GPU architecture (Warp's compiler
needs no driver) or by clang for the CPU, one after another from an empty kernel cache, timed in
CPU seconds of the compiling thread. A run compiles them side by side on up to 16 threads, so
on a machine with that many cores the longest module bounds the wait. One table, worst first.

    python lab/compile_cost.py [hero_castle] [--arch 90 | --device cpu] [--grid 256]
"""

import argparse
import tempfile
import time
from pathlib import Path

import warp as wp

import mpmfx.surface  # noqa: F401  (registers the surfacer's Warp modules)
from mpmfx.bench.report import print_table
from mpmfx.shotfile import load_shot_config
from mpmfx.stages import simulate
from mpmfx.stages.base import quiet_warp

SHOTS = Path(__file__).resolve().parents[1] / "pipeline" / "shots"


def groups(shot, device: str) -> dict[str, list]:
    """stage -> the Warp modules it launches on `device` (as ShotKernels.for_run lists them)."""
    try:
        from mpmfx.surface.kernel_modules import device_modules

        surfacer = device_modules(device)
    except ImportError:  # (a tree from before the CPU-only kernels had modules of their own: all of them)
        from warp._src.context import user_modules

        import mpmfx.surface  # noqa: F401

        surfacer = [m for n, m in user_modules.items() if n.startswith("mpmfx.surface.")]
    return {"simulate": [m for m, _ in simulate.kernel_modules(shot, device)], "surface": surfacer}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shot", nargs="?", default="hero_castle")
    ap.add_argument("--arch", type=int, default=90, help="GPU architecture (90: H100/H200)")
    ap.add_argument("--device", default=None, help="cpu: clang for the CPU instead")
    ap.add_argument("--grid", type=int, default=256, help="domain.grid_n (picks the brick P2G's variants)")
    a = ap.parse_args()
    quiet_warp()
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="warp-cold-")  # nothing compiled yet
    shot = load_shot_config(SHOTS / f"{a.shot}.toml", [f"domain.grid_n={a.grid}"])
    target = "cpu" if a.device == "cpu" else "cuda:0"
    rows, out = [], tempfile.mkdtemp(prefix="warp-aot-")
    for stage, mods in groups(shot, target).items():
        for m in mods:
            if not m.kernels:  # (functions only: compiled into the modules that call them)
                continue
            c0 = time.thread_time()
            if a.device == "cpu":
                wp.compile_aot_module(m, device="cpu", module_dir=out)
            else:
                wp.compile_aot_module(m, arch=a.arch, module_dir=out, use_ptx=False)
            rows.append({"stage": stage, "module": m.name, "kernels": len(m.kernels), "cpu_s": time.thread_time() - c0})
    rows.sort(key=lambda r: -r["cpu_s"])
    for r in rows:
        r["cpu_s"] = round(r["cpu_s"], 2)
    print_table(rows, ["stage", "module", "kernels", "cpu_s"])
    what = "CPU (clang)" if a.device == "cpu" else f"sm_{a.arch} (NVRTC)"
    for stage in ("simulate", "surface"):
        mine = [r["cpu_s"] for r in rows if r["stage"] == stage]
        print(
            f"{stage}: {len(mine)} modules for {what}, {sum(mine):.1f} CPU s in all, the longest {max(mine, default=0):.1f} s"
        )
    print(f"{a.shot} at grid {a.grid}: {sum(r['cpu_s'] for r in rows):.1f} CPU s one after another")


if __name__ == "__main__":
    main()
