"""Laboratory set-ups for `mpmfx bench accuracy`: dam break and granular column collapse.

Each set-up is scaled into the domain [0, 1]^3 with gravity g = 9.81 domain/s^2 (a 1 m
domain), is quasi-2D where the experiment is (a channel that fills the domain depth, side
walls `separate` and frictionless) and runs at a fixed dt on either the production solver
(`engine="warp"`) or the numpy reference step (`engine="reference"`,
`mpmfx.bench.reference_step`) with identical particles, grid, walls and dt, so the two can
be compared directly. The walls are planes `boundary_cells` cells inside the domain's faces
(`SolverConfig.wall_planes`): the material starts at x = y = 3 dx, on the channel's back wall
and floor.

Observables (rest volume of the particles binned in one-cell columns, so a few splashed
particles do not count):
- front / tip: far edge of the last one-cell column that holds at least `LAYER` of a
  one-cell-thick layer, measured from the back wall (x = 3 dx), domain units.
- height: thickest column of the deposit, domain units.
Imports numpy, warp and mpmfx.mpm only (the GPU machine has nothing else).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from mpmfx.bench.cases import lattice
from mpmfx.bench.reference_step import ReferenceSolver
from mpmfx.mpm import Particles, Solver, SolverConfig, preset

G = 9.81  # domain/s^2: standard gravity in a 1 m domain
LAYER = 0.25  # a column counts as covered from a quarter of a one-cell layer


@dataclass
class Run:
    """What one experiment run returns. times: s; fronts: domain units at those times;
    final: (n, 3) positions at the end; extra: set-up numbers (L0, H0, dt, ...)."""

    engine: str
    grid_n: int
    particles: int
    steps: int
    wall_s: float
    times: list = field(default_factory=list)
    fronts: list = field(default_factory=list)
    final: np.ndarray | None = None
    volume: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    device: str = "cpu"


def channel_walls(floor: str = "sticky"):
    """-x, +x, -y (floor), +y, -z, +z: a channel whose floor is `floor`."""
    return ("separate", "separate", floor, "separate", "separate", "separate")


def _engine(engine, materials, config, device):
    if engine == "reference":
        return ReferenceSolver(materials, config), "cpu (numpy reference)"
    solver = Solver(materials, config, device=device)
    return solver, (solver.device.name if solver.device.is_cuda else "cpu")


def simulate(engine, materials, config, x, spacing, *, dt, t_end, observe_times=(), observe=None, device=None) -> Run:
    """Run `x` (n, 3) at rest, one material (index 0), fixed dt until t_end (s).
    observe(positions) is called at each of observe_times (s, rounded to whole steps)."""
    n = len(x)
    parts = Particles(
        x=np.asarray(x, np.float32),
        v=np.zeros((n, 3), np.float32),
        volume=np.full(n, spacing**3, np.float32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
    )
    solver, dev = _engine(engine, materials, config, device)
    state = solver.init_state(parts)
    steps = int(math.ceil(t_end / dt))
    marks = {max(1, int(round(t / dt))): t for t in observe_times}
    run = Run(engine=engine, grid_n=config.grid_n, particles=n, steps=steps, wall_s=0.0, device=dev)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        solver.step(state, dt)
        if k in marks:
            run.times.append(k * dt)
            run.fronts.append(observe(np.asarray(solver.state_to_numpy(state)["x"], float)))
    out = solver.state_to_numpy(state)
    run.wall_s = time.perf_counter() - t0
    run.final = np.asarray(out["x"], float)
    run.volume = np.asarray(out["volume"], float)
    run.extra["max_speed"] = float(np.linalg.norm(np.asarray(out["v"], float), axis=1).max())
    return run


def column_profile(x, volume, dx, depth, *, axis=0, radial=False, origin=(0.0, 0.0)):
    """Deposit thickness per one-cell column, domain units: (edges (k+1,), thickness (k,)).
    Quasi-2D: rest volume per x-bin / (dx * depth). radial=True (axisymmetric, quarter
    column about `origin` in the x-z plane): per radial bin / its quarter-annulus area."""
    if radial:
        r = np.hypot(x[:, 0] - origin[0], x[:, 2] - origin[1])
    else:
        r = x[:, axis] - origin[0]
    edges = np.arange(0.0, r.max() + 2 * dx, dx)
    vol, _ = np.histogram(r, bins=edges, weights=volume)
    area = (0.25 * math.pi * (edges[1:] ** 2 - edges[:-1] ** 2)) if radial else dx * depth
    return edges, vol / area


def front_quantile(x, *, origin=0.0, q=0.998) -> float:
    """Continuous front for comparing two runs: the x (from `origin`) beyond which a
    fraction 1 - q of the particles lie. Not quantised to cells like the tip."""
    return float(np.quantile(x[:, 0], q) - origin)


def flank_angle(x, volume, dx, depth, **kw) -> float:
    """Slope of the deposit's flank, degrees: a line fitted to the thickness profile where it
    is between 20 % and 80 % of its maximum, beyond the thickest column (what a protractor
    laid on the pile's side reads)."""
    edges, h = column_profile(x, volume, dx, depth, **kw)
    centre = 0.5 * (edges[1:] + edges[:-1])
    top = int(np.argmax(h))
    keep = np.zeros(len(h), bool)
    keep[top:] = (h[top:] >= 0.2 * h[top]) & (h[top:] <= 0.8 * h[top])
    if keep.sum() < 2:
        return float("nan")
    slope = np.polyfit(centre[keep], h[keep], 1)[0]
    return float(np.degrees(np.arctan(abs(slope))))


def tip_and_height(x, volume, dx, depth, **kw):
    """(far edge of the last column holding >= LAYER cell of material, thickest column)."""
    edges, h = column_profile(x, volume, dx, depth, **kw)
    covered = np.flatnonzero(h >= LAYER * dx)
    tip = float(edges[covered[-1] + 1]) if len(covered) else 0.0
    return tip, float(h.max())


# ---------------------------------------------------------------------------- water
def dam_break(
    *,
    grid_n=32,
    width=0.2,
    t_star=(1.0, 1.5, 2.0, 2.5, 3.0),
    engine="warp",
    ppa=2,
    ppz=None,
    wall_friction=0.0,
    wall_layer=SolverConfig.wall_layer,
    floor="separate",
    cfl=0.4,
    device=None,
) -> Run:
    """Water column `width` wide and 2 width tall against the back wall of a channel filling
    the domain depth (Martin & Moyce 1952 n^2 = 2; Koshizuka & Oka 1996). Fronts (surge tip
    from the back wall) at T = t sqrt(2 g / width) = each of t_star. floor/wall_friction:
    the frictionless case is all walls `separate` with mu = 0; the rough case gives the
    walls Coulomb friction (or a sticky floor), acting over `wall_layer` (domain units)."""
    mat = preset("Water")
    cfg = SolverConfig(
        grid_n=grid_n,
        gravity=(0.0, -G, 0.0),
        walls=channel_walls(floor),
        wall_friction=wall_friction,
        wall_layer=wall_layer,
        cfl=cfl,
    )
    dx = cfg.dx
    x, spacing, depth = _quasi2d_block(dx, width, 2 * width, ppa, ppz)
    vmax = math.sqrt(2 * G * 2 * width)  # free fall from the top
    dt = cfg.cfl * dx / (mat.wave_speed() + vmax)
    scale = math.sqrt(2 * G / width)
    times = [T / scale for T in t_star]
    x0 = cfg.boundary_cells * dx
    run = simulate(
        engine,
        [mat],
        cfg,
        x,
        spacing,
        dt=dt,
        t_end=max(times),
        observe_times=times,
        observe=lambda p: (
            tip_and_height(p, np.full(len(p), spacing**3), dx, depth, origin=(x0,))[0],
            front_quantile(p, origin=x0),
        ),
        device=device,
    )
    run.extra = {
        "width": width,
        "dt": dt,
        "T": [t * scale for t in run.times],
        "Z": [f[0] / width for f in run.fronts],
        "Zq": [f[1] / width for f in run.fronts],
        "cells_across": width / dx,
    }
    return run


def _quasi2d_block(dx, length, height, ppa, ppz=None, bc=3):
    """Particles filling [b, b+length] x [b, b+height] x (the channel depth between the z
    walls), b = bc dx the walls' planes, ppa per cell in x, y and ppz (default ppa)
    in z. Returns (x, spacing, depth); volume per particle = spacing^3 with the z spacing
    folded into the depth."""
    lo = bc * dx
    n = int(round(1.0 / dx))
    depth = (n - 2 * bc) * dx
    ppz = ppz or ppa
    sp = dx / ppa
    xy = lattice([lo, lo, 0.5], [lo + length, lo + height, 0.5 + sp], sp)[:, :2]
    zs = lo + (np.arange((n - 2 * bc) * ppz) + 0.5) * dx / ppz
    x = np.concatenate([np.column_stack([xy, np.full(len(xy), z)]) for z in zs]).astype(np.float32)
    # rest volume per particle: (dx/ppa)^2 (dx/ppz); encode as spacing^3 with the same total
    spacing = (sp * sp * dx / ppz) ** (1.0 / 3.0)
    return x, spacing, depth


# ---------------------------------------------------------------------------- sand
def runout_law(a: float, source: str = "lube2005") -> tuple[float, float]:
    """Published normalised runout (L_inf - L0) / L0 and final height H_inf / L0 at aspect
    ratio a (see data/granular_collapse_laws.csv for the sources and coefficients)."""
    law = GRANULAR_LAWS[source]
    run = law["l1"] * a if a < law["a0"] else law["l2"] * a ** law["alpha"]
    height = a if a < law["h_a0"] else law["h2"] * a ** law["h_alpha"]
    return run, height


# coefficients of data/granular_collapse_laws.csv (kept here too: the GPU machine reads
# the package without its data files; tests check the two agree)
GRANULAR_LAWS = {
    "lube2005": {
        "geometry": "quasi2d",
        "l1": 1.2,
        "l2": 1.9,
        "alpha": 2 / 3,
        "a0": 2.8,
        "h_a0": 1.15,
        "h2": 1.0,
        "h_alpha": 0.4,
    },
    "lajeunesse2005": {
        "geometry": "quasi2d",
        "l1": 1.8,
        "l2": 2.3,
        "alpha": 2 / 3,
        "a0": 3.0,
        "h_a0": 1.15,
        "h2": 1.0,
        "h_alpha": 0.4,
    },
    "lube2004": {
        "geometry": "axisymmetric",
        "l1": 1.24,
        "l2": 1.6,
        "alpha": 0.5,
        "a0": 1.7,
        "h_a0": 0.74,
        "h2": 0.88,
        "h_alpha": 1 / 6,
    },
}


def column_collapse(
    *,
    a=1.0,
    grid_n=32,
    engine="warp",
    friction_angle=38.0,
    fit=None,
    ppa=2,
    ppz=None,
    floor="sticky",
    wall_friction=0.0,
    t_scale=5.0,
    cfl=0.4,
    axisymmetric=False,
    length=None,
    device=None,
    material=None,
    config=None,
) -> Run:
    """Granular column of aspect ratio a = H0 / L0 released against the back wall (quasi-2D,
    Lube et al. 2005) or a quarter cylinder in the corner (axisymmetric, Lube et al. 2004;
    the x and z walls are frictionless symmetry planes). Runs t_scale * sqrt(H0 / g) after
    release. L0 is chosen so the published runout fits the domain with margin. config: extra
    SolverConfig fields (e.g. boundary_cells) for diagnostics.
    extra: L0, H0, runout (L_inf - L0) / L0, height H_inf / L0, and the law's values."""
    over = {"friction_angle": friction_angle}
    if fit is not None:
        over["friction_fit"] = fit
    mat = material or preset("Granular", **over)
    cfg = SolverConfig(
        grid_n=grid_n,
        gravity=(0.0, -G, 0.0),
        walls=channel_walls(floor),
        wall_friction=wall_friction,
        cfl=cfl,
        **(config or {}),
    )
    dx = cfg.dx
    source = "lube2004" if axisymmetric else "lube2005"
    law_run, law_h = runout_law(a, source)
    usable = 1.0 - (2 * cfg.boundary_cells + 1) * dx
    L0 = length or min(usable / (1.6 * (1.0 + law_run)), 0.9 * usable / a)
    H0 = a * L0
    x0 = cfg.boundary_cells * dx  # the channel's back wall and floor
    if axisymmetric:
        sp = dx / ppa
        x = lattice(
            [x0, x0, x0], [x0 + L0, x0 + H0, x0 + L0], sp, inside=lambda p: np.hypot(p[:, 0] - x0, p[:, 2] - x0) <= L0
        )
        spacing, depth = sp, None
    else:
        x, spacing, depth = _quasi2d_block(dx, L0, H0, ppa, ppz, cfg.boundary_cells)
    vmax = math.sqrt(2 * G * H0)
    dt = cfg.cfl * dx / (mat.wave_speed() + vmax)
    run = simulate(engine, [mat], cfg, x, spacing, dt=dt, t_end=t_scale * math.sqrt(H0 / G), device=device)
    kw = {"radial": True, "origin": (x0, x0)} if axisymmetric else {"origin": (x0,)}
    tip, height = tip_and_height(run.final, run.volume, dx, depth, **kw)
    if axisymmetric:  # the annuli near the axis hold too few particles to give a thickness
        height = float(np.quantile(run.final[:, 1] - x0, 0.999)) + 0.5 * spacing
    run.extra = {
        **run.extra,
        "a": a,
        "L0": L0,
        "H0": H0,
        "dt": dt,
        "cells_across": L0 / dx,
        "flank_angle": flank_angle(run.final, run.volume, dx, depth, **kw),
        "runout": (tip - L0) / L0,
        "runout_q": (front_quantile(run.final, origin=x0) - L0) / L0,
        "height": height / L0,
        "law_runout": law_run,
        "law_height": law_h,
        "source": source,
        "friction_angle": mat.friction_angle,
        "fit": getattr(mat, "friction_fit", "compression"),
    }
    return run
