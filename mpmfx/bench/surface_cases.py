"""Accuracy and speed benchmark of the surfacer on particles sampled inside analytic shapes.

Error = distance of output vertices to the analytic surface, in
world units and in units of the particle spacing h, and the mesh's area-weighted distance
(`surface_error`: the vertex mean moves with where a flat face sits between voxel planes); volume error of the closed mesh against
the analytic volume; number of connected mesh pieces (1 = no interior bubbles, no specks);
jitter = how far the vertices move between two frames of a body at rest (ours only; see
`surface_jitter.rest_jitter`); moving = the same for a slowly moving body, measured against
the moved surface (`surface_jitter.moving_jitter`).
The peers (mpmfx.bench.surface_peers: splashsurf, Newton) run on the same particles and get
the same columns. Our surfacer runs at the shipped particle radius
(mpmfx.surface.PARTICLE_RADIUS_PER_SPACING x h).

    python -m mpmfx.bench.surface_cases --counts 100000 --device cpu --peers splashsurf
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Sequence

import numpy as np
import warp as wp
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from mpmfx.bench.surface_jitter import moving_jitter, rest_jitter
from mpmfx.bench.surface_peers import run_peer
from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles

SPHERE_RADIUS = 0.3
TORUS_RADII = (0.3, 0.12)  # major, minor; axis z
BOX_HALF = np.array([0.3, 0.2, 0.25])


def shape_sdf(shape: str) -> tuple[Callable[[np.ndarray], np.ndarray], float, np.ndarray]:
    """(signed distance of (n, 3) points, analytic volume m^3, (3,) half extent of the bounds)."""
    if shape == "sphere":
        return (
            (lambda p: np.linalg.norm(p, axis=1) - SPHERE_RADIUS),
            4 / 3 * math.pi * SPHERE_RADIUS**3,
            np.full(3, SPHERE_RADIUS),
        )
    if shape == "torus":
        big, small = TORUS_RADII

        def torus(p: np.ndarray) -> np.ndarray:
            q = np.hypot(np.hypot(p[:, 0], p[:, 1]) - big, p[:, 2])
            return q - small

        return torus, 2 * math.pi**2 * big * small**2, np.array([big + small, big + small, small])
    if shape == "box":

        def box(p: np.ndarray) -> np.ndarray:
            q = np.abs(p) - BOX_HALF
            return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

        return box, float(np.prod(2 * BOX_HALF)), BOX_HALF.copy()
    raise ValueError(f"bench shape {shape!r}: use one of sphere, torus, box")


def sample_shape(
    shape: str, count: int, sampling: str, *, seed: int = 0, jitter: float = 0.0
) -> tuple[np.ndarray, float]:
    """About `count` particles inside `shape`; returns ((n, 3) float32 positions m, spacing h m).

    lattice: cell centres of a cubic lattice of spacing h, each moved by up to +-jitter * h
    per axis (uniform); random:
    uniform in the volume (what MPM particles after a simulation resemble more), same count.
    """
    sdf, volume, half = shape_sdf(shape)
    h = (volume / count) ** (1 / 3)
    if shape == "box" and sampling == "lattice":
        # half extents 0.3 : 0.2 : 0.25 are multiples of 0.05, so h = 0.1 / k lays whole cells
        # on every face: the particles then sample exactly the analytic box (sharp edges).
        h = 0.1 / max(1, round(0.1 / h))
    rng = np.random.default_rng(seed)
    if sampling == "lattice":
        axes = [np.arange(-hx, hx, h) + h / 2 for hx in half]
        p = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        p = p - (p.max(axis=0) + p.min(axis=0)) / 2  # symmetric about the shape's centre
        if jitter:
            p = p + rng.uniform(-jitter * h, jitter * h, size=p.shape)
    elif sampling == "random":
        box_volume = float(np.prod(2 * half))
        p = rng.uniform(-half, half, size=(int(count * box_volume / volume * 1.2) + 64, 3))
    else:
        raise ValueError(f"bench sampling {sampling!r}: use lattice or random")
    p = p[sdf(p) < 0]
    if sampling == "random":
        p = p[:count]
    return p.astype(np.float32), h


def mesh_stats(vertices: np.ndarray, faces: np.ndarray) -> tuple[float, int]:
    """(enclosed volume m^3 by the divergence theorem, number of connected pieces)."""
    if len(faces) == 0:
        return 0.0, 0

    t = vertices[faces].astype(np.float64)
    volume = float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    n = len(vertices)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    used = np.unique(faces)
    _, labels = connected_components(graph, directed=False)
    return volume, len(np.unique(labels[used]))


_AREA_POINTS = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
"""Barycentric points of the 3-point rule (exact for quadratics) that surface_error samples each triangle at."""


def surface_error(vertices: np.ndarray, faces: np.ndarray, sdf: Callable[[np.ndarray], np.ndarray]) -> float:
    """Mean distance of the mesh's surface to the analytic one (m): |sdf| averaged over the
    triangles by area. The vertex mean samples the surface where marching cubes puts vertices,
    on grid edges, so it depends on where a flat face sits between voxel planes: the 1M random
    box at "fast" reads 0.104-0.123 h as the box moves by fractions of a voxel, while this
    reads the same at every offset."""
    if len(faces) == 0:
        return float("nan")
    t = np.asarray(vertices, np.float64)[faces]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    err = np.mean([np.abs(sdf(np.einsum("j,ijk->ik", b, t))) for b in _AREA_POINTS], axis=0)
    return float((err * area).sum() / max(area.sum(), 1e-300))


def _row(
    shape: str,
    sampling: str,
    x: np.ndarray,
    h: float,
    method: str,
    grid: str,
    seconds: float,
    verts: np.ndarray,
    faces: np.ndarray,
) -> dict:
    """One result row: timing, vertex distance to the analytic surface (m and h) and the
    surface's area-weighted distance (surface_error), volume, pieces."""
    sdf, volume, _ = shape_sdf(shape)
    err = np.abs(sdf(np.asarray(verts, np.float64))) if len(verts) else np.array([np.nan])
    surf = surface_error(verts, faces, sdf)
    mesh_volume, pieces = mesh_stats(verts, faces)
    return {
        "shape": shape,
        "sampling": sampling,
        "particles": len(x),
        "h": h,
        "method": method,
        "grid": grid,
        "seconds": seconds,
        "particles_per_s": len(x) / seconds,
        "err_mean": float(err.mean()),
        "err_p99": float(np.percentile(err, 99)),
        "err_max": float(err.max()),
        "err_mean_h": float(err.mean() / h),
        "err_surface_h": surf / h,
        "err_p99_h": float(np.percentile(err, 99) / h),
        "err_max_h": float(err.max() / h),
        "volume_err": mesh_volume / volume - 1.0,
        "components": pieces,
        "vertices": len(verts),
    }


