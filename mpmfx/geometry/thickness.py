"""Thickness check: is every part of an asset at least a few grid cells thick?

Why (the tutorial "Material Point Method: Step by Step", "The five traps"): the quadratic
B-spline stencil spans three cells, so a feature about two cells thick has no interior particles and cannot carry a
bending moment, at any stiffness; around five cells across it survives. This module measures
the local thickness of a mesh in units of the simulation cell dx = size / grid_n.

World units (metres) throughout; "cells" means multiples of dx.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from mpmfx.geometry.inside import Lattice, inside_mask, signed_distance

# Raster used for measuring: up to this many samples per sim cell, and at most this many
# voxels in all (so a check stays within a few seconds on a laptop CPU).
SAMPLES_PER_CELL = 4
MAX_RASTER_VOXELS = 1_500_000
# A thin voxel is part of a real thin feature ("core") when it sits near the centre of the
# largest ball covering it: thickness <= _CORE_RATIO * its own inscribed diameter (+1 voxel).
# Slivers along a convex edge or corner of a thick body are covered by balls 3.4x (90 deg
# edge) or 2.4x (box corner) their depth and are not thin features; fins, rods and wedges
# sharper than ~20 deg are.
_CORE_RATIO = 1.2
# Radii every half voxel up to this multiple of warn_cells; above, 6 % steps (values there
# are at most one step low, and exact for slabs, rods and balls).
_FINE_UP_TO = 1.1
_COARSE_STEP = 1.06
# Thin features with less than this fraction of the object's volume (slivers at an ear tip, a
# fin of negligible volume) are listed but ignored by the verdict and by "grid_n to pass": they
# would otherwise set the grid for the whole object, and what the simulation loses there is
# a speck.
IGNORE_BELOW = 0.01


class Verdict(enum.Enum):
    """Outcome of a thickness check."""

    PASS = "pass"
    WARN = "warn"
    FAIL = "fail"


@dataclass
class ThinRegion:
    """One connected thin feature.

    bbox_min, bbox_max: (3,) float64 world corners (m). volume: m^3 of the thin voxels.
    thickness_cells: typical thickness of the region (median along its core), in sim cells
    (0 = thinner than the measuring raster, i.e. below 1 / samples-per-cell).
    """

    bbox_min: np.ndarray
    bbox_max: np.ndarray
    volume: float
    thickness_cells: float
    # Lower quartile along the core, cells: what min_grid_n_to_pass scales, as the median
    # reads high where a thin part widens into a thick one over a long fillet (fin on a ball).
    lower_quartile_cells: float = 0.0
    # Under IGNORE_BELOW of the object's volume: listed, but no part of the verdict.
    ignored: bool = False


@dataclass
class ThicknessReport:
    """Result of ``check_thickness``.

    asset: name. grid_n: sim cells per domain edge. dx: cell size (m).
    min_thickness_cells: thinnest feature, in cells. fraction_under: volume fraction of the
    asset in thin features under ``fail_cells``; fraction_thin: under ``warn_cells``;
    fraction_ignored: in features too small to count (``ignore_below``, a fraction of the
    asset's volume). regions: thin features (thickness < ``warn_cells``), thinnest first.
    min_grid_n_to_pass: smallest grid_n at which the thinnest feature that counts is
    ``warn_cells`` across. verdict: PASS/WARN/FAIL (rule: check_thickness).
    vertex_thickness_cells: (v,) float64 thickness at each mesh vertex, cells (heatmap).
    """

    asset: str
    grid_n: int
    dx: float
    min_thickness_cells: float
    fraction_under: float
    regions: list[ThinRegion]
    min_grid_n_to_pass: int
    verdict: Verdict
    warn_cells: float = 5.0
    fail_cells: float = 3.0
    fraction_thin: float = 0.0
    fraction_ignored: float = 0.0
    ignore_below: float = IGNORE_BELOW
    vertex_thickness_cells: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def to_dict(self) -> dict:
        """JSON-safe dict (no numpy types); the per-vertex array is left out."""
        return {
            "asset": self.asset,
            "grid_n": int(self.grid_n),
            "dx": float(self.dx),
            "warn_cells": float(self.warn_cells),
            "fail_cells": float(self.fail_cells),
            "min_thickness_cells": float(self.min_thickness_cells),
            "fraction_under": float(self.fraction_under),
            "fraction_thin": float(self.fraction_thin),
            "fraction_ignored": float(self.fraction_ignored),
            "ignore_below": float(self.ignore_below),
            "min_grid_n_to_pass": int(self.min_grid_n_to_pass),
            "verdict": self.verdict.value,
            "regions": [
                {
                    "bbox_min": [float(x) for x in r.bbox_min],
                    "bbox_max": [float(x) for x in r.bbox_max],
                    "volume": float(r.volume),
                    "thickness_cells": float(r.thickness_cells),
                    "ignored": bool(r.ignored),
                }
                for r in self.regions
            ],
        }

    def format_table(self) -> str:
        """Human-readable summary and one line per thin region."""
        lines = [
            f"asset {self.asset or '-'}: grid_n {self.grid_n}, dx {self.dx:.4g} m -> {self.verdict.name}",
            f"  thinnest feature   {self.min_thickness_cells:.2f} cells "
            f"(warn < {self.warn_cells:g}, fail < {self.fail_cells:g})",
            f"  volume under warn  {self.fraction_thin:.1%}",
            f"  volume under fail  {self.fraction_under:.1%}",
            f"  grid_n to pass     {self.min_grid_n_to_pass}",
        ]
        ignored = [r for r in self.regions if r.ignored]
        if ignored:
            lines.append(
                f"  ignored            {len(ignored)} feature{'s' * (len(ignored) != 1)} under "
                f"{self.ignore_below:.0%} of the volume each ({self.fraction_ignored:.2%} in all): too small "
                "to set the grid; the simulation may lose them"
            )
        if self.regions:
            lines.append(f"  {'region':>6}  {'cells':>6}  {'volume m^3':>11}  bbox min .. max (m)")
            for i, r in enumerate(self.regions):
                lo = ", ".join(f"{x:.3g}" for x in r.bbox_min)
                hi = ", ".join(f"{x:.3g}" for x in r.bbox_max)
                note = "  (ignored)" if r.ignored else ""
                lines.append(f"  {i:>6}  {r.thickness_cells:6.2f}  {r.volume:11.3g}  ({lo}) .. ({hi}){note}")
        return "\n".join(lines)


def local_thickness(inside: np.ndarray, *, voxel: float, fine_up_to: float | None = None) -> np.ndarray:
    """Local thickness (same shape, float64, metres; 0 outside) of a boolean voxel solid.

    The diameter of the largest ball that contains the voxel and fits inside the solid
    (Hildebrand & Ruegsegger 1997). The surface is taken halfway between inside and outside
    voxel centres. Radii are swept every half voxel up to ``fine_up_to`` metres of diameter
    (default: all), then in _COARSE_STEP ratios; each covered voxel takes the diameter of the
    actual ball that covers it, so values are within about one voxel of the truth.
    inside: (a, b, c) bool; voxels outside the array count as outside.
    """
    depth = ndimage.distance_transform_edt(np.pad(inside, 1))[1:-1, 1:-1, 1:-1]
    depth = np.where(inside, depth - 0.5, 0.0)
    thick = _thickness_from_depth(depth, fine_up_to / voxel if fine_up_to else None)
    return thick * voxel


def _thickness_from_depth(depth: np.ndarray, fine_up_to: float | None) -> np.ndarray:
    """Local thickness (float64, voxel units) from depth (distance to the surface, voxels).

    depth: (a, b, c) >= 0, 0 outside; sub-voxel accurate where it comes from the mesh.
    Sweeps radii r: every voxel within depth(c) + 0.5 of the nearest centre c whose depth
    is >= r gets 2 * ridge(c) (the ball's diameter; ridge: the depth's sub-voxel peak near
    c). The +0.5 keeps raster staircases at sloped faces from reading as thin.
    """
    padded = np.pad(depth, 1)
    ridge = _ridge_depth(padded)
    thick = 2.0 * np.where(padded > 0, ridge, 0.0)  # every voxel lies in its own ball
    max_r = float(padded.max())
    if max_r <= 0:
        return thick[1:-1, 1:-1, 1:-1]
    fine_r = max_r if fine_up_to is None else min(max_r, fine_up_to / 2.0 + 0.5)
    radii = list(np.arange(0.5, fine_r + 1e-9, 0.5))
    while radii[-1] * _COARSE_STEP < max_r:
        radii.append(radii[-1] * _COARSE_STEP)
    if radii[-1] < max_r:
        radii.append(max_r)
    for r in radii:
        if r > fine_r and r >= 8:
            _cover_coarse(padded, ridge, thick, r)
            continue
        dist, idx = ndimage.distance_transform_edt(padded < r, return_indices=True)
        c = tuple(idx)
        hit = (dist < padded[c] + 0.5) & (padded > 0)
        np.maximum(thick, np.where(hit, 2.0 * ridge[c], 0.0), out=thick)
    return thick[1:-1, 1:-1, 1:-1]


def _cover_coarse(depth, ridge, thick, r: float) -> None:
    """One radius of the sweep on a 2x coarser grid of block maxima (8x cheaper).

    The block's deepest voxel may sit up to sqrt(3)/2 voxel from the block centre, so
    the cover reaches that much further: small next to r >= 8.
    """
    shape = depth.shape
    pad = [(0, n % 2) for n in shape]
    blocks = [np.pad(a, pad) for a in (depth, ridge)]
    sub_d, sub_r = (
        b.reshape(b.shape[0] // 2, 2, b.shape[1] // 2, 2, b.shape[2] // 2, 2).max(axis=(1, 3, 5)) for b in blocks
    )
    dist, idx = ndimage.distance_transform_edt(sub_d < r, sampling=2.0, return_indices=True)
    c = tuple(idx)
    val = np.where(dist < sub_d[c] + 0.5 + 0.87, 2.0 * sub_r[c], 0.0)
    for axis in range(3):
        val = np.repeat(val, 2, axis=axis)
    val = val[: shape[0], : shape[1], : shape[2]]
    np.maximum(thick, np.where(depth > 0, val, 0.0), out=thick)


def _ridge_depth(depth: np.ndarray) -> np.ndarray:
    """Depth's peak near each voxel (same shape, voxels): the sampled depth plus the
    sub-voxel rise to a ridge that lies between it and an axis neighbour.

    Across a medial surface the depth is a tent (two straight flanks), so where voxels c
    and c+1 sit on opposite flanks (c-1 < c, c+2 < c+1) the peak is where the lines
    through (c-1, c) and (c+1, c+2) meet: exact for a slab's or a rod's ridge, and a flat
    top (a plateau) adds nothing. depth: padded by at least one zero voxel on every side.
    """
    up = np.zeros_like(depth)
    for axis in range(3):
        for step in (1, -1):
            a = np.roll(depth, step, axis)
            p = np.roll(depth, -step, axis)
            q = np.roll(depth, -2 * step, axis)
            s_left, s_right = depth - a, p - q
            ok = (s_left > 0) & (s_right > 0)
            den = np.where(ok, s_left + s_right, 1.0)
            x = np.clip((p - depth + s_right) / den, 0.0, 1.0)  # peak offset, voxels
            rise = np.minimum(s_left * x, np.minimum(x, p + 1.0 - x - depth))
            np.maximum(up, np.where(ok, rise, 0.0), out=up)
    return depth + up


def measuring_lattice(mesh, dx: float) -> Lattice:
    """Voxel-centre lattice over the mesh bbox (+1 voxel), SAMPLES_PER_CELL per cell, capped."""
    extent = np.asarray(mesh.extents, float)
    h = dx / SAMPLES_PER_CELL
    h = max(h, float(np.prod(extent + 2 * h) / MAX_RASTER_VOXELS) ** (1.0 / 3.0))
    shape = tuple(int(n) for n in np.ceil(extent / h).astype(int) + 3)
    # Centres start half a voxel (plus an odd fraction) below the bbox: one outside layer,
    # and no centre lands exactly on a face that is aligned with the bbox.
    origin = np.asarray(mesh.bounds[0], float) - (0.5 - 0.0137) * h
    return Lattice(origin=origin, h=h, shape=shape)


def check_thickness(
    mesh,
    *,
    grid_n: int,
    origin,
    size: float,
    warn_cells: float = 5.0,
    fail_cells: float = 3.0,
    name: str = "",
    ignore_below: float = IGNORE_BELOW,
) -> ThicknessReport:
    """Measure how many sim cells thick each part of ``mesh`` is.

    grid_n: cells per domain edge; origin (3,) m and size (m) define the domain, so
    dx = size / grid_n. The mesh is rasterised at up to 4 samples per cell (coarser for
    large assets, at most 1.5 M voxels) and its local thickness measured. Thin regions are
    connected groups of voxels thinner than ``warn_cells`` that contain a core (a voxel near
    the centre of its own inscribed ball: slivers along the convex edges of thick parts are
    not features). Parts thinner than the raster are found from mesh vertices with no inside
    voxel nearby and get thickness 0 (and at most one raster voxel times half their faces'
    area of volume). A region with under ``ignore_below`` of the asset's volume is ignored.

    Verdict rule, over the regions not ignored: FAIL if any thin region is under
    ``fail_cells``; WARN if any region is under ``warn_cells``; else PASS.
    min_grid_n_to_pass = ceil(warn_cells * size / (t - h / 2)), t: the smallest lower quartile
    of a region's thickness along its core (else t_min), h: the raster voxel (it reads faces
    up to h / 2 out), so that grid passes.
    """
    if grid_n < 1 or size <= 0 or not 0 < fail_cells <= warn_cells:
        raise ValueError(
            f"grid_n={grid_n}, size={size}, fail_cells={fail_cells}, "
            f"warn_cells={warn_cells}: need grid_n >= 1, size > 0 and "
            "0 < fail_cells <= warn_cells"
        )
    dx = float(size) / grid_n
    lat = measuring_lattice(mesh, dx)
    inside = inside_mask(mesh, lat)
    h = lat.h
    # Exact distance to the mesh (not to the nearest outside voxel): features only two or
    # three voxels across then read their true width instead of a whole odd voxel count.
    depth = np.maximum(-signed_distance(mesh, lat, inside).astype(np.float64), 0.0) / h
    # The mesh distance also counts faces buried in the solid (kit-bashed parts overlapping,
    # a model built of separate cubes): those are no surface. The distance to the nearest
    # outside voxel centre is never below the true depth and at most ~sqrt(3)/2 voxel above
    # it, so it minus one voxel is a floor that only buried faces push the mesh distance under.
    floor = ndimage.distance_transform_edt(np.pad(inside, 1))[1:-1, 1:-1, 1:-1] - 1.0
    depth = np.where(inside, np.maximum(depth, floor), 0.0)
    thick_v = _thickness_from_depth(depth, _FINE_UP_TO * warn_cells * dx / h)
    thick = thick_v * h  # metres
    thin = inside & (thick < warn_cells * dx)
    core = inside & (thick_v <= _CORE_RATIO * 2.0 * depth + 1.0)
    # The +1 voxel above lets the outermost voxels at a convex edge or corner (depth a few
    # hundredths of a voxel, ball < 1 voxel) pass as cores: a line of them along a box edge
    # read as a 0.1-cell feature. A voxel next to one covered by a ball more than twice its
    # own (+2 voxels) is the raster's edge of that thick body, not a feature.
    core &= ndimage.maximum_filter(thick_v, size=3) <= 2.0 * thick_v + 2.0
    labels, _ = ndimage.label(thin, structure=np.ones((3, 3, 3)))
    # A feature needs a core of at least one sim cell's worth of voxels; fewer are
    # staircase artefacts of the raster at curved or sloped faces.
    min_core = max(2, int(round(dx / h)))
    core_count = np.bincount(labels[thin & core], minlength=labels.max() + 1)
    cored = np.flatnonzero(core_count >= min_core)
    cored = cored[cored > 0]
    regions = _regions(labels, cored, thick, core, lat, dx, min_core)
    in_feature = np.isin(labels, cored) & thin
    # Edge slivers show as "fine" (warn) in the heatmap rather than as false thin spots.
    shown = np.where(thin & ~in_feature, warn_cells * dx, thick)
    vertex_cells, lost = _vertex_thickness(mesh, inside, shown, lat)
    vertex_cells /= dx
    lost_regions = _lost_regions(mesh, lost, min_extent=dx, depth=h)
    regions += lost_regions
    regions.sort(key=lambda r: r.thickness_cells)
    volume = max(1, int(inside.sum())) * h**3
    for r in regions:
        r.ignored = r.volume < ignore_below * volume
    ignored = sum(r.volume for r in regions if r.ignored) / volume
    thin_volume = float(in_feature.sum()) * h**3 + sum(r.volume for r in lost_regions)
    all_regions, regions = regions, [r for r in regions if not r.ignored]

    if regions:
        t_min = regions[0].thickness_cells * dx
    else:
        thick_core = thick[core & ~thin]
        t_min = float(thick_core.min()) if thick_core.size else float(thick.max())
    under = float((in_feature & (thick < fail_cells * dx)).sum()) / max(1, int(inside.sum()))
    verdict = Verdict.PASS
    if regions:
        worst = regions[0].thickness_cells
        verdict = Verdict.FAIL if worst < fail_cells else Verdict.WARN
    # Unresolved parts are thinner than one raster voxel: use that as their upper bound.
    # The raster reads a face up to half a voxel out (never thinner than the truth, as
    # measured on slabs at random offsets): scale from the thinnest the part can be, so
    # the grid_n given passes when re-run.
    if regions:
        t_min_q = min(r.lower_quartile_cells for r in regions) * dx
        t_pass = min(t_min, t_min_q)
    else:
        t_pass = t_min
    t_pass = t_pass - 0.5 * h if t_pass > h else h
    # The 1e-4 margin: a part exactly warn_cells thick at some grid measures a hair under
    # it there (float32 distances), so that grid would still warn.
    need = int(math.ceil(warn_cells * size / t_pass * (1.0 + 1e-4)))
    return ThicknessReport(
        asset=name,
        grid_n=int(grid_n),
        dx=dx,
        min_thickness_cells=t_min / dx,
        fraction_under=under,
        regions=all_regions,
        min_grid_n_to_pass=need,
        verdict=verdict,
        warn_cells=warn_cells,
        fail_cells=fail_cells,
        fraction_thin=min(1.0, thin_volume / volume),
        fraction_ignored=ignored,
        ignore_below=ignore_below,
        vertex_thickness_cells=vertex_cells,
    )


def _regions(labels, cored, thick, core, lat: Lattice, dx: float, min_core: int) -> list[ThinRegion]:
    out = []
    slices = ndimage.find_objects(labels)
    for lab in cored:
        if lab == 0:
            continue
        sl = slices[lab - 1]
        sub = labels[sl] == lab
        offset = np.array([s.start for s in sl])
        parts = _split_features(sub & core[sl], thick[sl], dx=dx, h=lat.h, min_core=min_core)
        for mask, t, _ in parts:
            # The feature: its thin voxels within half its thickness (+1 voxel) of its core.
            # Edge slivers of thick parts that merely touch it lie further and are left out
            # (else a wall's box would span the whole body it stands on).
            reach = ndimage.distance_transform_edt(~mask) * lat.h <= t / 2 + lat.h
            idx = np.argwhere(sub & reach)
            lo, hi = offset + idx.min(0), offset + idx.max(0)
            out.append(
                ThinRegion(
                    bbox_min=lat.points(lo[None])[0] - lat.h / 2,
                    bbox_max=lat.points(hi[None])[0] + lat.h / 2,
                    volume=float(len(idx)) * lat.h**3,
                    thickness_cells=float(t) / dx,
                    lower_quartile_cells=float(np.percentile(thick[sl][mask], 25)) / dx,
                )
            )
    return out


def _split_features(core, thick, *, dx: float, h: float, min_core: int, levels: int = 4):
    """[(core mask, thickness m, is_rest), ...]: the features of one thin component.

    core: (a, b, c) bool core voxels of the component; thick: same shape, metres; dx, h:
    sim cell and raster voxel (m). is_rest: the part left after thinner features are split off.
    A feature reads the median thickness along its core, not its minimum: features that
    taper to a point (cone tips, limbs pinched at their joints) would read 0 however thick
    they are elsewhere, and a neck shorter than a cell does not part the simulated body.
    But thin parts of different thickness touch (a one-cube wall on a two-cube base): core
    voxels a cell or more under the median that form a part longer than twice its own
    thickness are a feature of their own (a taper's tip or a neck is shorter than that),
    measured the same way; the rest keeps the median of what is left.
    """
    t = float(np.median(thick[core]))
    out, rest = [], core.copy()
    lower = core & (thick < t - dx)
    if levels > 0 and lower.sum() >= min_core:
        lab, _ = ndimage.label(lower, structure=np.ones((3, 3, 3)))
        for k, sl in enumerate(ndimage.find_objects(lab), start=1):
            part = np.zeros_like(core)
            part[sl] = lab[sl] == k
            n = int(part[sl].sum())
            if n < min_core:
                continue
            tk = float(np.median(thick[part]))
            extent = max(s.stop - s.start for s in sl) * h
            if extent >= max(2.0 * tk, dx):
                sub = _split_features(part, thick, dx=dx, h=h, min_core=min_core, levels=levels - 1)
                out += [(m, tm, False) for m, tm, _ in sub]
                rest &= ~part
    if rest.sum() >= min_core or not out:
        out.append((rest if out else core, float(np.median(thick[rest if out else core])), True))
    return out


def _vertex_thickness(mesh, inside, shown, lat: Lattice):
    """Per-vertex thickness (v,) metres from the nearest inside surface voxel, and a (v,)
    bool mask of vertices with no inside voxel among the 3 x 3 x 3 centres around them
    (unresolved features). Vertices buried in the solid (kit-bashed parts overlapping, a
    box's corner inside another) are far from the skin but not lost: inside voxels surround
    them."""
    verts = np.asarray(mesh.vertices, float)
    skin = inside & ~ndimage.binary_erosion(inside)
    idx = np.argwhere(skin)
    if len(idx) == 0:
        return np.zeros(len(verts)), np.ones(len(verts), bool)
    _, nearest = cKDTree(lat.points(idx)).query(verts)
    values = shown[tuple(idx[nearest].T)]
    # The 3 x 3 x 3 block reaches at least 1.5 h: a cube corner can be sqrt(3)/2 h from
    # its nearest centre, so a resolved corner always has an inside centre in it.
    near = ndimage.binary_dilation(inside, structure=np.ones((3, 3, 3), bool))
    cell = np.clip(np.rint((verts - lat.origin) / lat.h).astype(np.int64), 0, np.array(lat.shape) - 1)
    lost = ~near[tuple(cell.T)]
    return np.where(lost, 0.0, values), lost


def _lost_regions(mesh, lost: np.ndarray, *, min_extent: float, depth: float) -> list[ThinRegion]:
    """Group unresolved vertices along mesh edges into regions of thickness 0.

    Groups spanning less than ``min_extent`` (m; one sim cell) are left out: they are the
    points of cones and pinched joints (vertices that meet within a raster voxel), whose
    neighbourhood the raster resolves, not sheets or wires thinner than the raster. A region's
    volume is at most half the area of its faces (a sheet has two sides) times ``depth`` (m,
    the raster voxel it is thinner than).
    """
    if not lost.any():
        return []

    e = np.asarray(mesh.edges_unique)
    e = e[lost[e[:, 0]] & lost[e[:, 1]]]
    n = len(lost)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    verts = np.asarray(mesh.vertices, float)
    faces = np.asarray(mesh.faces)
    lost_faces = lost[faces].all(axis=1)
    face_comp, face_area = comp[faces[lost_faces, 0]], np.asarray(mesh.area_faces)[lost_faces]
    out = []
    for c in np.unique(comp[lost]):
        v = verts[(comp == c) & lost]
        if np.linalg.norm(v.max(0) - v.min(0)) < min_extent:
            continue
        volume = 0.5 * float(face_area[face_comp == c].sum()) * depth
        out.append(ThinRegion(bbox_min=v.min(0), bbox_max=v.max(0), volume=volume, thickness_cells=0.0))
    return out


def refine_for_heatmap(mesh, *, grid_n: int, size: float, max_faces: int = 2_000_000):
    """`mesh` with no edge longer than one sim cell, so per-vertex thickness can be shown on
    long faces (a box fin has only corner vertices). Same geometry; capped at `max_faces`."""
    dx = size / grid_n
    if len(mesh.faces) >= max_faces or mesh.edges_unique_length.max() <= dx:
        return mesh
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=dx, max_iter=12)
    return mesh if len(f) > max_faces else trimesh.Trimesh(v, f, process=False)
