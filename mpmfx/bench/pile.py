"""The poured pile of `mpmfx bench accuracy`: sand poured from a hopper heaps into a cone, and
the cone's slope is compared with the material's friction angle.

A quarter pile in the corner of a 1 m domain (g = 9.81 domain/s^2): the -x and -z walls are
`slip` symmetry planes (frictionless, the material may not leave them), the floor is `sticky`
(a rough base, as a pile on a table), the other walls are far away. The hopper's outlet, a
square quarter box in the corner `drop` above the floor, emits the Granular preset downwards
at a steady rate for `pour_time` s, as an `[[emitters]]` box does (mpmfx/geometry/emitters.py):
its lattice, downstream first, refilled with seeded jitter, particle j born at
(j + 1/2) v_p / rate, at the speed rate / outlet area so the fills leave as an even stream.
It pours the volume of a cone of radius `radius` at the friction angle, then rests
`settle_time` s. The solver runs through `Solver.advance` a frame (1/24 s) at a time, as the
simulate stage does.

The repose angle is measured on the final particles (repose_angle): the pile's top surface
h(r) against the distance r from the axis, one-cell radial bins, a line fitted between 20 % and
80 % of the pile's radius (the apex, where the stream lands, and the foot's thin skirt left
out); the angle is atan of its slope. Beside it, the outer flank's (FOOT: 50-90 % of the
radius), away from the top that the landing stream flattens. Imports numpy, warp and
mpmfx.mpm only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from mpmfx.bench.cases import lattice
from mpmfx.mpm import Particles, Solver, SolverConfig, preset

G = 9.81  # domain/s^2: standard gravity in a 1 m domain
FPS = 24.0
LAYER = 0.25  # the pile's edge: the last radial bin holding a quarter of a one-cell layer
FIT = (0.2, 0.8)  # the fitted part of the flank, fractions of the pile's radius
FOOT = (0.5, 0.9)  # the outer flank alone, away from where the stream lands (reported beside)


@dataclass
class Pile:
    """A pour's result. angle: degrees (NaN if no flank to fit); radius, height: the pile's,
    domain units; x: (n, 3) final positions of the particles in the shot; extra: set-up."""

    grid_n: int
    particles: int
    substeps: int
    wall_s: float
    angle: float
    radius: float
    height: float
    x: np.ndarray
    device: str
    extra: dict


def pile_walls():
    """-x, +x, -y (floor), +y, -z, +z: symmetry planes at the corner, a rough floor."""
    return ("slip", "separate", "sticky", "separate", "slip", "separate")


def hopper(
    dx: float, *, volume: float, pour_time: float, outlet: float, drop: float, ppa: int = 2, seed: int = 0, bc: int = 3
) -> Particles:
    """Every particle a quarter outlet `outlet` wide (domain units, in the corner at x = z = bc
    dx) with its bottom `drop` above the floor emits: `volume` (domain^3) over `pour_time` s,
    ppa^3 particles a cell, births sorted. Their speed is rate / outlet^2, downwards."""
    lo = bc * dx
    sp = dx / ppa
    depth = max(2 * sp, 0.4 * outlet)
    pts = lattice([lo, lo + drop, lo], [lo + outlet, lo + drop + depth, lo + outlet], sp)
    pts = pts[np.lexsort((np.arange(len(pts)), pts[:, 1]))]  # downstream (lowest) first
    rate = volume / pour_time
    vp = sp**3
    n = int(round(volume / vp))
    j = np.arange(n)
    jitter = 0.5 * (np.random.default_rng(seed).random((n, 3)) - 0.5) * sp
    x = pts[j % len(pts)] + jitter
    x[:, [0, 2]] = np.maximum(x[:, [0, 2]], lo + 0.05 * sp)  # inside the symmetry planes
    speed = rate / outlet**2
    return Particles(
        x=x.astype(np.float32),
        v=np.tile(np.float32([0.0, -speed, 0.0]), (n, 1)),
        volume=np.full(n, vp, np.float32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
        birth=((j + 0.5) * vp / rate).astype(np.float32),
    )


def repose_angle(x: np.ndarray, volume: np.ndarray, dx: float, *, origin=(0.0, 0.0, 0.0), sector=1.0, fit=FIT):
    """(angle in degrees, radius, height) of a pile whose axis is the vertical line through
    `origin` (domain units; origin[1] the floor), `sector` of a whole one (0.25: a quarter pile
    in a corner): the top surface h(r), the highest particle in each one-cell radial bin,
    fitted by a line between fit[0] and fit[1] of the radius. The radius is the far edge of
    the last bin whose rest volume covers its annulus LAYER of a cell deep; the height the
    highest particle's. x: (n, 3), volume: (n,) rest volumes. NaN angle when fewer than 3 bins
    fit."""
    r = np.hypot(x[:, 0] - origin[0], x[:, 2] - origin[2])
    y = x[:, 1] - origin[1]
    edges = np.arange(0.0, r.max() + 2 * dx, dx)
    vol, _ = np.histogram(r, bins=edges, weights=volume)
    thick = vol / (sector * np.pi * (edges[1:] ** 2 - edges[:-1] ** 2))
    covered = np.flatnonzero(thick >= LAYER * dx)
    if len(covered) == 0:
        return float("nan"), 0.0, 0.0
    radius = float(edges[covered[-1] + 1])
    idx = np.digitize(r, edges) - 1
    top = np.full(len(edges) - 1, -np.inf)
    np.maximum.at(top, idx, y)
    centre = 0.5 * (edges[1:] + edges[:-1])
    keep = (centre >= fit[0] * radius) & (centre <= fit[1] * radius) & np.isfinite(top)
    height = float(y.max())
    if keep.sum() < 3:
        return float("nan"), radius, height
    slope = np.polyfit(centre[keep], top[keep], 1)[0]
    return float(np.degrees(np.arctan(-slope))), radius, height


def pour(
    *,
    grid_n: int = 32,
    friction_angle: float = 38.0,
    fit: str = "repose",
    radius: float = 0.45,
    pour_time: float = 2.0,
    settle_time: float = 0.5,
    outlet: float = 0.1,
    cfl: float = 0.4,
    device=None,
) -> Pile:
    """Pour a quarter pile of radius ~`radius` (domain units, sized at the friction angle) at
    `grid_n` and measure its repose angle. The outlet's bottom is 0.1 above the pile's top."""
    mat = preset("Granular", friction_angle=friction_angle, friction_fit=fit)
    cfg = SolverConfig(grid_n=grid_n, walls=pile_walls(), cfl=cfl)
    dx = cfg.dx
    lo = cfg.boundary_cells * dx
    height = radius * math.tan(math.radians(friction_angle))
    volume = math.pi * radius**2 * height / 12.0  # a quarter cone
    parts = hopper(dx, volume=volume, pour_time=pour_time, outlet=outlet, drop=height + 0.1, bc=cfg.boundary_cells)
    solver = Solver([mat], cfg, device=device)
    state = solver.init_state(parts)
    frames = int(math.ceil((pour_time + settle_time) * FPS))
    substeps = 0
    t0 = time.perf_counter()
    for f in range(frames):
        substeps += solver.advance(state, f / FPS, (f + 1) / FPS).substeps
    out = solver.state_to_numpy(state)
    wall = time.perf_counter() - t0
    alive = np.asarray(out["alive"]) != 0
    x = np.asarray(out["x"], float)[alive]
    vol = np.asarray(out["volume"], float)[alive]
    angle, r, h = repose_angle(x, vol, dx, origin=(lo, lo, lo), sector=0.25)
    foot = repose_angle(x, vol, dx, origin=(lo, lo, lo), sector=0.25, fit=FOOT)[0]
    return Pile(
        grid_n=grid_n,
        particles=len(parts.x),
        substeps=substeps,
        wall_s=wall,
        angle=angle,
        radius=r,
        height=h,
        x=x,
        device=solver.device.name if solver.device.is_cuda else "cpu",
        extra={
            "friction_angle": friction_angle,
            "fit": fit,
            "cells_across": r / dx,
            "outer_angle": foot,
            "max_speed": float(np.linalg.norm(np.asarray(out["v"], float)[alive], axis=1).max()),
        },
    )