SHEET_RADIUS = 0.3
"""Radius of the thin-sheet case (m): a disc one particle spacing thick (a water sheet)."""


def sample_sheet(count: int, sampling: str, *, seed: int = 0) -> tuple[np.ndarray, float]:
    """About `count` particles in a disc of radius SHEET_RADIUS and thickness h, axis z, centred
    at 0; returns ((n, 3) float32 positions m, spacing h m). lattice: one square layer at z = 0;
    random: uniform in the slab |z| < h / 2 at the same number density 1 / h^3 (a splash sheet)."""
    h = math.sqrt(math.pi * SHEET_RADIUS**2 / count)
    rng = np.random.default_rng(seed)
    if sampling == "lattice":
        a = np.arange(-SHEET_RADIUS, SHEET_RADIUS, h) + h / 2
        p = np.stack(np.meshgrid(a, a, [0.0], indexing="ij"), -1).reshape(-1, 3)
    elif sampling == "random":
        p = rng.uniform(
            [-SHEET_RADIUS, -SHEET_RADIUS, -h / 2], [SHEET_RADIUS, SHEET_RADIUS, h / 2], size=(int(count * 1.3), 3)
        )
    else:
        raise ValueError(f"bench sampling {sampling!r}: use lattice or random")
    p = p[np.hypot(p[:, 0], p[:, 1]) < SHEET_RADIUS][:count]
    return p.astype(np.float32), h


