"""Where an advance()'s time goes beyond its kernels (GPU): the bench's scene and interval
(`bench gpu`'s run_case warm-up), then one timed advance split into the host's pieces.

    PYTHONPATH=/opt/wp/site:$PWD python3 scripts/advance_probe.py Mushy:128 Mushy:256

Per case: wall ms of the advance, of its chunks (launch to the clock's read-back, which
waits for the GPU), of the wear read-back, of the report (its device sums and elastic
energy), and the rest; then the same scene over one 1/24 s frame (a shot's advance).
"""
import sys
import time

import numpy as np
import warp as wp

from mpmfx.bench import gpu as bench
from mpmfx.mpm import Solver, SolverConfig

DEVICE = __import__("os").environ.get("DEVICE", "cuda:0")


def timed(obj, name, acc, key):
    fn = getattr(obj, name)

    def wrap(*a, **k):
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            acc[key] = acc.get(key, 0.0) + time.perf_counter() - t
            acc[key + "_n"] = acc.get(key + "_n", 0) + 1
    setattr(obj, name, wrap)


def case(name: str, grid_n: int):
    mats, parts, colliders = bench.scene(name, grid_n)
    cfg = SolverConfig(grid_n=grid_n)
    solver = Solver(mats, cfg, colliders=colliders, device=DEVICE)
    da = solver._device_advance
    state = solver.init_state(parts)
    c = max(m.wave_speed() for m in mats)
    span = bench.SUBSTEPS * cfg.cfl * cfg.dx / c
    for i in range(2):
        solver.advance(state, i * span, (i + 1) * span)
    da.sort_every = state.clock.sort_every or da.last_sort_every
    for i in (2, 3):
        solver.advance(state, i * span, (i + 1) * span)
    acc: dict = {}
    timed(da, "_chunk", acc, "chunk_launch")
    timed(solver, "_report", acc, "report")
    timed(da, "_upload", acc, "upload")
    if hasattr(da, "_read_back"):
        timed(da, "_read_back", acc, "read_back")
    orig_numpy = wp.array.numpy

    def numpy_timed(self):
        t = time.perf_counter()
        try:
            return orig_numpy(self)
        finally:
            key = "clock_readback" if self is da.clk else ("frag_readback" if da._brick is not None and self is da._brick.frag
                                                            else "other_readback")
            acc[key] = acc.get(key, 0.0) + time.perf_counter() - t
            acc[key + "_n"] = acc.get(key + "_n", 0) + 1
    wp.array.numpy = numpy_timed
    try:
        wp.synchronize()
        t0 = time.perf_counter()
        rep = solver.advance(state, 4 * span, 5 * span)
        wp.synchronize()
        wall = time.perf_counter() - t0
    finally:
        wp.array.numpy = orig_numpy
    k = rep.substeps + rep.rejected_substeps
    parts_ms = {key: 1e3 * v for key, v in acc.items() if not key.endswith("_n")}
    print(f"{name} {grid_n}^3 n={state.n} substeps={k} wall={1e3 * wall:.3f} ms ({1e3 * wall / k:.4f} ms/substep) "
          f"G/s={state.n * rep.substeps / wall / 1e9:.3f}")
    for key, v in sorted(parts_ms.items()):
        print(f"   {key:16s} {v:8.3f} ms  x{acc[key + '_n']}")
    inner = ("other_readback", "clock_readback") if "read_back" in parts_ms else ("other_readback",)
    print(f"   {'rest':16s} {1e3 * wall - sum(v for kk, v in parts_ms.items() if kk not in inner):8.3f} ms")
    # the pieces of the report alone, the GPU idle
    if hasattr(solver, "report_sums"):  # one reduction for the report
        pieces = [("report_sums", lambda: solver.report_sums(state))]
    else:
        from mpmfx.mpm import stepper
        pieces = [("report_sums", lambda: stepper.report_sums(state, solver.device)),
                  ("elastic_energy", lambda: solver.elastic_energy(state))]
    for label, fn in pieces + [("clk.numpy idle", lambda: da.clk.numpy())]:
        fn()
        wp.synchronize()
        t = time.perf_counter()
        for _ in range(20):
            fn()
        print(f"   {label:16s} {1e3 * (time.perf_counter() - t) / 20:8.3f} ms idle")
    # the host's own time by function over one more interval (the GPU waits show in numpy / synchronize)
    import cProfile
    import pstats
    prof = cProfile.Profile()
    wp.synchronize()
    prof.enable()
    solver.advance(state, 5 * span, 6 * span)
    wp.synchronize()
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(12)
    # a shot's advance: one 1/24 s frame (many more substeps per read-back and report)
    t1 = 6 * span
    solver.advance(state, t1, t1 + 1 / 24)  # (captures any new chunk lengths)
    t1 += 1 / 24
    wp.synchronize()
    t0 = time.perf_counter()
    rep = solver.advance(state, t1, t1 + 1 / 24)
    wp.synchronize()
    wall = time.perf_counter() - t0
    k = rep.substeps + rep.rejected_substeps
    print(f"   frame 1/24 s: substeps={k} wall={1e3 * wall:.2f} ms ({1e3 * wall / k:.4f} ms/substep) "
          f"G/s={state.n * rep.substeps / wall / 1e9:.3f}", flush=True)


if __name__ == "__main__":
    wp.init()
    for arg in sys.argv[1:] or ["Mushy:128"]:
        n, g = arg.split(":")
        case(n, int(g))
