"""Frames per second over a sequence on this machine's cores, ours against splashsurf, both ways
a sequence can use the cores: one frame at a time on all of them, or one frame per core at a
time (as the surface stage's Dask workers run them, one thread each: mpmfx.stages.parallel).
The frames are one 100k-particle case (mpmfx bench surface), each moved by a different
sub-voxel offset so no two frames are the same particles.

    python lab/surface_cpu_throughput.py [--shape torus] [--sampling lattice] [--frames 16] [--out X.json]

Each worker process warms up (a first call, Warp's kernels loaded) and says so before the clock
starts; the time is from the start signal to the last frame done.
"""

import argparse
import json
import multiprocessing as mp
import os
import sys
import time

PEER = "splashsurf"


def frames(shape: str, sampling: str, count: int, n: int):
    import numpy as np

    from mpmfx.bench.surface_cases import sample_shape

    x, h = sample_shape(shape, count, sampling)
    rng = np.random.default_rng(1)
    return [(x + rng.uniform(-0.5, 0.5, 3).astype(np.float32) * h) for _ in range(n)], h


def worker(method: str, threads: int, shape: str, sampling: str, count: int, mine: list[int], n: int, ready, go, done):
    os.environ["MPMFX_SURFACE_THREADS"] = str(threads)
    os.environ["RAYON_NUM_THREADS"] = str(threads)
    import warp as wp

    wp.config.quiet = True
    wp.init()
    xs, h = frames(shape, sampling, count, n)
    if method == PEER:
        from mpmfx.bench.surface_peers import SPLASHSURF_SETTINGS, splashsurf_call

        kernel, cube = SPLASHSURF_SETTINGS[sampling]
        call = lambda x: splashsurf_call(x, h, kernel=kernel, cube=cube)()  # noqa: E731
    else:
        from mpmfx.bench.surface_cases import OURS
        from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles

        s = dict(OURS[method])
        p = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=s.pop("voxel_h") * h, dense_output=False, **s)
        call = lambda x: surface_particles(x, None, p, device="cpu")  # noqa: E731
    call(xs[0])  # warm-up
    ready.put(os.getpid())
    go.wait()
    for i in mine:
        call(xs[i])
    done.put(time.perf_counter())


def run(method: str, procs: int, threads: int, args) -> float:
    """Frames per second with `procs` worker processes of `threads` threads each."""
    ctx = mp.get_context("spawn")
    ready, go, done = ctx.Queue(), ctx.Event(), ctx.Queue()
    ps = [
        ctx.Process(
            target=worker,
            args=(
                method,
                threads,
                args.shape,
                args.sampling,
                args.count,
                list(range(k, args.frames, procs)),
                args.frames,
                ready,
                go,
                done,
            ),
        )
        for k in range(procs)
    ]
    for p in ps:
        p.start()
    for _ in ps:  # every worker past its warm-up call
        ready.get()
    t0 = time.perf_counter()
    go.set()
    end = max(done.get() for _ in ps)
    for p in ps:
        p.join()
    return args.frames / (end - t0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="torus")
    ap.add_argument("--sampling", default="lattice")
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    rows = []
    for rnd in range(args.rounds):
        for method in ("fast", "fine", PEER):
            for procs, threads in ((1, cores), (cores, 1)):
                fps = run(method, procs, threads, args)
                rows.append(
                    {"round": rnd, "method": method, "processes": procs, "threads": threads, "frames_per_s": fps}
                )
                print(
                    f"round {rnd} {args.shape} {args.sampling} {args.count}: {method:10} {procs} x {threads} threads: "
                    f"{fps:6.2f} frames/s ({1000 / fps:6.1f} ms a frame)",
                    flush=True,
                )
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"args": vars(args), "cores": cores, "rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
