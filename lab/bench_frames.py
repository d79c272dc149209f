"""Wall time of one per-frame stage on 1, 2, ... Dask workers (LocalCluster), upstream cached.

    python lab/bench_frames.py pipeline/shots/jelly_splash.toml --cache cache --frames 1:16 \
        --workers 1 2 4 8 16 --device cpu [--stage surface] [--set render.width=160 ...]

The Cycles render (`--stage render`, the shot's engine) runs one Blender process on 1 worker
and strided chunks of frames, one Blender a chunk on its worker's share of the cores, on 2 or
more (`mpmfx.stages.render.chunks`); frames/min counts the frames asked for.

Each row re-runs the stage from scratch (`force`) through the product's path (`ShotRun.run`,
`mpmfx.stages.parallel.Frames`), including the LocalCluster's start (also timed alone). A
one-frame serial warm-up first loads (and on a fresh machine compiles) the kernels. The CPU
column adds up every process (client and workers): on a shared machine, where wall time
measures the neighbours, CPU seconds / cores bounds what an idle machine would take.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time


def main() -> int:
    from mpmfx.stages.parallel import Frames
    from mpmfx.stages.runner import load_shot

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shot")
    ap.add_argument("--cache", default=None)
    ap.add_argument("--frames", default=None, metavar="A:B")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--device", default=None)
    ap.add_argument("--stage", default="surface")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    shot = lambda w: load_shot(  # noqa: E731
        args.shot, cache_root=args.cache, device=args.device, quiet=True, workers=w, overrides=args.overrides
    )
    frames = None
    if args.frames:
        a, b = args.frames.split(":")
        frames = list(range(int(a), int(b) + 1))
    t = time.perf_counter()
    shot(1).run(until=args.stage, frames=frames[:1] if frames else None, force=[args.stage])
    print(f"warm-up (1 frame, serial, kernels loaded/compiled): {time.perf_counter() - t:.1f} s", flush=True)
    n = len(frames) if frames else len(shot(1).shot.frames)
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; {n} frames of {args.stage}")
    print("| workers | wall s | of which cluster start s | speed-up | frames/min | CPU s, all processes |")
    print("|---|---|---|---|---|---|")
    base = None
    for w in args.workers:
        start = 0.0
        if w > 1:
            t = time.perf_counter()
            with Frames(workers=w) as ex:
                ex.client()
            start = time.perf_counter() - t
        t, cpu = time.perf_counter(), _cpu()
        shot(w).run(until=args.stage, frames=frames, force=[args.stage])
        wall, cpu = time.perf_counter() - t, _cpu() - cpu
        base = base or wall
        print(f"| {w} | {wall:.1f} | {start:.1f} | {base / wall:.2f} | {60 * n / wall:.1f} | {cpu:.1f} |", flush=True)
    return 0


def _cpu() -> float:
    """CPU seconds of this process and its reaped children (the LocalCluster's workers, once closed)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


if __name__ == "__main__":
    sys.exit(main())
