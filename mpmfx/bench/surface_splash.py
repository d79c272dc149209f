"""A real splash frame for the surfacer: water_dam's surge running up the far wall.

The particles are one frame (SPLASH_FRAME) of pipeline/shots/water_dam.toml as shipped (grid 48,
8 particles per cell: 52,896 particles, spacing h = 1/96 m), simulated on the CPU and stored in
SPLASH_ASSET quantised to 16 bits per axis over the domain (steps of 1/65535 m = 0.0015 h), so
the bench needs no simulation; `write_splash_asset` makes it again from a simulate stage's frame.
Each surfacer sees the same particles and is judged like the thin sheet (surface_cases.sheet_stats):
pieces (all, and those of at least MIN_PIECE_VOLUME h^3: the rest are droplets), holes (total
genus: a hole through a sheet is a handle), open edges; plus the mesh
volume over the particles' own volume n h^3 (water shrinks or swells under a kernel) and time.
Ours runs at the shot's surface setting (mpmfx.stages.surface.surface_params), isotropic and
anisotropic; the peers at their "random" settings (MPM particles are irregular, not a lattice).

    python -m mpmfx.bench.surface_splash [--peers splashsurf newton newton-aniso] [--device cpu]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import warp as wp
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from mpmfx.bench.report import write_rows
from mpmfx.bench.surface_cases import Table, mesh_stats, sheet_stats
from mpmfx.bench.surface_peers import run_peer
from mpmfx.shotfile import load_shot_config
from mpmfx.stages.surface import surface_params
from mpmfx.surface import SurfaceParams, surface_particles

SPLASH_ASSET = Path(__file__).parent / "data" / "water_dam_splash.npz"
SPLASH_SHOT = Path(__file__).parents[2] / "pipeline" / "shots" / "water_dam.toml"
SPLASH_PARTICLES = 52_896
"""Particles in the asset (`mpmfx bench surface` runs the splash only when --counts reach it)."""
SPLASH_FRAME = 14
"""water_dam frame of the asset: the surge, 2 m/s, climbing the far wall as a thin tongue
(frames 11-17 of the shot; its crest reaches 0.32 m at frame 17)."""


def write_splash_asset(
    frame_npz: str | Path, out: str | Path = SPLASH_ASSET, *, shot: str | Path = SPLASH_SHOT, frame: int = SPLASH_FRAME
) -> Path:
    """Store the positions `x` of a simulate-stage frame (.npz) of `shot` as the bench's asset:
    uint16 per axis over the shot's domain cube, with origin, size, spacing h (m) and frame."""
    cfg = load_shot_config(shot)
    origin, size = np.asarray(cfg.domain.origin, np.float64), float(cfg.domain.size)
    x = np.load(frame_npz)["x"].astype(np.float64)
    q = np.clip(np.rint((x - origin) / size * 65535.0), 0, 65535).astype(np.uint16)
    out = Path(out)
    np.savez_compressed(out, q=q, origin=origin, size=size, h=cfg.particle_spacing, frame=frame)
    return out