def sheet_stats(vertices: np.ndarray, faces: np.ndarray, h: float) -> dict:
    """What a thin sheet's surface is judged by: pieces (connected components), holes (total genus
    from the Euler characteristic V - E + F = sum over pieces of 2 - 2 genus: each hole through
    the sheet is a handle), open edges (used by one triangle; 0 for a closed mesh) and the
    thickness error (mean 2|z| over h, minus 1, of the vertices more than 2 h inside the rim)."""
    if len(faces) == 0:
        return {"components": 0, "holes": 0, "open_edges": 0, "thickness_err": float("nan")}
    _, pieces = mesh_stats(vertices, faces)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1).astype(np.int64)
    # an edge as one int64 key: np.unique over rows (axis=0) took ~1 min a row at the 1M sheet
    edges, uses = np.unique(e[:, 0] * (int(e.max()) + 1) + e[:, 1], return_counts=True)
    euler = len(np.unique(faces)) - len(edges) + len(faces)
    v = np.asarray(vertices, np.float64)
    flat = np.hypot(v[:, 0], v[:, 1]) < SHEET_RADIUS - 2 * h
    thickness = float(2 * np.abs(v[flat, 2]).mean() / h - 1.0) if flat.any() else float("nan")
    return {
        "components": pieces,
        "holes": int(round((2 * pieces - euler) / 2)),
        "open_edges": int((uses == 1).sum()),
        "thickness_err": thickness,
    }


def measure_sheet(
    count: int,
    sampling: str,
    *,
    label: str = "fine",
    device: str | None = None,
    radius_factor: float = PARTICLE_RADIUS_PER_SPACING,
    **overrides,
) -> dict:
    """Our surfacer (setting OURS[label], plus SurfaceParams `overrides`, e.g. anisotropic=True)
    on the thin-sheet case: time (s, whole call), pieces, holes, open edges, thickness error."""
    x, h = sample_sheet(count, sampling)
    setting = {**OURS[label], **overrides}
    voxel_h = setting.pop("voxel_h")
    params = SurfaceParams(particle_radius=radius_factor * h, voxel_size=voxel_h * h, dense_output=False, **setting)
    t0 = time.perf_counter()
    res = surface_particles(x, None, params, device=device)
    seconds = time.perf_counter() - t0
    method = (
        f"mpmfx {label}"
        + (" anisotropic" if overrides.pop("anisotropic", False) else "")
        + "".join(f" {k}={v}" for k, v in overrides.items())
    )
    settings = f"r {radius_factor:g}h voxel {voxel_h:g}h smooth {params.smooth_iters}"
    return {
        "shape": "sheet",
        "sampling": sampling,
        "particles": len(x),
        "h": h,
        "method": method,
        "seconds": seconds,
        **sheet_stats(res.mesh.vertices, res.mesh.faces, h),
        "vertices": len(res.mesh.vertices),
        "device": str(wp.get_device(device)),
        "settings": settings,
    }


def measure_sheet_peer(name: str, count: int, sampling: str, *, device: str | None = None, repeats: int = 1) -> dict:
    """Peer `name` (mpmfx.bench.surface_peers.PEERS) on the very particles `measure_sheet` sees, with
    the settings the bench gives it for `sampling`: the same columns, plus its device and settings.
    splashsurf 0.14 has no anisotropic kernel (its Laplacian mesh smoothing moves vertices but
    keeps the topology: holes unchanged, measured), so its row is its isotropic colour field;
    "newton-aniso" is Newton's Yu & Turk mode. Time: median of `repeats` after a warm-up."""
    x, h = sample_sheet(count, sampling)
    res = run_peer(name, x, h, sampling, device=device, repeats=repeats)
    return {
        "shape": "sheet",
        "sampling": sampling,
        "particles": len(x),
        "h": h,
        "method": res.name,
        "seconds": res.seconds,
        **sheet_stats(res.vertices, res.faces, h),
        "vertices": len(res.vertices),
        "device": res.device,
        "settings": res.settings,
    }


