"""`mpmfx bench oscillation`: how fast the transfers damp a free oscillation (docs/physics.md, "The method").

Two cases, each at three resolutions, each with APIC (flip 0) and the FLIP blends of
`SolverConfig.flip`:

- bar: the Buzzi et al. 2008 elastic bar in free axial vibration (bench.cases.vibrating_bar's
  set-up: a free-free bar, its first mode, rod theory period 10 s), run for three periods;
  observable: the centre-of-mass velocity of its right half.
- slosh: the first standing wave of water in a tank (quasi-2D: a slab 2 cells thick between two
  frictionless plane colliders, frictionless walls), against linear theory
  w^2 = g k tanh(k h), k = pi / L; run for two periods; observable: the horizontal centre of mass.

Each row gives the period error against theory (from the zero crossings) and the decay per
period, 1 - (amplitude one period later / amplitude) from the peaks between the crossings. An
undamped oscillation has decay 0. Prints one table, writes oscillation.csv/json under `out`.
Imports numpy, warp and mpmfx.mpm only.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from mpmfx.bench.cases import _dt, _elastic, _setup, device_name, lattice
from mpmfx.bench.report import print_table, write_rows
from mpmfx.mpm import Collider, ColliderKind, Particles, Solver, SolverConfig, preset

__all__ = ["Sweep", "QUICK", "FULL", "bar", "slosh", "oscillation_metrics", "main"]


@dataclass(frozen=True)
class Sweep:
    """bar / slosh: grid_n of the three resolutions; flips: the FLIP shares compared (0: APIC)."""

    bar: tuple = (20, 40, 80)
    slosh: tuple = (16, 24, 32)
    flips: tuple = (0.0, 0.5, 0.9, 0.95, 0.99)


QUICK = Sweep()
FULL = Sweep(bar=(40, 80, 160), slosh=(32, 64, 128))


def oscillation_metrics(t: np.ndarray, y: np.ndarray, period: float) -> tuple[float, float]:
    """(relative period error, decay per period) of samples y(t) oscillating about 0.

    The period is twice the mean spacing of the zero crossings (linear interpolation); the
    amplitudes are the largest |y| between consecutive crossings, and the decay per period is
    1 - exp(2 b) with b the slope of log(amplitude) per half period (least squares). NaN where
    there are too few crossings (the motion died or never crossed)."""
    s = np.sign(y)
    idx = np.flatnonzero(s[:-1] * s[1:] < 0)
    cross = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])
    if len(cross) < 3:
        return float("nan"), float("nan")
    measured = 2.0 * float(np.mean(np.diff(cross)))
    amps = np.array([np.abs(y[a + 1 : b + 1]).max() for a, b in zip(idx[:-1], idx[1:])])
    if len(amps) < 2 or np.any(amps <= 0):
        return measured / period - 1.0, float("nan")
    slope = np.polyfit(np.arange(len(amps)), np.log(amps), 1)[0]
    return measured / period - 1.0, float(1.0 - math.exp(2.0 * slope))


def _row(case, solver, state, flip, t, y, period, wall, steps, **extra) -> dict:
    err, decay = oscillation_metrics(np.asarray(t), np.asarray(y), period)
    return {
        "case": case,
        "grid_n": solver.config.grid_n,
        "flip": flip,
        "period_error": err,
        "decay_per_period": decay,
        "particles": state.n,
        "substeps": steps,
        "wall_s": wall,
        "device": device_name(solver),
        **extra,
    }


def bar(grid_n: int, flip: float, *, periods: float = 3.0, cfl: float = 0.4, device=None) -> dict:
    """The vibrating bar (bench.cases.vibrating_bar's set-up) for `periods` periods."""
    L, ppa = 0.3, 2
    s = L / 25.0  # Buzzi's bar (E = 100, L = 25, v0 = 0.1) scaled into the domain
    E, v0, T = 100.0 * s**2, 0.1 * s, 10.0
    dx = 1.0 / grid_n
    x = lattice([0.5 - L, 0.5 - dx, 0.5 - dx], [0.5 + L, 0.5 + dx, 0.5 + dx], dx / ppa)
    v = np.zeros_like(x)
    v[:, 0] = v0 * np.sin(math.pi / (2 * L) * (x[:, 0] - 0.5))
    solver, state = _setup(_elastic(E, 0.0), x, v, dx / ppa, grid_n=grid_n, device=device, flip=flip)
    per = math.ceil(T / _dt(solver, state, cfl, v0))
    dt = T / per
    right = x[:, 0] > 0.5
    ys = [float(v[right, 0].mean())]
    t0 = time.perf_counter()
    for _ in range(round(per * periods)):
        solver.step(state, dt)
        ys.append(float(state.cur.v.numpy()[right, 0].mean()))  # (step's reference P2G keeps the order)
    wall = time.perf_counter() - t0
    t = np.arange(len(ys)) * dt
    return _row("bar", solver, state, flip, t, ys, T, wall, len(ys) - 1, cells_across=2)


def _slab_colliders(z0: float, z1: float, dx: float) -> tuple:
    """Two frictionless planes holding the material in z0 <= z <= z1 (quasi-2D), z0 and z1 on
    nodes. A collider holds the nodes strictly inside it, so each plane sits half a cell inside
    the slab: the nodes at z0 and z1 are held, and the material stops there, as it does at the
    walls' inner band node (a plane on the node would let it spread a cell into each side)."""
    return (
        Collider(ColliderKind.PLANE, normal=(0.0, 0.0, 1.0), point=(0.0, 0.0, z0 + 0.5 * dx)),
        Collider(ColliderKind.PLANE, normal=(0.0, 0.0, -1.0), point=(0.0, 0.0, z1 - 0.5 * dx)),
    )


def slosh(
    grid_n: int, flip: float, *, depth: float = 0.25, periods: float = 2.0, cfl: float = 0.4, device=None
) -> dict:
    """First sloshing mode of a water tank, surface eta = a cos(k x), a = depth / 10, from rest,
    hydrostatic J. The tank spans the walls: material from (boundary_cells - 1) dx, the band's
    inner node, where the walls stop it."""
    ppa, g = 2, 9.81
    dx = 1.0 / grid_n
    lo = 2 * dx  # (boundary_cells - 1) dx with the default 3-cell band
    L = 1.0 - 2 * lo
    k = math.pi / L
    a = depth / 10.0
    omega = math.sqrt(g * k * math.tanh(k * depth))
    z0, z1 = 0.5 - dx, 0.5 + dx
    x = lattice([lo, lo, z0], [1.0 - lo, lo + depth + a, z1], dx / ppa)
    x = x[x[:, 1] <= lo + depth + a * np.cos(k * (x[:, 0] - lo))]
    water = preset("Water")
    cfg = SolverConfig(grid_n=grid_n, gravity=(0.0, -g, 0.0), wall_friction=0.0, flip=flip)
    solver = Solver([water], cfg, colliders=_slab_colliders(z0, z1, dx), device=device)
    n = len(x)
    parts = Particles(
        x=x,
        v=np.zeros_like(x),
        volume=np.full(n, (dx / ppa) ** 3, np.float32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
    )
    state = solver.init_state(parts)
    # hydrostatic start (Tait: p = K (J^-gamma - 1)), so no pressure wave rings over the slosh
    head = lo + depth + a * np.cos(k * (x[:, 0] - lo)) - x[:, 1]
    p = water.density * g * np.maximum(head, 0.0)
    state.cur.J.assign((1.0 + p / water.bulk_modulus) ** (-1.0 / water.eos_gamma))
    T = 2 * math.pi / omega
    dt = min(T / 200, _dt(solver, state, cfl, a * omega))
    per = math.ceil(T / dt)
    dt = T / per
    solver.step(state, 1e-9)  # compile now (a substep of no consequence)
    xc, every = 0.5, max(1, per // 200)  # ~200 samples a period
    ys = [float(x[:, 0].mean()) - xc]
    steps = round(per * periods)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        solver.step(state, dt)
        if k % every == 0:
            ys.append(float(state.cur.x.numpy()[:, 0].mean()) - xc)
    wall = time.perf_counter() - t0
    t = np.arange(len(ys)) * dt * every
    return _row("slosh", solver, state, flip, t, ys, T, wall, steps, cells_deep=round(depth * grid_n))


def run(sweep: Sweep, device=None) -> list[dict]:
    rows = []
    for case, grids in (("bar", sweep.bar), ("slosh", sweep.slosh)):
        fn = bar if case == "bar" else slosh
        for n in grids:
            for f in sweep.flips:
                rows.append(fn(n, f, device=device))
                r = rows[-1]
                print(
                    f"  {case} grid {n} flip {f}: period {r['period_error']:+.4f}, decay {r['decay_per_period']:.4f}",
                    flush=True,
                )
    return rows


COLS = ["case", "grid_n", "flip", "period_error", "decay_per_period", "particles", "substeps", "wall_s", "device"]


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    rows = run(QUICK if quick else FULL, device=device)
    print_table(rows, COLS)
    write_rows(rows, out, "oscillation")
    return 0
