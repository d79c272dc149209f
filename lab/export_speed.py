"""The export stage's time on one large surface frame: `mpmfx.stages.export.frame` on a synthetic
frame of about --faces triangles, with and without the VDB grids, and where its time goes
(`seconds_split`: reading the surface frame, building the USD layer, building and writing the
VDB grids, writing the USD layer). One table; rows as JSON under --out.

    python lab/export_speed.py [--device cpu|cuda:0] [--faces 10000000] [--repeat 2] [--parallel 4]

The frame is built on the host: per surface group of jelly_splash a sphere, meshed as a latitude /
longitude grid (vertices, normals, velocities of a spin), and its level set as 8^3 leaves in the
narrow band with the leaves wholly inside listed, as the surface stage stores them; its radius is
the one at which marching cubes gives about that many triangles, so the leaves are as many as a
surfaced frame's. Export runs on the host's cores whatever the device: --device only names the
machine in the table (run it on the GPU machine to time that machine's CPU).
`--parallel W` then exports 2W copies of the frame (without VDB) on W processes at once, as the
stage's Dask workers take frames on a many-core host, and prints the seconds a frame.
"""

import argparse
import json
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from mpmfx.bench.report import print_table
from mpmfx.bench.shots import device_name
from mpmfx.cache import Entry
from mpmfx.io.frames import GroupSurface, SurfaceFrame
from mpmfx.shotfile import load_shot_config
from mpmfx.stages import export
from mpmfx.stages.parallel import FrameJob

OUT = os.environ.get("OUT", "renders/bench")
SHOT = Path(__file__).resolve().parents[1] / "pipeline" / "shots" / "jelly_splash.toml"
VOXEL = 0.004  # m
FRAME = 1


def sphere(faces: int, center: np.ndarray, density: bool) -> GroupSurface:
    """A sphere of about `faces` triangles and its narrow-band leaves (GroupSurface's units)."""
    h, band = VOXEL, 3 * VOXEL
    r = np.sqrt(faces / (8 * np.pi))  # voxels: marching cubes gives ~8 pi r^2 triangles on a sphere
    n = max(int(np.sqrt(faces / 2)), 4)  # a latitude / longitude grid of n x n vertices
    th, ph = np.meshgrid(np.linspace(0.01, np.pi - 0.01, n), np.linspace(0, 2 * np.pi, n, endpoint=False))
    unit = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    spin = lambda p: np.cross([0.0, 2.0, 0.0], p)  # noqa: E731  (rad/s about y: m/s)
    verts = (center + r * h * unit).astype(np.float32)
    i, j = np.meshgrid(np.arange(n), np.arange(n - 1), indexing="ij")
    a, b, c, d = i * n + j, ((i + 1) % n) * n + j, ((i + 1) % n) * n + j + 1, i * n + j + 1
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    # leaves: the 8^3 blocks the band touches, and those wholly inside
    c0 = np.round(center / h / 8).astype(np.int64) * 8  # leaves start at multiples of 8
    m = int(np.ceil((r + 8) / 8))
    g = np.stack(np.meshgrid(*[np.arange(-m, m + 1)] * 3, indexing="ij"), -1).reshape(-1, 3) * 8
    dist = np.linalg.norm(g + 3.5, axis=1)
    half = 3.5 * np.sqrt(3)
    near = np.abs(dist - r) < half + band / h
    inside = dist + half < r - band / h
    ijk = g[near] + c0
    local = np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), -1).reshape(-1, 3)
    pos = (ijk[:, None, :] + local[None]) * h  # (b, 512, 3) m
    sdf = np.linalg.norm(pos - center, axis=2) - r * h
    blocks = np.clip(sdf, -band, band).astype(np.float32).reshape(-1, 8, 8, 8)
    vel = spin(pos - center).astype(np.float16).reshape(-1, 8, 8, 8, 3)
    vel[np.broadcast_to((sdf > band).reshape(-1, 8, 8, 8, 1), vel.shape)] = 0  # no particle reaches out there
    fog = np.clip(0.5 - sdf / (2 * band), 0, 1).astype(np.float16).reshape(-1, 8, 8, 8) if density else None
    return GroupSurface(
        vertices=verts,
        faces=tris.astype(np.int32),
        normals=unit.astype(np.float32),
        velocities=spin(verts - center).astype(np.float32),
        block_ijk=ijk,
        blocks=blocks,
        inside_ijk=g[inside] + c0,
        voxel_size=h,
        background=band,
        vel_blocks=vel,
        density_blocks=fog,
    )