def measure(
    shape: str,
    count: int,
    sampling: str,
    *,
    radius_factor: float = PARTICLE_RADIUS_PER_SPACING,
    device: str | None = None,
    sample: tuple[np.ndarray, float] | None = None,
    repeats: int = 1,
    label: str = "",
    voxel_h: float | None = None,
    **overrides,
) -> dict:
    """Reconstruct one sample with our surfacer and measure it (particle_radius = radius_factor * h).

    sample: (x (n, 3) float32 m, h m) from `sample_shape`, to reuse the peers' particles; None
      samples `shape` here. repeats > 1: one untimed warm-up, then the median of `repeats`.
    label: names the row "mpmfx <label>"; voxel_h: voxel_size = voxel_h * h (None: SurfaceParams'
    default); overrides: other SurfaceParams fields.
    On a CUDA device x is uploaded before the timer, as the peers' particles are, and passed
    as a device array. "seconds" is the device work (SurfaceResult.stats["device"]),
    "seconds_host" the whole call including the copy of the result to the host.
    """
    x, h = sample if sample is not None else sample_shape(shape, count, sampling)
    if voxel_h is not None:
        overrides["voxel_size"] = voxel_h * h
    params = SurfaceParams(particle_radius=radius_factor * h, **overrides)
    wp.init()
    dev = wp.get_device(device)
    x_in = x if dev.is_cpu else wp.array(x, dtype=wp.vec3, device=dev)
    times, on_device = [], []
    for _ in range(repeats + 1 if repeats > 1 else 1):  # + 1: the untimed warm-up
        t0 = time.perf_counter()
        res = surface_particles(x_in, None, params, device=device)
        wp.synchronize_device(dev)
        times.append(time.perf_counter() - t0)
        on_device.append(res.stats.get("device", times[-1]))
    keep = slice(1, None) if repeats > 1 else slice(None)
    # end to end = particles on the device -> level set and mesh on the device (as the peers'
    # times are taken); copying the result to the host is reported apart (seconds_host)
    seconds, seconds_host = float(np.median(on_device[keep])), float(np.median(times[keep]))
    if res.level_set.values.size == 0:
        grid_txt = f"{len(res.sparse.block_ijk)}blk"
    else:
        grid_txt = "x".join(map(str, res.level_set.values.shape))
    method = f"mpmfx {label}" if label else "mpmfx"
    row = _row(shape, sampling, x, h, method, grid_txt, seconds, res.mesh.vertices, res.mesh.faces)
    settings = f"r {radius_factor:g}h voxel {params.resolved_voxel_size / h:g}h smooth {params.smooth_iters}"
    if params.min_feature_particles:
        settings += f" specks<{params.min_feature_particles}"
    jitter, repeat = rest_jitter(x, h, params, res, device=device)
    return {
        **row,
        "seconds_host": seconds_host,
        "device": str(dev),
        "settings": settings,
        "stages": res.stats,
        "jitter_h": jitter,
        "repeat_h": repeat,
        "moving_h": moving_jitter(x, h, params, res, device=device),
    }


def measure_peer(
    name: str,
    shape: str,
    sampling: str,
    sample: tuple[np.ndarray, float],
    *,
    device: str | None = None,
    repeats: int = 3,
) -> dict:
    """Peer `name` (mpmfx.bench.surface_peers.PEERS) on `sample` = (x (n, 3) m, h m); one row like ours."""
    x, h = sample
    res = run_peer(name, x, h, sampling, device=device, repeats=repeats)
    row = _row(shape, sampling, x, h, res.name, "-", res.seconds, res.vertices, res.faces)
    return {**row, "device": res.device, "settings": res.settings, "stages": {}}


OURS = {
    # voxel = r (0.6 h) and four smoothing steps: the speed setting (with sharp edges, as a shot
    # with those two knobs gets them)
    "fast": {"voxel_h": PARTICLE_RADIUS_PER_SPACING, "smooth_iters": 4, "sharp_edges": True},
    # what shots run with (the surface stage's defaults: mpmfx/stages/surface.py, config.Surface):
    # voxel h / 2, eight smoothing steps, blobs of fewer than 8 particles removed, sharp edges
    "fine": {"voxel_h": 0.5, "smooth_iters": 8, "min_feature_particles": 8, "sharp_edges": True},
    # "fine" with surface.sharp_edges = false: edges and corners as the kernels round them
    "round": {"voxel_h": 0.5, "smooth_iters": 8, "min_feature_particles": 8, "sharp_edges": False},
}
"""Our settings in the benchmark: label -> `measure` keywords (voxel_h x particle spacing h)."""


