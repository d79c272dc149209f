"""Flicker of a slowly moving body over a run of frames, as an artist sees it in a render.

A block of uniformly random particles (MPM-like, not a lattice) glides MOVE_STEP h a frame along
a fixed oblique direction while each particle creeps by REST_NOISE h (rms per axis, fresh every
frame), for FLICKER_FRAMES frames. Each frame is surfaced on its own. With the motion taken back
out, a surfacer that follows the body leaves a mesh that stands still; what moves is flicker:

- normal jitter: distance of each vertex of frame k, moved back, to the surface of frame k - 1
  (its closest point; a re-triangulation of the same surface reads 0), mean and p99 in h;
- normal turn: angle between the vertex normal and frame k - 1's smooth-shading normal at that
  closest point (degrees): what moves a highlight; on the faces, and apart on the box's edges
  (within EDGE_BAND h of two faces), where a random sample is roughest;
- area and volume change between consecutive frames (%): a "breathing" or shimmering body;
- the picture: each frame rendered from a camera that moves with the body (PyVista, glossy, a
  grazing key light; `render`), and the change of its pixels between consecutive frames over
  the pixels the body covers in either: the mean in 8-bit levels, and the share that change by
  more than VISIBLE_LEVELS. A surfacer without flicker gives two equal pictures.

Every method gets its normals the same way (area-weighted face normals), so peers compare.

    python -m mpmfx.bench.surface_flicker [--count 20000] [--peers splashsurf newton] [--device cpu]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from mpmfx.bench.report import write_rows
from mpmfx.bench.surface_cases import BOX_HALF, OURS, RUN_ERRORS, Table, mesh_stats, sample_shape
from mpmfx.bench.surface_jitter import MOVE_STEP, REST_NOISE
from mpmfx.bench.surface_peers import run_peer
from mpmfx.render import import_pyvista
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles

FLICKER_COUNT = 20_000
"""Particles in the moving block (flicker is measured in h, so a GPU-sized block adds nothing)."""
FLICKER_FRAMES = 10
"""Frames of the moving block (about half a second of a shot at 24 fps)."""
DIRECTION = np.array([0.57, 0.41, 0.71]) / np.linalg.norm([0.57, 0.41, 0.71])
"""Direction of motion: oblique, so the body crosses voxel faces on all three axes."""


def moving_frames(
    count: int, *, frames: int = FLICKER_FRAMES, seed: int = 0
) -> tuple[list[np.ndarray], float, np.ndarray]:
    """([frames] (n, 3) float32 positions m, spacing h m, (3,) step m per frame): a random box
    moving MOVE_STEP h a frame along DIRECTION, each particle creeping REST_NOISE h a frame."""
    x, h = sample_shape("box", count, "random", seed=seed)
    step = DIRECTION * MOVE_STEP * h
    rng = np.random.default_rng(seed + 1)
    out = [(x + k * step + rng.normal(0.0, REST_NOISE * h, size=x.shape)).astype(np.float32) for k in range(frames)]
    return out, h, step


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) unit area-weighted vertex normals of a triangle mesh (outward for a CCW mesh)."""
    v = vertices.astype(np.float64)
    fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = np.zeros_like(v)
    for c in range(3):
        np.add.at(n, faces[:, c], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


def surface_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total triangle area (m^2)."""
    v = vertices.astype(np.float64)
    return float(
        np.linalg.norm(np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]]), axis=1).sum() / 2
    )


def _segment_closest(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Closest points of segments a-b to points p (all (..., 3))."""
    ab = b - a
    t = np.clip(np.einsum("...i,...i->...", p - a, ab) / np.maximum(np.einsum("...i,...i->...", ab, ab), 1e-30), 0, 1)
    return a + t[..., None] * ab


def closest_on_mesh(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each of `points` (q, 3), the closest point of the triangles around its nearest vertex
    of the mesh (vertices (m, 3), faces (k, 3)) and the vertex `normals` (m, 3) interpolated there
    (barycentric, renormalised: what smooth shading shows). Returns ((q, 3) points, (q, 3) normals)."""
    _, near = cKDTree(vertices).query(points)
    # triangles incident to each vertex, padded with the vertex's first one (a repeat changes no minimum)
    order = np.argsort(faces.ravel(), kind="stable")
    owner = faces.ravel()[order]
    start = np.searchsorted(owner, np.arange(len(vertices)))
    count = np.bincount(owner, minlength=len(vertices))
    k = np.arange(max(int(count.max()), 1))
    slot = start[near][:, None] + np.minimum(k[None, :], np.maximum(count[near], 1)[:, None] - 1)
    tri = faces[order[np.minimum(slot, len(order) - 1)] // 3]  # (q, K, 3)
    a, b, c = (vertices[tri[..., i]] for i in range(3))
    p = points[:, None, :]
    n = np.cross(b - a, c - a)
    nn = np.maximum(np.einsum("...i,...i->...", n, n), 1e-30)
    proj = p - (np.einsum("...i,...i->...", p - a, n) / nn)[..., None] * n
    wa = np.einsum("...i,...i->...", np.cross(c - b, proj - b), n) / nn
    wb = np.einsum("...i,...i->...", np.cross(a - c, proj - c), n) / nn
    inside = (wa >= 0) & (wb >= 0) & (1 - wa - wb >= 0)
    cands = [
        np.where(inside[..., None], proj, np.inf),
        _segment_closest(p, a, b),
        _segment_closest(p, b, c),
        _segment_closest(p, c, a),
    ]
    cands = np.stack(cands, axis=-2)  # (q, K, 4, 3)
    d = np.linalg.norm(cands - p[..., None, :], axis=-1)
    d = np.where(np.isfinite(d), d, np.inf).reshape(len(points), -1)
    best = d.argmin(axis=1)
    q = np.arange(len(points))
    x = cands.reshape(len(points), -1, 3)[q, best]
    t = best // 4
    ta, tb, tc = a[q, t], b[q, t], c[q, t]
    nt = n[q, t]
    ntn = np.maximum(np.einsum("ij,ij->i", nt, nt), 1e-30)
    ua = np.einsum("ij,ij->i", np.cross(tc - tb, x - tb), nt) / ntn
    ub = np.einsum("ij,ij->i", np.cross(ta - tc, x - tc), nt) / ntn
    tri_q = tri[q, t]
    normal = (
        ua[:, None] * normals[tri_q[:, 0]]
        + ub[:, None] * normals[tri_q[:, 1]]
        + (1 - ua - ub)[:, None] * normals[tri_q[:, 2]]
    )
    return x, normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)


def frame_change(
    prev: tuple[np.ndarray, np.ndarray],
    cur: tuple[np.ndarray, np.ndarray],
    h: float,
    *,
    edges: np.ndarray | None = None,
) -> dict:
    """Flicker between two consecutive meshes (vertices (m, 3) m, faces (k, 3)), both already moved
    back to the body's rest place: distance of each vertex of `cur` to the surface of `prev` (its
    closest point; a re-triangulation of the same surface reads 0), mean / p99 in h, and the turn
    of the shading normal there (degrees: `cur`'s vertex normal against `prev`'s interpolated),
    mean / p99 over the vertices off the `edges` mask ((m,) bool over `cur`'s vertices; None: all),
    and p99 on it (nan without a mask): sharp edges flicker more than faces."""
    (va, fa), (vb, fb) = prev, cur
    va, vb = np.asarray(va, np.float64), np.asarray(vb, np.float64)
    na, nb = vertex_normals(va, fa), vertex_normals(vb, fb)
    x, n = closest_on_mesh(vb, va, fa, na)
    off = np.linalg.norm(vb - x, axis=1) / h
    turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, nb), -1.0, 1.0)))
    flat = turn if edges is None else turn[~edges]
    sharp = turn[edges] if edges is not None and edges.any() else np.array([np.nan])
    return {
        "normal_jitter_h": float(off.mean()),
        "normal_jitter_p99_h": float(np.percentile(off, 99)),
        "normal_turn_deg": float(flat.mean()),
        "normal_turn_p99_deg": float(np.percentile(flat, 99)),
        "edge_turn_p99_deg": float(np.percentile(sharp, 99)),
    }


def box_edges(vertices: np.ndarray, h: float) -> np.ndarray:
    """(m,) bool: vertices (m, 3) m within EDGE_BAND h of two or more faces of the bench's box."""
    return (np.abs(np.abs(vertices) - BOX_HALF) < EDGE_BAND * h).sum(axis=1) >= 2


EDGE_BAND = 1.5
"""Vertices this close (in h) to two faces of the box count as its edges (the rounded strip)."""


RENDER_SIZE = (560, 420)
"""Pixels of a rendered frame (width, height): the 20k block is about 30 h across, ~9 pixels an h."""
CAMERA = [(1.05, 0.8, 0.85), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)]
"""Camera (position, focus, up; m) on the block at its rest place: three faces, their edges and a corner."""
VISIBLE_LEVELS = 4
"""A pixel changing by more than this (of 255, ~1.6 %) between frames counts as a visible change:
at 24 fps the eye sees flicker of about 1-2 % contrast."""


def render(pv, vertices: np.ndarray, faces: np.ndarray, size: tuple[int, int] = RENDER_SIZE) -> np.ndarray:
    """(H, W, 3) uint8 picture of one mesh (m) from CAMERA on black, glossy with smooth shading
    (area-weighted vertex normals, as every method gets), a key light grazing the top face so a
    normal's turn shows as a highlight's change."""
    plotter = pv.Plotter(off_screen=True, window_size=size, lighting="none")
    plotter.set_background("black")
    plotter.add_light(pv.Light(position=(0.9, -0.4, 0.45), focal_point=(0, 0, 0), intensity=1.0))
    plotter.add_light(pv.Light(position=(-0.5, 0.8, 0.3), focal_point=(0, 0, 0), intensity=0.3))
    mesh = pv.PolyData(np.asarray(vertices, np.float64), np.hstack([np.full((len(faces), 1), 3), faces]).ravel())
    mesh.point_data["Normals"] = vertex_normals(vertices, faces)
    plotter.add_mesh(
        mesh, color="#8fb8d8", smooth_shading=True, specular=0.9, specular_power=60, diffuse=0.6, ambient=0.1
    )
    plotter.camera_position = CAMERA
    img = plotter.screenshot(return_img=True)
    plotter.close()
    return np.asarray(img)[..., :3]


def picture_change(meshes: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """Rendered flicker of meshes already moved back to the body's rest place: over each
    consecutive pair, the pixels showing the body in either picture, their change (the largest
    over R, G, B; 8-bit levels) averaged, and the share changing by more than VISIBLE_LEVELS;
    means over the pairs. Empty where PyVista is missing (a GPU node): the table shows "-"."""
    try:
        pv = import_pyvista()
    except ImportError:
        return {}
    pictures = [render(pv, v, f).astype(np.int16) for v, f in meshes]
    means, shares = [], []
    for a, b in zip(pictures[:-1], pictures[1:]):
        body = (a.max(axis=2) > 0) | (b.max(axis=2) > 0)
        change = np.abs(b - a).max(axis=2)[body]
        means.append(change.mean())
        shares.append((change > VISIBLE_LEVELS).mean())
    return {"pixel_change": float(np.mean(means)), "pixels_changed": float(np.mean(shares))}


def flicker_run(
    surface: Callable[[np.ndarray], tuple], frames: list[np.ndarray], h: float, step: np.ndarray
) -> tuple[list[dict], list[tuple[np.ndarray, np.ndarray]]]:
    """Surface every frame with `surface` (positions -> (vertices, faces), or (vertices, faces,
    seconds) when it times itself); returns one row per frame (seconds, area, volume, and from
    the second frame on its change against the previous: `frame_change`, box edges apart, plus
    area_change / volume_change as fractions) and the meshes moved back."""
    rows, meshes = [], []
    for k, x in enumerate(frames):
        t0 = time.perf_counter()
        v, f, *timed = surface(x)
        seconds = timed[0] if timed else time.perf_counter() - t0
        v = np.asarray(v, np.float64) - k * step
        f = np.asarray(f, np.int64)
        volume, pieces = mesh_stats(v, f)
        row = {"frame": k, "seconds": seconds, "area": surface_area(v, f), "volume": volume, "components": pieces}
        if meshes:
            row.update(frame_change(meshes[-1], (v, f), h, edges=box_edges(v, h)))
            row["area_change"] = row["area"] / rows[-1]["area"] - 1.0
            row["volume_change"] = row["volume"] / rows[-1]["volume"] - 1.0
        rows.append(row)
        meshes.append((v, f))
    return rows, meshes


def ours(label: str, h: float, device: str | None = None) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Our surfacer at setting OURS[label] as a positions -> (vertices, faces) function."""
    setting = dict(OURS[label])
    voxel = setting.pop("voxel_h") * h
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=voxel, dense_output=False, **setting)

    def run(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mesh = surface_particles(x, None, params, device=device).mesh
        return mesh.vertices, mesh.faces

    return run


def peer(
    name: str, h: float, device: str | None = None
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, float]]:
    """Peer `name` at its bench settings for random samples as a positions -> (vertices, faces,
    seconds) function; seconds = its timed call (run_peer warms up first, untimed)."""

    def run(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        res = run_peer(name, x, h, "random", device=device, repeats=1)
        return res.vertices, res.faces, res.seconds

    return run


def summarise(method: str, rows: list[dict], n: int, h: float) -> dict:
    """One table row of a run: means over the frame pairs, and the worst pair's area / volume change."""
    pairs = rows[1:]

    def mean(key: str) -> float:
        return float(np.mean([r[key] for r in pairs]))

    return {
        "case": "moving random box",
        "particles": n,
        "h": h,
        "frames": len(rows),
        "method": method,
        "seconds": float(np.mean([r["seconds"] for r in rows])),
        "normal_jitter_h": mean("normal_jitter_h"),
        "normal_jitter_p99_h": mean("normal_jitter_p99_h"),
        "normal_turn_deg": mean("normal_turn_deg"),
        "normal_turn_p99_deg": mean("normal_turn_p99_deg"),
        "edge_turn_p99_deg": mean("edge_turn_p99_deg"),
        "area_change_max": float(max(abs(r["area_change"]) for r in pairs)),
        "volume_change_max": float(max(abs(r["volume_change"]) for r in pairs)),
        "components_max": int(max(r["components"] for r in rows)),
    }


def bench_flicker(
    count: int = FLICKER_COUNT,
    device: str | None = None,
    *,
    peers: Sequence[str] = (),
    frames: int = FLICKER_FRAMES,
    echo: bool = True,
) -> list[dict]:
    """The moving block with each of our settings and each peer; one summary row per method."""
    xs, h, step = moving_frames(count, frames=frames)
    surface_particles(xs[0][:500], None, SurfaceParams(h), device=device)  # compile
    methods = [(f"mpmfx {label}", ours(label, h, device)) for label in OURS]
    methods += [(name, peer(name, h, device)) for name in peers]
    out = Table(FLICKER_HEADER, format_flicker_row, echo=echo)
    for method, run in methods:
        try:
            rows, meshes = flicker_run(run, xs, h, step)
        except RUN_ERRORS as exc:
            print(f"flicker: {method} failed, no row: {exc}", flush=True)
            continue
        out.emit({**summarise(method, rows, len(xs[0]), h), **picture_change(meshes)})
    return list(out)


FLICKER_HEADER = (
    f"{'case':18} {'n':>7} {'method':16} {'s/frame':>7} {'jitter/h':>8} {'p99/h':>6} {'turn deg':>8} "
    f"{'p99 deg':>7} {'edge p99':>8} {'dA max':>7} {'dV max':>7} {'pieces':>6} {'px lvl':>6} "
    f"{'px >' + str(VISIBLE_LEVELS):>6}"
)


def format_flicker_row(r: dict) -> str:
    """One line of the flicker table (columns of FLICKER_HEADER; changes in %)."""
    return (
        f"{r['case']:18} {r['particles']:7d} {r['method']:16} {r['seconds']:7.3f} {r['normal_jitter_h']:8.4f} "
        f"{r['normal_jitter_p99_h']:6.3f} {r['normal_turn_deg']:8.2f} {r['normal_turn_p99_deg']:7.2f} "
        f"{r['edge_turn_p99_deg']:8.2f} "
        f"{r['area_change_max']:7.3%} {r['volume_change_max']:7.3%} {r['components_max']:6d} "
        + (f"{r['pixel_change']:6.2f} {r['pixels_changed']:6.2%}" if "pixel_change" in r else f"{'-':>6} {'-':>6}")
    )


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=FLICKER_COUNT)
    ap.add_argument("--frames", type=int, default=FLICKER_FRAMES)
    ap.add_argument("--device", default=None)
    ap.add_argument("--peers", nargs="*", default=[], help="splashsurf, newton, newton-aniso")
    ap.add_argument("--out", default=None, help="also write surface_flicker.csv/json here")
    args = ap.parse_args(argv)
    rows = bench_flicker(args.count, args.device, peers=args.peers, frames=args.frames)
    if args.out:
        print(f"table: {write_rows(rows, args.out, 'surface_flicker')} (+ .json)")


if __name__ == "__main__":
    main()
