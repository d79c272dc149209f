"""The surface stage's throughput on one frame, from the frame file to the mesh on disk.

    python lab/surface_stage_gpu.py [--grid 400] [--device cuda] [--reps 3]

hero_castle is voxelised at `--grid` (400: 10.1M particles) through the stage runner, its
particles written as a simulate frame file (`ParticleFrame`, as simulate writes it), and that
frame surfaced `--reps` times as the surface stage does it, in turn (no solver beside it):
reading the file, the surfacer (its own stats: the device's part), building the frame record,
and writing its file (deflate, checksums, disk). Prints one table, each part in ms and the
whole in M particles/s. The castle at rest has less surface than the collapsing pile a shot
frame holds (fewer vertices a particle).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np
import warp as wp

import mpmfx
from mpmfx.bench.shots import SHOT_DIR, device_name
from mpmfx.io.frames import ParticleFrame, SeedParticles


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grid", type=int, default=400)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="more shot overrides")
    args = ap.parse_args(argv)
    from mpmfx.stages.surface import make_surfaces, write_threads
    from mpmfx.stages.writer import FrameWriter

    dx = 2.0 / args.grid
    over = [f"domain.grid_n={args.grid}", f"domain.origin=[-1.0, {-3 * dx:.6g}, -1.0]", *args.overrides]
    cache = Path(tempfile.mkdtemp(prefix="surface_stage_"))
    run = mpmfx.load_shot(
        SHOT_DIR / "hero_castle.toml", overrides=over, cache_root=cache, device=args.device, quiet=True
    )
    t0 = time.perf_counter()
    run.run(until="voxelise")
    seed = SeedParticles.read(run.entries()["voxelise"].root)
    n = len(seed.x)
    print(f"hero_castle at grid {args.grid}: {n:,} particles voxelised in {time.perf_counter() - t0:.1f} s", flush=True)
    frame = ParticleFrame(
        x=seed.x.astype(np.float32),
        v=seed.v.astype(np.float32),
        id=np.arange(n, dtype=np.int32),
        material=np.zeros(n, np.int32),
        body=seed.body,
        Jp=np.zeros(n, np.float32),
        J=np.ones(n, np.float32),
    )
    src = cache / "particles_0001.npz"
    frame.write(src)
    job = types.SimpleNamespace(shot=run.shot, device=args.device)
    rows = []
    for rep in range(args.reps + 1):  # the first one loads the kernels
        t = [time.perf_counter()]
        p = ParticleFrame.read(src)
        t.append(time.perf_counter())
        surfaces, stats = make_surfaces(job, p, 1)
        wp.synchronize()
        t.append(time.perf_counter())
        with FrameWriter(write_threads(args.device)) as writer:
            writer.submit(surfaces.write, cache / f"surface_{rep}.npz")
        t.append(time.perf_counter())
        if rep:
            rows.append((np.diff(t) * 1e3, stats, (cache / f"surface_{rep}.npz").stat().st_size))
    print(f"surface stage, one frame in turn, {device_name(args.device)}, {os.cpu_count()} host cores")
    print("| rep | read ms | surface ms | write ms | whole ms | M particles/s | vertices | faces | file MB |")
    print("|---|---|---|---|---|---|---|---|---|")
    for i, (ms, stats, size) in enumerate(rows, 1):
        print(
            f"| {i} | {ms[0]:.0f} | {ms[1]:.0f} | {ms[2]:.0f} | {ms.sum():.0f} | {n / ms.sum() / 1e3:.1f} | "
            f"{stats['vertices']:,} | {stats['faces']:,} | {size / 1e6:.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