def bench_surface(
    counts: Sequence[int] = (100_000,),
    shapes: Sequence[str] = ("sphere", "torus", "box"),
    samplings: Sequence[str] = ("lattice", "random"),
    device: str | None = None,
    *,
    peers: Sequence[str] = (),
    repeats: int = 1,
    echo: bool = True,
    dense_output: bool = False,
    stages: bool = False,
) -> list[dict]:
    """Measure every (count, shape, sampling) with each of our settings (OURS) and each peer
    (mpmfx.bench.surface_peers.PEERS), all on the same particles; print a table when `echo`.

    repeats > 1: every method gets one untimed warm-up, then the median of `repeats` calls.
    Sparse runs return only the sparse level set unless `dense_output` (dense arrays cost
    O(bounding box) to fill and copy to the host). A peer that fails at run time (out of
    memory, say) is reported and left out; the others go on.
    """
    surface_particles(sample_shape("sphere", 500, "lattice")[0], None, SurfaceParams(0.01), device=device)  # compile
    rows: list[dict] = []

    def emit(row: dict, count: int) -> None:
        row["count"] = count  # the requested count: lattices hold about that many
        rows.append(row)
        if echo:
            print(format_row(row), flush=True)
            if stages and row["stages"]:
                print("  stages (cumulative s):", row["stages"], flush=True)

    for count in counts:
        for shape in shapes:
            for sampling in samplings:
                sample = sample_shape(shape, count, sampling)
                for label, setting in OURS.items():
                    emit(
                        measure(
                            shape,
                            count,
                            sampling,
                            device=device,
                            sample=sample,
                            repeats=repeats,
                            label=label,
                            dense_output=dense_output,
                            **setting,
                        ),
                        count,
                    )
                for name in peers:
                    try:
                        emit(measure_peer(name, shape, sampling, sample, device=device, repeats=repeats), count)
                    except (RuntimeError, MemoryError, ValueError) as exc:
                        print(f"{shape} {sampling} {len(sample[0])}: peer {name} failed, no row: {exc}", flush=True)
    return rows


SHEET_COUNTS = {"quick": 20_000, "full": 1_000_000}
"""Particles in the thin-sheet case: CPU-sized for --quick, GPU-sized for the full run."""


RUN_ERRORS = (RuntimeError, MemoryError, ValueError)  # a method failing at run time: reported, no row


class Table(list):
    """A bench table's rows, each printed with `fmt` as it comes when `echo` (header first)."""

    def __init__(self, header: str, fmt: Callable[[dict], str], *, echo: bool = True):
        super().__init__()
        self.fmt, self.echo = fmt, echo
        if echo:
            print(header, flush=True)

    def emit(self, row: dict) -> None:
        self.append(row)
        if self.echo:
            print(self.fmt(row), flush=True)

    def attempt(self, what: str, make: Callable[[], dict]) -> None:
        """emit(make()), or say that `what` failed and add no row (one failing peer must not
        lose the rest of the table)."""
        try:
            row = make()
        except RUN_ERRORS as exc:
            print(f"{what} failed, no row: {exc}", flush=True)
            return
        self.emit(row)


def bench_sheet(count: int, device: str | None = None, *, peers: Sequence[str] = (), echo: bool = True) -> list[dict]:
    """The thin-sheet case (a disc one spacing thick, lattice and random) with each of our
    settings, isotropic and anisotropic, and each peer on the same particles (`measure_sheet_peer`;
    one that fails at run time is reported and left out): pieces, holes, open edges, thickness
    error, time."""
    for label in OURS:  # load every setting's kernels first: on a fresh GPU machine a module's first
        for aniso in (False, True):  # load compiles it (a minute, which would land in the first row)
            measure_sheet(500, "random", label=label, device=device, anisotropic=aniso)
    rows = Table(SHEET_HEADER, format_sheet_row, echo=echo)
    for sampling in ("lattice", "random"):
        for label in OURS:
            for aniso in (False, True):
                rows.emit(
                    {**measure_sheet(count, sampling, label=label, device=device, anisotropic=aniso), "count": count}
                )
        for name in peers:
            rows.attempt(
                f"sheet {sampling} {count}: peer {name}",
                lambda: {**measure_sheet_peer(name, count, sampling, device=device), "count": count},
            )
    return list(rows)