def load_splash(path: str | Path = SPLASH_ASSET) -> tuple[np.ndarray, float]:
    """((n, 3) float32 positions m, particle spacing h m) of the splash asset."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: splash asset missing; make it with "
            "mpmfx.bench.surface_splash.write_splash_asset(<simulate frame .npz>)"
        )
    d = np.load(path)
    x = d["origin"] + d["q"].astype(np.float64) / 65535.0 * float(d["size"])
    return x.astype(np.float32), float(d["h"])


def splash_params(h: float, *, anisotropic: bool, shot: str | Path = SPLASH_SHOT):
    """The surface stage's SurfaceParams for `shot`'s first surface group (water_dam's water:
    radius_scale 1.2, no sharp edges), with `anisotropic` set as asked; h must be the shot's
    spacing (checked: the asset's shot)."""
    cfg = load_shot_config(shot)
    if not np.isclose(cfg.particle_spacing, h):
        raise ValueError(
            f"{shot}: spacing {cfg.particle_spacing:g} m, the splash asset's {h:g} m; "
            "make the asset again (write_splash_asset) from this shot"
        )
    return dataclasses.replace(surface_params(cfg, cfg.surface_groups()[0]), anisotropic=anisotropic)


def piece_volumes(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Enclosed volume (m^3) of each connected piece of a closed triangle mesh, by the divergence
    theorem per piece; (pieces,) float64, in no particular order."""
    if len(faces) == 0:
        return np.zeros(0)
    n = len(vertices)
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    _, labels = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False)
    t = vertices[faces].astype(np.float64)
    signed = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6.0
    _, piece = np.unique(labels[faces[:, 0]], return_inverse=True)
    return np.bincount(piece, weights=signed)


MIN_PIECE_VOLUME = 8.0
"""Pieces smaller than this many particle volumes h^3 are droplets, not breaks in the sheet
(our shot setting removes blobs of fewer than 8 particles; the peers keep them)."""


def _row(
    method: str,
    x: np.ndarray,
    h: float,
    seconds: float,
    vertices: np.ndarray,
    faces: np.ndarray,
    device: str,
    settings: str,
) -> dict:
    stats = sheet_stats(vertices, faces, h)
    stats.pop("thickness_err")  # a disc's measure; this frame has no analytic thickness
    volume, _ = mesh_stats(vertices, faces)
    big = int((piece_volumes(vertices, faces) >= MIN_PIECE_VOLUME * h**3).sum())
    return {
        "shape": "water_dam splash",
        "particles": len(x),
        "h": h,
        "method": method,
        "seconds": seconds,
        **stats,
        "pieces_big": big,
        "volume_ratio": volume / (len(x) * h**3),
        "vertices": len(vertices),
        "device": device,
        "settings": settings,
    }


def measure_splash(x: np.ndarray, h: float, *, anisotropic: bool, device: str | None = None) -> dict:
    """Our surfacer at the shot's setting on (x (n, 3) m, h m); time = one whole call (compiled)."""
    params = splash_params(h, anisotropic=anisotropic)
    t0 = time.perf_counter()
    mesh = surface_particles(x, None, params, device=device).mesh
    seconds = time.perf_counter() - t0
    settings = (
        f"shot: radius_scale {params.radius_scale:g} voxel {params.resolved_voxel_size / h:g}h "
        f"smooth {params.smooth_iters}"
    )
    return _row(
        "mpmfx fine" + (" anisotropic" if anisotropic else ""),
        x,
        h,
        seconds,
        mesh.vertices,
        mesh.faces,
        str(wp.get_device(device)),
        settings,
    )


def measure_splash_peer(name: str, x: np.ndarray, h: float, *, device: str | None = None, repeats: int = 1) -> dict:
    """Peer `name` on (x, h) at its bench settings for random samples; time: median after a warm-up."""
    res = run_peer(name, x, h, "random", device=device, repeats=repeats)
    return _row(res.name, x, h, res.seconds, res.vertices, res.faces, res.device, res.settings)


def bench_splash(
    device: str | None = None, *, peers: Sequence[str] = (), echo: bool = True, asset: str | Path = SPLASH_ASSET
) -> list[dict]:
    """The splash frame with ours isotropic and anisotropic and each peer (a failing peer is
    reported and left out); prints SPLASH_HEADER rows when `echo`."""
    x, h = load_splash(asset)
    surface_particles(x[:500], None, SurfaceParams(h, anisotropic=True), device=device)  # compile
    rows = Table(SPLASH_HEADER, format_splash_row, echo=echo)
    for aniso in (False, True):
        rows.emit(measure_splash(x, h, anisotropic=aniso, device=device))
    for name in peers:
        rows.attempt(f"splash frame: peer {name}", lambda: measure_splash_peer(name, x, h, device=device))
    return list(rows)


SPLASH_HEADER = (
    f"{'frame':16} {'n':>7} {'method':22} {'time s':>7} {'pieces':>6} {'>=8h3':>5} {'holes':>6} "
    f"{'open':>5} {'vol/nh3':>7} {'device':>7}  settings"
)


def format_splash_row(r: dict) -> str:
    """One line of the splash table (columns of SPLASH_HEADER)."""
    return (
        f"{r['shape']:16} {r['particles']:7d} {r['method']:22} {r['seconds']:7.3f} {r['components']:6d} "
        f"{r['pieces_big']:5d} {r['holes']:6d} {r['open_edges']:5d} {r['volume_ratio']:7.3f} {r['device']:>7}  {r['settings']}"
    )


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None)
    ap.add_argument("--peers", nargs="*", default=[], help="splashsurf, newton, newton-aniso")
    ap.add_argument("--out", default=None, help="also write surface_splash.csv/json here")
    args = ap.parse_args(argv)
    rows = bench_splash(args.device, peers=args.peers)
    if args.out:
        print(f"table: {write_rows(rows, args.out, 'surface_splash')} (+ .json)")


if __name__ == "__main__":
    main()
