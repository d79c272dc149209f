"""The surface stage's throughput, from the frame file to the mesh on disk.

    python lab/surface_stage_gpu.py [--grid 400] [--device cuda] [--reps 3] [--stream 8] [--variants]
                                    [--profile] [--simulate 12]

hero_castle is voxelised at `--grid` (400: 10.1M particles) through the stage runner, its
particles written as a simulate frame file (`ParticleFrame`, as simulate writes it; with
`--simulate K`, simulated K frames and the last one taken: a collapsing pile), and that frame
surfaced `--reps` times as the surface stage does it, in turn (no solver beside it): reading the
file, the surfacer (its own stats: the device's part), building the frame record, and writing its
file (deflate, checksums, disk). Prints one table, each part in ms and the whole in M particles/s,
with the surfacer's own split (its passes on the device, the download). `--stream K` then runs the
stage's own loop (`mpmfx.stages.surface`: the next frame read ahead and frames written behind on
threads) over K copies of the frame as cache files with their digests, and prints its throughput;
`--variants` runs that loop again with one thing changed each time (pageable reads, zlib's
deflate, nothing deflated, nothing written). `--profile` runs one more frame in turn under
cProfile and prints where the host's time goes. The castle at rest has less surface than the
collapsing pile a shot frame holds (fewer vertices a particle).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
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
    ap.add_argument("--stream", type=int, default=0, help="frames through the stage's own loop")
    ap.add_argument("--profile", action="store_true", help="one frame in turn under cProfile")
    ap.add_argument("--simulate", type=int, default=0, help="surface the castle after this many frames")
    ap.add_argument(
        "--variants",
        action="store_true",
        help="with --stream: the loop again with pageable reads, zlib's deflate, nothing deflated, nothing written",
    )
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="more shot overrides")
    args = ap.parse_args(argv)
    args.label = ""
    import mpmfx.stages.surface as stage
    from mpmfx.stages.surface import make_surfaces, write_threads
    from mpmfx.stages.writer import FrameWriter

    dx = 2.0 / args.grid
    over = [f"domain.grid_n={args.grid}", f"domain.origin=[-1.0, {-3 * dx:.6g}, -1.0]", *args.overrides]
    over += [f"shot.frame_end={1 + args.simulate}"] if args.simulate else []
    cache = Path(tempfile.mkdtemp(prefix="surface_stage_"))
    run = mpmfx.load_shot(
        SHOT_DIR / "hero_castle.toml", overrides=over, cache_root=cache, device=args.device, quiet=True
    )
    t0 = time.perf_counter()
    run.run(until="voxelise")
    seed = SeedParticles.read(run.entries()["voxelise"].root)
    n = len(seed.x)
    print(f"hero_castle at grid {args.grid}: {n:,} particles voxelised in {time.perf_counter() - t0:.1f} s", flush=True)
    if args.simulate:
        t0 = time.perf_counter()
        run.run(until="simulate")
        src = run.entries()["simulate"].frame_path(1 + args.simulate, ParticleFrame.EXT)
        print(f"simulated {args.simulate} frames in {time.perf_counter() - t0:.1f} s; surfacing frame {src.stem}")
    else:
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
    splits = []  # the surfacer's own stats of each call (SurfaceResult.stats)
    surface = stage.surface_particles

    def recorded(*a, **k):
        res = surface(*a, **k)
        splits.append(res.stats)
        return res

    stage.surface_particles = recorded
    rows = []
    for rep in range(args.reps + 1):  # the first one loads the kernels
        t = [time.perf_counter()]
        p = ParticleFrame.read(src, fields=stage.SURFACED)
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
    print("\nthe surfacer's split of each call, ms (device: its passes; download: the host copies)")
    keys = ("blocks", "field", "topology", "smooth", "mesh", "device", "download_mesh", "download", "active_blocks")
    print("| rep | " + " | ".join(keys) + " |\n|---|" + "---|" * len(keys))
    for i, st in enumerate(splits[1:], 1):
        cells = [f"{st[k]:,}" if k == "active_blocks" else f"{st.get(k, 0) * 1e3:.0f}" for k in keys]
        print(f"| {i} | " + " | ".join(cells) + " |")
    if args.stream:
        stream(run.shot, src, cache, n, args)
        if args.variants:
            variants(run.shot, src, cache, n, args)
    if args.profile:
        prof = cProfile.Profile()
        prof.enable()
        make_surfaces(job, ParticleFrame.read(src, fields=stage.SURFACED), 1)[0].write(cache / "surface_p.npz")
        prof.disable()
        print("\none frame in turn under cProfile (read, surface, write), the 25 largest by own time:")
        pstats.Stats(prof).sort_stats("tottime").print_stats(25)
    return 0


def stream(shot, src: Path, cache: Path, n: int, args) -> None:
    """The stage's own loop over `args.stream` copies of the frame, as cache files of a simulate
    entry (digests checked on read), into a surface entry."""
    import shutil

    from mpmfx import checksum
    from mpmfx.cache import Entry
    from mpmfx.stages.parallel import FrameJob
    from mpmfx.stages.surface import _pipelined, write_threads

    sim = Entry(cache / "sim", "simulate", "lab", {})
    out = Entry(cache / "surf", "surface", "lab", {})
    sim.frames_dir.mkdir(parents=True, exist_ok=True)
    out.frames_dir.mkdir(parents=True, exist_ok=True)
    frames = list(range(1, args.stream + 1))
    for f in frames:  # copies with their digests, as simulate leaves them (in the page cache)
        dst = sim.frame_path(f, ParticleFrame.EXT)
        shutil.copyfile(src, dst)
        checksum.record(dst)
    job = FrameJob(shot, out, {"simulate": sim}, args.device)
    bar = types.SimpleNamespace(update=lambda: None)
    threads = write_threads(args.device)
    for f in frames:  # a variant's run writes into the same entry
        out.frame_path(f, "npz").unlink(missing_ok=True)
    cpu0, t0 = os.times(), time.perf_counter()
    stats = _pipelined([(job, f) for f in frames], bar, write_threads=threads)
    wall, cpu1 = time.perf_counter() - t0, os.times()
    cpu = (cpu1.user - cpu0.user + cpu1.system - cpu0.system) / len(frames)
    waits = {k: sum(st["seconds"][k] for st in stats) / len(stats) * 1e3 for k in stats[0]["seconds"]}
    print(
        f"\nthe stage's loop{args.label}, {len(frames)} frames of {n:,} particles, {threads} writers: {wall:.2f} s, "
        f"{wall / len(frames) * 1e3:.0f} ms a frame, {n * len(frames) / wall / 1e6:.1f} M particles/s, "
        f"{cpu:.2f} host CPU-s a frame; a frame's mean ms: " + ", ".join(f"{k} {ms:.0f}" for k, ms in waits.items()),
        flush=True,
    )


def variants(shot, src: Path, cache: Path, n: int, args) -> None:
    """The loop again with one thing changed each time: which part of the host's work bounds it."""
    import mpmfx.stages.surface as stage
    from mpmfx.io import npz
    from mpmfx.io.frames import SurfaceFrame
    from mpmfx.surface.pinned import host_buffer

    for name, alloc in (("pageable", None), ("page-locked", lambda nbytes: host_buffer(wp, nbytes))):
        p = ParticleFrame.read(src, fields=stage.SURFACED, alloc=alloc)
        wp.synchronize()
        t0 = time.perf_counter()
        for a in (p.x, p.v):
            wp.array(a, dtype=wp.vec3, device=args.device)
        wp.synchronize()
        print(f"\nupload of x and v from {name} memory: {(time.perf_counter() - t0) * 1e3:.1f} ms")

    def again(label, **changes):
        stream(shot, src, cache, n, argparse.Namespace(**{**vars(args), "label": f" ({label})", **changes}))

    stage.PINNED_READS = False
    again("pageable reads")
    stage.PINNED_READS = True
    isal_deflate = npz._deflate
    npz._deflate = _zlib_deflate
    again("zlib's deflate")
    npz._deflate = isal_deflate
    deflate, write = SurfaceFrame._DEFLATE, SurfaceFrame.write
    SurfaceFrame._DEFLATE = ()
    again("stored, no deflate")
    SurfaceFrame._DEFLATE = deflate
    SurfaceFrame.write = lambda self, path: None
    again("no writes")
    SurfaceFrame.write = write
    again("page-locked reads, once more: after the pool's buffers are made")


def _zlib_deflate(piece, last: bool) -> bytes:
    """mpmfx.io.npz's deflate of a piece with zlib's level 1, as the frame files were written before."""
    import zlib

    c = zlib.compressobj(1, zlib.DEFLATED, -15)
    return c.compress(piece) + c.flush(zlib.Z_FINISH if last else zlib.Z_FULL_FLUSH)


if __name__ == "__main__":
    sys.exit(main())
