"""A frame's trip off the device: the simulate stage's host copies (a checkpoint and the frame's
arrays) into fresh host arrays, against HostStaging's reused, page-locked buffers
(mpmfx/mpm/readback.py). Checks that both give the same arrays, bit for bit, after the particles
were re-sorted (storage order != particle order); one table of milliseconds a frame.

    python lab/readback_gpu.py [--device cuda:0] [--particles 3000000] [--grid 256] [--reps 5]
"""

import argparse
import time

import numpy as np
import warp as wp
from collider_cost import snow_block

from mpmfx.bench.report import print_table
from mpmfx.mpm import Solver, SolverConfig, preset
from mpmfx.mpm.readback import HostStaging

FPS = 24.0


def timed(fn, reps: int) -> tuple[float, dict]:
    out = fn()  # warm: compiles, first allocations
    t0 = time.perf_counter()
    for _ in range(reps):
        out = fn()
    return (time.perf_counter() - t0) / reps, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--particles", type=int, default=3_000_000)
    ap.add_argument("--grid", type=int, default=256)
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args()
    wp.config.quiet = True
    rows = []
    for material in ("Mushy", "Water"):
        s = Solver([preset(material)], SolverConfig(grid_n=a.grid), device=a.device)
        st = s.init_state(snow_block(a.particles, a.grid))
        s.advance(st, 0.0, 2.0 / FPS)  # sorted at least once: storage order is not particle order
        staging = HostStaging(s.device)
        fresh_s, fresh = timed(lambda: s.checkpoint(st, 0.0), a.reps)
        staged_s, staged = timed(lambda: s.checkpoint(st, 0.0, staging), a.reps)
        same = all(np.array_equal(fresh[k], staged[k]) for k in fresh)
        rows.append(
            {
                "material": material,
                "particles": st.n,
                "permuted": bool(st.permuted),
                "MB": round(sum(v.nbytes for v in fresh.values()) / 1e6, 1),
                "fresh_ms": round(1e3 * fresh_s, 1),
                "staged_ms": round(1e3 * staged_s, 1),
                "identical": same,
            }
        )
    print_table(rows, list(rows[0]))


if __name__ == "__main__":
    main()
