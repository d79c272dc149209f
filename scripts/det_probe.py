"""Timing probe (not a product path): where the brick P2G's deterministic mode loses time
against the fast one, on hero_dam. Each variant swaps one piece of the int64 window for a
cheaper, WRONG one (the timing is all that is read): 32-bit shared atomics, no global flush.

    python3 scripts/det_probe.py --out $OUT        # on the GPU
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


def main() -> int:
    wp.config.quiet = True
    from p2g_shot import p2g_ms
    from shot_profile import build
    variants = {"int64 window (as shipped)": pb.window_q, "32-bit shared atomics": window_q_atom32,
                "plain (racy) int64 adds": window_q_plain,
                "no global flush (reads 0)": window_q_noflush}
    rows = []
    for name, fn in variants.items():
        pb.window_q = fn
        pb.make_brick_scatter.cache_clear()
        solver, state, shot = build("hero_dam", SMOKE, Path("/tmp/p2g_shot_cache"), DEVICE)
        solver._device_advance.p2g = "brick"
        for f in range(2):
            solver.advance(state, f / 24, (f + 1) / 24)
        ms = p2g_ms(solver, state, 2 / 24, 2 / 24 + 1 / 96)
        rows.append({"variant": name, "scatter_ms": ms, "grid_mass": float(solver._grid_fixed.numpy()[..., 0].sum())})
        print(json.dumps(rows[-1]), flush=True)
    Path(os.environ.get("OUT", ".")).joinpath("det_probe.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
