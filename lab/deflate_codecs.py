"""Deflate on a surfaced frame's arrays: zlib's level 1 (the frame files before) against ISA-L's
levels 0-2 (python-isal, what `mpmfx.io.npz` deflates with): the ratio, and MB/s of one core
deflating and inflating, each array cut into the writer's 4 MB pieces.

    python lab/deflate_codecs.py [--grid 160] [--repeat 3]

hero_castle is voxelised at `--grid` and surfaced on the CPU as the surface stage does it (its
level set's leaves kept, as for a VDB export); the arrays are the mesh's vertices and faces and
the level set's leaves, as the surface stage writes them.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np
from isal import isal_zlib

import mpmfx
from mpmfx.bench.shots import SHOT_DIR
from mpmfx.io.frames import SeedParticles
from mpmfx.io.npz import CHUNK
from mpmfx.stages.surface import surface_params
from mpmfx.surface import surface_particles

CODECS = (("zlib", zlib, 1), ("ISA-L", isal_zlib, 0), ("ISA-L", isal_zlib, 1), ("ISA-L", isal_zlib, 2))


def deflate(lib, level: int, pieces: list[bytes]) -> list[bytes]:
    out = []
    for i, p in enumerate(pieces):
        c = lib.compressobj(level, lib.DEFLATED, -15)
        out.append(c.compress(p) + c.flush(lib.Z_FINISH if i == len(pieces) - 1 else lib.Z_FULL_FLUSH))
    return out


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grid", type=int, default=160)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    dx = 2.0 / args.grid
    over = [f"domain.grid_n={args.grid}", f"domain.origin=[-1.0, {-3 * dx:.6g}, -1.0]"]
    run = mpmfx.load_shot(
        SHOT_DIR / "hero_castle.toml", overrides=over, cache_root=Path(tempfile.mkdtemp()), device="cpu", quiet=True
    )
    run.run(until="voxelise")
    seed = SeedParticles.read(run.entries()["voxelise"].root)
    group = run.shot.surface_groups()[0]
    res = surface_particles(
        seed.x.astype(np.float32), seed.v.astype(np.float32), surface_params(run.shot, group), device="cpu"
    )
    arrays = {"vertices": res.mesh.vertices, "faces": res.mesh.faces, "level set leaves": res.sparse.values}
    print(
        f"hero_castle at grid {args.grid}: {len(seed.x):,} particles, {len(res.mesh.vertices):,} vertices, "
        f"{len(res.mesh.faces):,} faces, {len(res.sparse.values):,} leaves; one core, best of {args.repeat}"
    )
    print("| array | MB | codec | ratio | deflate MB/s | inflate MB/s (zlib) | inflate MB/s (ISA-L) |")
    print("|---|---|---|---|---|---|---|")
    for name, a in arrays.items():
        raw = np.ascontiguousarray(a).tobytes()
        pieces = [raw[i : i + CHUNK] for i in range(0, len(raw), CHUNK)]
        mb = len(raw) / 1e6
        for label, lib, level in CODECS:
            packed = b"".join(deflate(lib, level, pieces))
            assert zlib.decompressobj(-15).decompress(packed) == raw  # one raw deflate stream, as zip readers see it
            d = best(lambda lib=lib, level=level: deflate(lib, level, pieces), args.repeat)
            iz = best(lambda: zlib.decompressobj(-15).decompress(packed), args.repeat)
            ii = best(lambda: isal_zlib.decompressobj(-15).decompress(packed), args.repeat)
            print(
                f"| {name} | {mb:.1f} | {label} {level} | {len(raw) / len(packed):.2f} | {mb / d:.0f} | "
                f"{mb / iz:.0f} | {mb / ii:.0f} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
