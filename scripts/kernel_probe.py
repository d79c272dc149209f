"""Timing probes (not product paths), on the GPU:

1. where the brick P2G's deterministic mode loses time against the fast one, on hero_dam:
   after two frames with the shipped kernel, each variant swaps one piece of the int64 window
   for a cheaper, WRONG one for one timed quarter frame (only its time is read): 32-bit shared
   atomics, plain (racy) adds, no global flush;
2. G2P (and, by kernel_caps("scatter", ...), the brick P2G's scatter) under register caps.

    python3 scripts/kernel_probe.py --out $OUT
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parent)]


SMOKE = ["domain.grid_n=32", "domain.origin=[-1.0, -0.1875, -1.0]"] if "--smoke" in sys.argv else []
DEVICE = "cpu" if "--smoke" in sys.argv else "cuda"


import warp as wp  # noqa: E402

import mpmfx.mpm.p2g_brick as pb  # noqa: E402

_Q = dict(T="long long", A="unsigned long long", N=pb.WIN_NODES)
_ATOM32 = pb._WINDOW.replace("atomicAdd(({A}*)&win[e], ({A})value);",
                             "atomicAdd((unsigned int*)&win[e], (unsigned int)value);")
_PLAIN = pb._WINDOW.replace("atomicAdd(({A}*)&win[e], ({A})value);", "win[e] += value;")
_NOFLUSH = pb._WINDOW.replace("return win[e];", "return op == 2 ? 0 : win[e];")


@wp.func_native(_ATOM32.format(**_Q))
def window_q_atom32(op: int, e: int, value: wp.int64) -> wp.int64: ...


@wp.func_native(_PLAIN.format(**_Q))
def window_q_plain(op: int, e: int, value: wp.int64) -> wp.int64: ...


@wp.func_native(_NOFLUSH.format(**_Q))
def window_q_noflush(op: int, e: int, value: wp.int64) -> wp.int64: ...


def kernel_caps(kernel_name: str, grid_n: int = 128, name: str = "Mushy", caps=(None, 96, 80, 72),
                block: int | None = None) -> list[dict]:
    """Device ms a substep of the kernel `kernel_name` ("g2p", or the brick P2G's "scatter") in the
    `name` block of mpmfx bench gpu, compiled under each register cap (None: the compiler's own);
    block: G2P's threads a block (g2p.G2P_BLOCK) for the probe."""
    from mpmfx.bench.gpu import scene
    from mpmfx.mpm import Solver, SolverConfig
    from mpmfx.mpm import g2p as g2p_mod
    from shot_profile import kernel_split
    kernel, rows = wp.kernel, []
    for cap in caps:
        def capped(*a, **kw):
            def deco(f):
                if f.__name__ != kernel_name:
                    return kernel(*a, **kw)(f)
                opts = {**kw, "cuda_max_registers": cap, "module": kw["module"] + f"_cap{cap}"}
                if kernel_name == "g2p":  # the renamed module keeps G2P's fast math
                    wp.set_module_options({"fast_math": g2p_mod.G2P_FAST_MATH}, module=opts["module"])
                if cap is None:
                    opts.pop("cuda_max_registers")
                return kernel(*a, **opts)(f)
            return deco
        wp.kernel = capped  # (both kernels are built lazily: at the solver's construction / first scatter)
        block0 = g2p_mod.G2P_BLOCK
        g2p_mod.G2P_BLOCK = block or block0
        g2p_mod.make_g2p.cache_clear()
        pb.make_brick_scatter.cache_clear()
        try:
            mats, parts, _ = scene(name, grid_n)
            solver = Solver(mats, SolverConfig(grid_n=grid_n, deterministic=False), device=DEVICE)
            state = solver.init_state(parts)
            span = 32 * solver.config.cfl * solver.config.dx / max(m.wave_speed() for m in mats)
            solver.advance(state, 0.0, span)
        finally:
            wp.kernel = kernel
        ms, rep = kernel_split(solver, state, span, 2 * span)
        g2p_mod.G2P_BLOCK = block0
        k = max(1, rep.substeps + rep.rejected_substeps)
        rows.append({"probe": f"{kernel_name} cap, {name}", "variant": f"{cap}/{block or 'default'}", "n": state.n,
                     f"{kernel_name}_ms": sum(v for n, v in ms.items() if kernel_name in n) / k,
                     "total_ms": sum(ms.values()) / k})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main() -> int:
    wp.config.quiet = True
    from p2g_shot import p2g_ms
    from shot_profile import build
    variants = {"int64 window (as shipped)": pb.window_q, "32-bit shared atomics": window_q_atom32,
                "plain (racy) int64 adds": window_q_plain,
                "no global flush (reads 0)": window_q_noflush}
    rows = []
    solver, state, shot = build("hero_dam", SMOKE, Path("/tmp/p2g_shot_cache"), DEVICE)
    solver._device_advance.p2g = "brick"
    for f in range(2):
        solver.advance(state, f / 24, (f + 1) / 24)
    data, t = solver.checkpoint(state, 2 / 24), 2 / 24
    for name, fn in variants.items():
        pb.window_q = fn
        pb.make_brick_scatter.cache_clear()
        st, _ = solver.restore(data)
        solver._device_advance._brick = None
        try:  # ~10 substeps: the wrong variants may blow the state up soon after
            ms = p2g_ms(solver, st, t, t + 5e-4)
        except Exception as err:  # noqa: BLE001 (reported)
            ms = repr(err)[:120]
        rows.append({"probe": "det window", "variant": name, "scatter_ms": ms})
        print(json.dumps(rows[-1]), flush=True)
    pb.window_q = variants["int64 window (as shipped)"]
    rows += kernel_caps("g2p", 16 if SMOKE else 128)
    out = Path(os.environ.get("OUT", "profile_out"))  # as shot_profile.py / p2g_shot.py
    out.mkdir(parents=True, exist_ok=True)
    (out / "kernel_probe.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