SHEET_HEADER = (
    f"{'shape':7} {'sampling':8} {'n':>8} {'method':34} {'time s':>7} {'pieces':>6} {'holes':>6} {'open':>5} "
    f"{'thick err':>9} {'device':>7}  settings"
)


def format_sheet_row(r: dict) -> str:
    """One line of the thin-sheet table (columns of SHEET_HEADER; thickness error in h)."""
    return (
        f"{r['shape']:7} {r['sampling']:8} {r['particles']:8d} {r['method']:34} {r['seconds']:7.3f} "
        f"{r['components']:6d} {r['holes']:6d} {r['open_edges']:5d} {r['thickness_err']:+9.3f} "
        f"{r.get('device', ''):>7}  {r.get('settings', '')}"
    )


HEADER = (
    f"{'shape':7} {'sampling':8} {'n':>8} {'method':18} {'grid':>13} {'time s':>7} {'+host':>6} {'Mp/s':>6} "
    f"{'mean/h':>7} {'surf/h':>7} {'p99/h':>6} {'max/h':>6} {'mean m':>9} {'max m':>9} {'vol err':>8} {'pieces':>6} "
    f"{'jitter/h':>8} {'moving/h':>8} {'device':>7}  settings"
)


def _host(r: dict) -> str:
    """Seconds including the copy of the result to the host (ours only), or '-'."""
    return f"{r['seconds_host']:6.3f}" if "seconds_host" in r else "-"


def _jitter(r: dict) -> str:
    """Vertex jitter of a body at rest (ours only), or '-'."""
    return f"{r['jitter_h']:8.4f}" if "jitter_h" in r else "-"


def _moving(r: dict) -> str:
    """Flicker of a slowly moving body (ours only), or '-'."""
    return f"{r['moving_h']:8.4f}" if "moving_h" in r else "-"


def format_row(r: dict) -> str:
    """One line of the printed table (columns of HEADER)."""
    return (
        f"{r['shape']:7} {r['sampling']:8} {r['particles']:8d} {r['method']:18} {r['grid']:>13} "
        f"{r['seconds']:7.3f} {_host(r):>6} {r['particles_per_s'] / 1e6:6.2f} {r['err_mean_h']:7.3f} {r['err_surface_h']:7.3f} "
        f"{r['err_p99_h']:6.3f} {r['err_max_h']:6.2f} {r['err_mean']:9.2e} {r['err_max']:9.2e} {r['volume_err']:+8.2%} {r['components']:6d} "
        f"{_jitter(r):>8} {_moving(r):>8} {r.get('device', ''):>7}  {r.get('settings', '')}"
    )


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[100_000])
    ap.add_argument("--shapes", nargs="+", default=["sphere", "torus", "box"])
    ap.add_argument("--samplings", nargs="+", default=["lattice", "random"])
    ap.add_argument("--stages", action="store_true", help="print our cumulative stage times")
    ap.add_argument("--dense-output", action="store_true", help="also return dense arrays (slower)")
    ap.add_argument("--device", default=None)
    ap.add_argument(
        "--peers", nargs="*", default=[], help="also run these on the same particles: splashsurf, newton, newton-aniso"
    )
    ap.add_argument("--repeats", type=int, default=1, help="> 1: warm-up, then the median of this many")
    ap.add_argument("--sheet", type=int, default=0, help="also the thin-sheet case with this many particles")
    args = ap.parse_args(argv)
    print(HEADER)
    bench_surface(
        args.counts,
        args.shapes,
        args.samplings,
        args.device,
        peers=args.peers,
        repeats=args.repeats,
        stages=args.stages,
        dense_output=args.dense_output,
    )
    if args.sheet:
        bench_sheet(args.sheet, args.device, peers=args.peers)


if __name__ == "__main__":
    main()