def frame(shot, faces: int, density: bool) -> SurfaceFrame:
    groups = list(dict.fromkeys(shot.surface_groups()))
    r = np.sqrt(faces / len(groups) / (8 * np.pi)) * VOXEL
    return SurfaceFrame(
        {g: sphere(faces // len(groups), np.array([2.5 * r * k, 0.5, 0.0]), density) for k, g in enumerate(groups)}
    )


def time_export(shot, root: Path, surf: Entry, vdb: bool, repeat: int) -> list[dict]:
    """export.frame on the frame in `surf`, `repeat` times (its files removed in between)."""
    shot = shot.model_copy(update={"export": shot.export.model_copy(update={"vdb": vdb, "points": False})})
    out = []
    for k in range(repeat):
        entry = Entry(root / f"export-{int(vdb)}-{k}", "export", f"export{k}", {})
        job = FrameJob(shot, entry, {"surface": surf, "simulate": surf})
        t0 = time.perf_counter()
        split = export.frame(job, FRAME) or {}
        out.append({"whole": time.perf_counter() - t0, **split})
    return out


def _warm(_) -> None:
    """A process's imports (USD's included), before the timed frames."""
    import pxr.Usd  # noqa: F401


def throughput(shot, root: Path, mesh: Entry, workers: int) -> float:
    """Seconds a frame of export.frame over 2 * workers copies of `mesh`'s frame on `workers`
    processes at once (VDB off)."""
    import multiprocessing
    import shutil
    from concurrent.futures import ProcessPoolExecutor

    from mpmfx import checksum

    shot = shot.model_copy(update={"export": shot.export.model_copy(update={"vdb": False, "points": False})})
    frames = list(range(FRAME, FRAME + 2 * workers))
    for f in frames[1:]:
        dst = mesh.frame_path(f, SurfaceFrame.EXT)
        shutil.copyfile(mesh.frame_path(FRAME, SurfaceFrame.EXT), dst)
        checksum.record(dst)
    job = FrameJob(shot, Entry(root / "export-parallel", "export", "parallel", {}), {"surface": mesh, "simulate": mesh})
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("forkserver")) as pool:
        list(pool.map(_warm, range(workers)))
        t0 = time.perf_counter()
        list(pool.map(export.frame, [job] * len(frames), frames))
        return (time.perf_counter() - t0) / len(frames)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu", help="names the machine in the table (export runs on its CPU)")
    ap.add_argument("--faces", type=int, default=10_000_000)
    ap.add_argument("--repeat", type=int, default=2, help="runs of each; the table shows the fastest")
    ap.add_argument("--density", action="store_true", help="fog density leaves too (surface.density)")
    ap.add_argument("--no-vdb-run", action="store_true", help="only the run without VDB grids")
    ap.add_argument("--parallel", type=int, default=0, help="then 2W frames on W processes (VDB off)")
    args = ap.parse_args()
    shot = load_shot_config(SHOT)
    with tempfile.TemporaryDirectory(prefix="mpmfx-export-speed-") as tmp:
        root = Path(tmp)
        surf = Entry(root / "surface", "surface", "surface", {})
        t0 = time.perf_counter()
        sf = frame(shot, args.faces, args.density)
        sf.write(surf.frame_path(FRAME, SurfaceFrame.EXT))
        built = time.perf_counter() - t0
        nfaces = sum(len(g.faces) for g in sf.groups.values())
        leaves = sum(len(g.block_ijk) for g in sf.groups.values())
        size = surf.frame_path(FRAME, SurfaceFrame.EXT).stat().st_size
        # without VDB the surface stage keeps no leaves: the frame export reads is the mesh alone
        mesh = Entry(root / "surface-mesh", "surface", "surface-mesh", {})
        no_leaves = dict.fromkeys(("block_ijk", "blocks", "inside_ijk", "vel_blocks", "density_blocks"))
        SurfaceFrame({g: replace(d, **no_leaves) for g, d in sf.groups.items()}).write(
            mesh.frame_path(FRAME, SurfaceFrame.EXT)
        )
        del sf
        print(
            f"frame: {nfaces:,} faces, {leaves:,} leaves, {len(shot.surface_groups())} objects; "
            f"{size / 1e6:.0f} MB on disk with its leaves, "
            f"{mesh.frame_path(FRAME, SurfaceFrame.EXT).stat().st_size / 1e6:.0f} MB without; "
            f"built and written in {built:.1f} s",
            flush=True,
        )
        rows, dev = [], device_name(args.device)
        for vdb in [False] if args.no_vdb_run else [False, True]:
            runs = time_export(shot, root, surf if vdb else mesh, vdb, args.repeat)
            best = min(runs, key=lambda r: r["whole"])
            tag = "VDB on" if vdb else "VDB off"
            for part, s in best.items():
                rows.append(
                    {"row": f"export.frame, {part}", "vdb": tag, "s": round(s, 3), "faces": nfaces, "device": dev}
                )
        if args.parallel:
            s = throughput(shot, root, mesh, args.parallel)
            row = f"{2 * args.parallel} frames on {args.parallel} processes, a frame"
            rows.append({"row": row, "vdb": "VDB off", "s": round(s, 3), "faces": nfaces, "device": dev})
    print(f"export of one frame, {nfaces:,} faces; {dev}")
    print_table(rows, ["row", "vdb", "s"])
    Path(OUT).mkdir(parents=True, exist_ok=True)
    (Path(OUT) / "export_speed.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
