"""Where a bench gpu substep goes outside the kernels Warp times: the brick P2G's sort
(CUB radix sort and scan are not Warp launches, so `bench gpu`'s phase split leaves them in
"host"). Per scene: the cadence the stepper picked, ms a substep with the sort forced every
k substeps, and one sort alone. H100, 2026-11-26 (fast mode; one sort: keys 0.21, radix 0.93,
flags 0.10, scan 0.08, starts 0.12 ms at 19.4M):

    sort every            natural (1)  2     4     8     32
    Mushy 19.4M, ms       7.76         7.28  6.97  6.91  6.76
    Water 19.4M, ms       6.19         6.03  5.52  5.44  5.40 Usage on the GPU machine:

    PYTHONPATH=/opt/wp/site:$PWD python3 scripts/sort_probe.py
"""
import time

import warp as wp

from mpmfx.bench.gpu import scene, sort_ms
from mpmfx.mpm import Solver, SolverConfig

SCENES = [("Mushy", 256), ("Water", 256), ("Mushy", 128), ("Water", 128)]
SUBSTEPS = 50


def interval(solver, state, t, span):
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    r = solver.advance(state, t, t + span)
    wp.synchronize_device(solver.device)
    return 1e3 * (time.perf_counter() - t0) / max(1, r.substeps + r.rejected_substeps), t + span


def main(device="cuda:0", scenes=SCENES):
    wp.init()
    for name, g in scenes:
        mats, parts, colliders = scene(name, g)
        cfg = SolverConfig(grid_n=g, deterministic=False)
        solver = Solver(mats, cfg, colliders=colliders, device=device)
        da = solver._device_advance
        state = solver.init_state(parts)
        c = max(m.wave_speed() for m in mats)
        span = SUBSTEPS * cfg.cfl * cfg.dx / c
        t = 0.0
        for _ in range(2):
            solver.advance(state, t, t + span)
            t += span
        natural = da.last_sort_every
        print(f"{name} grid {g}: {state.n} particles, natural cadence {natural}", flush=True)
        for k in (natural, 1, 2, 4, 8, 32, natural):
            da.sort_every = k
            _, t = interval(solver, state, t, span)  # captures this cadence's graphs
            ms, t = interval(solver, state, t, span)
            print(f"  sort every {k:2d}: {ms:.3f} ms a substep", flush=True)
        da.sort_every = 0
        print(f"  one sort alone: {sort_ms(solver, state, whole=True):.3f} ms", flush=True)


if __name__ == "__main__":
    import sys
    main(*sys.argv[1:2])  # [device]
