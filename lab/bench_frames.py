"""Wall time of one per-frame stage on 1, 2, ... Dask workers (LocalCluster), upstream cached.

    python lab/bench_frames.py pipeline/shots/jelly_splash.toml --cache cache --frames 1:16 \
        --workers 1 2 4 8 16 --device cpu [--stage surface]

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
    args = ap.parse_args()
    frames = None
    if args.frames:
        a, b = args.frames.split(":")
        frames = list(range(int(a), int(b) + 1))
    t = time.perf_counter()
    load_shot(args.shot, cache_root=args.cache, device=args.device, quiet=True, workers=1).run(
        until=args.stage, frames=frames[:1] if frames else None, force=[args.stage]
    )
    print(f"warm-up (1 frame, serial, kernels loaded/compiled): {time.perf_counter() - t:.1f} s", flush=True)
    print(f"{os.cpu_count()} cores; {len(frames) if frames else 'all'} frames of {args.stage}")
    print("| workers | wall s | of which cluster start s | speed-up | CPU s, all processes |")
    print("|---|---|---|---|---|")
    base = None
    for w in args.workers:
        start = 0.0
        if w > 1:
            t = time.perf_counter()
            with Frames(workers=w) as ex:
                ex.client()
            start = time.perf_counter() - t
        t, cpu = time.perf_counter(), _cpu()
        load_shot(args.shot, cache_root=args.cache, device=args.device, quiet=True, workers=w).run(
            until=args.stage, frames=frames, force=[args.stage]
        )
        wall, cpu = time.perf_counter() - t, _cpu() - cpu
        base = base or wall
        print(f"| {w} | {wall:.1f} | {start:.1f} | {base / wall:.2f} | {cpu:.1f} |", flush=True)
    return 0


def _cpu() -> float:
    """CPU seconds of this process and its reaped children (the LocalCluster's workers, once closed)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


if __name__ == "__main__":
    sys.exit(main())
