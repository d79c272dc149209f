"""Export measurements (run by hand): `python scripts/measure_export.py DIR`.

Prints: seconds and bytes per particle for one 1,000,000-particle USD frame; finalize time and
root-stage open time for a 240-frame shot; seconds for one 128^3 VDB level set + vel frame.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mpmfx.io.usd import PointsSample, UsdShotWriter
from mpmfx.io.vdb import VdbGrid, write_vdb


def _particles(n: int, seed: int) -> PointsSample:
    rng = np.random.default_rng(seed)
    return PointsSample(
        positions=rng.random((n, 3), dtype=np.float32),
        velocities=rng.standard_normal((n, 3)).astype(np.float32),
        widths=np.full(n, 0.005, np.float32),
        ids=np.arange(n, dtype=np.int64),
        primvars={"material": rng.integers(0, 3, n).astype(np.int32),
                  "body": rng.integers(0, 4, n).astype(np.int32),
                  "Jp": rng.random(n, dtype=np.float32)},
    )


def big_frame(out: Path, n: int = 1_000_000) -> None:
    writer = UsdShotWriter(out / "big" / "shot.usda", fps=24, start_frame=1, end_frame=1)
    sample = _particles(n, 0)
    for label, widths in (("per-particle widths", sample.widths), ("one shared width", 0.005)):
        sample.widths = widths
        best = min(_timed(lambda: writer.write_frame(1, points={"water": sample})) for _ in range(3))
        size = writer.frame_path(1).stat().st_size
        print(f"USD frame, {n:,} particles, {label}: {best:.3f} s, {size / n:.1f} bytes/particle "
              f"({size / 1e6:.1f} MB)")


def many_frames(out: Path, frames: int = 240) -> None:
    root = out / "many" / "shot.usda"
    writer = UsdShotWriter(root, fps=24, start_frame=1, end_frame=frames)
    for f in range(1, frames + 1):
        writer.write_frame(f, points={"water": _particles(1000, f)},
                           volumes={"water": {"surface": f"vdb/{f:04d}.vdb"}})
    print(f"finalize, {frames} frames: {_timed(lambda: writer.finalize(range(1, frames + 1))):.3f} s")
    code = ("import time; from pxr import Usd; t=time.perf_counter(); s=Usd.Stage.Open(%r); "
            "t1=time.perf_counter(); s.GetPrimAtPath('/World/water/particles').GetAttribute('points')"
            ".Get(%d); t2=time.perf_counter(); print(f'{t1-t:.4f} {t2-t1:.4f}')" % (str(root), frames // 2))
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
            .stdout.split() for _ in range(3)]
    open_s = min(float(r[0]) for r in runs)
    read_s = min(float(r[1]) for r in runs)
    print(f"root stage open, {frames} frames (fresh process, pxr already imported): {open_s:.3f} s; "
          f"first read of one frame's points: {read_s * 1e3:.1f} ms")


def vdb_frame(out: Path, n: int = 128) -> None:
    h = 1.0 / n
    idx = (np.arange(n) - n / 2) * h
    x, y, z = np.meshgrid(idx, idx, idx, indexing="ij")
    phi = (np.sqrt(x * x + y * y + z * z) - 0.3).astype(np.float32)
    vel = np.stack([z, np.zeros_like(z), -x], -1).astype(np.float32)
    vel[phi > 3 * h] = 0
    grids = [VdbGrid("surface", phi, (-n // 2,) * 3, h, background=3 * h),
             VdbGrid("vel", vel, (-n // 2,) * 3, h, grid_class="unknown")]
    path = out / "vdb" / "0001.vdb"
    best = min(_timed(lambda: write_vdb(path, grids, metadata={"frame": 1})) for _ in range(3))
    print(f"VDB frame, {n}^3 level set + vel: {best:.3f} s, {path.stat().st_size / 1e6:.2f} MB")


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/mpmfx-io-measure")
    big_frame(out)
    many_frames(out)
    vdb_frame(out)
