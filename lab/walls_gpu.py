"""The walls on their planes, measured (GPU; about 3 minutes on one H200): material placed on the
declared floor and walls (`SolverConfig.wall_planes`) at rest, a sloshing pool's period against
linear theory, and the dam-break front against Martin & Moyce 1952 with and without wall
friction. Prints one table.

    python lab/walls_gpu.py                  # the full set, device cuda
    python lab/walls_gpu.py --dams           # the dam-break rows only
    python lab/walls_gpu.py --quick --device cpu   # small grids, a check that it runs

Rows:
- sand column: a Granular block 0.3 x 0.25 x 0.3 placed on the floor (it slumps); how far the
  median of its bottom particle layer (a quarter cell above the floor) moves in 0.5 s, and the
  lowest particle's height above the floor's plane, in cells (< 0: into the floor).
- water at rest: water filling the tank wall to wall, 12 cells deep; the highest rise of the
  particles next to the side walls in 0.3 s (cells) and the lowest volume ratio J.
- pool period: the first sloshing mode of a quasi-2D tank (slip walls) h = 8 and 16 cells
  deep, amplitude 0.1 h; the period from the surface at the side wall's zero crossings, against
  linear theory w^2 = g k tanh(k h), k = pi / (wall-to-wall width), and the fraction of the
  mode's amplitude lost from the first period to the second.
- dam break: mean relative front error against Martin & Moyce 1952 (a = 2.25 in) at grid
  64 / 128 / 256, all walls separate, wall_friction 0, then 0.3 at the walls' nodes only
  (wall_layer 0) and 0.3 over the layer (`--layer`, default SolverConfig's 0.02: 2 cm in the
  1 m domain); and each friction's effect, the points it takes off the frictionless error
  (`mpmfx.bench.experiments.dam_break`).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from mpmfx.bench import experiments as ex
from mpmfx.bench.cases import lattice
from mpmfx.bench.lab import front_error, water_references
from mpmfx.mpm import Particles, Solver, SolverConfig, preset

G = 9.81  # domain/s^2: a 1 m domain


def _particles(x: np.ndarray, spacing: float) -> Particles:
    n = len(x)
    return Particles(
        x=x.astype(np.float32),
        v=np.zeros((n, 3), np.float32),
        volume=np.full(n, spacing**3, np.float32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
    )


def sand_sink(n: int, device: str) -> tuple[float, float]:
    """(median move of the bottom particle layer, lowest particle's height above the floor
    plane), cells, of a sand block placed on the floor after 0.5 s (< 0: down)."""
    dx = 1 / n
    lo, _ = SolverConfig(grid_n=n).wall_planes
    x = lattice([0.35, lo, 0.35], [0.65, lo + 0.25, 0.65], dx / 2)
    solver = Solver([preset("Granular")], SolverConfig(grid_n=n), device=device)
    state = solver.init_state(_particles(x, dx / 2))
    solver.advance(state, 0.0, 0.5)
    y = solver.state_to_numpy(state)["x"][:, 1]
    bottom = x[:, 1] < lo + dx / 2
    return float(np.median(y[bottom] - x[bottom, 1]) / dx), float((y.min() - lo) / dx)


def water_at_rest(n: int, device: str) -> tuple[float, float]:
    """(highest rise next to a side wall in 0.3 s, cells; lowest J) of water filling the tank."""
    dx = 1 / n
    lo, hi = SolverConfig(grid_n=n).wall_planes
    x = lattice([lo, lo, lo], [hi, lo + 12 * dx, hi], dx / 2)
    solver = Solver([preset("Water")], SolverConfig(grid_n=n), device=device)
    state = solver.init_state(_particles(x, dx / 2))
    side = lambda p: (p[:, 0] < lo + dx) | (p[:, 0] > hi - dx)  # noqa: E731
    top, climb, j_min = x[side(x), 1].max(), 0.0, 1.0
    for f in range(12):
        solver.advance(state, f * 0.025, (f + 1) * 0.025)
        out = solver.state_to_numpy(state)
        climb = max(climb, float(out["x"][side(out["x"]), 1].max() - top))
        j_min = min(j_min, float(out["J"].min()))
    return climb / dx, j_min


def pool_period(n: int, depth_cells: int, device: str, periods: float = 2.3) -> tuple[float, float, float]:
    """(simulated period, linear-theory period at the depth the particles fill, fraction of the
    fundamental's amplitude lost from the first period to the second) of the first sloshing mode
    in a quasi-2D tank (it fills the domain depth between the slip walls, 1 particle per cell in
    z)."""
    dx = 1 / n
    lo, hi = SolverConfig(grid_n=n).wall_planes
    L, h = hi - lo, depth_cells * dx
    k = math.pi / L
    amp = 0.1 * h
    sp = dx / 2
    xy = lattice([lo, lo, 0.5], [hi, lo + h + amp, 0.5 + sp], sp)[:, :2]
    xy = xy[xy[:, 1] < lo + h + amp * np.cos(k * (xy[:, 0] - lo))]
    zs = lo + (np.arange(round((hi - lo) / dx)) + 0.5) * dx
    x = np.concatenate([np.column_stack([xy, np.full(len(xy), z)]) for z in zs])
    cfg = SolverConfig(grid_n=n, walls=("slip",) * 6, wall_friction=0.0)
    solver = Solver([preset("Water")], cfg, device=device)
    state = solver.init_state(_particles(x, (sp * sp * dx) ** (1 / 3)))
    h = len(x) * sp * sp * dx / (L * len(zs) * dx)  # the mean depth the particles' volume fills
    w = math.sqrt(G * k * math.tanh(k * h))
    T_lin = 2 * math.pi / w
    frame = T_lin / 40
    ts, eta = [], []
    for f in range(int(periods * 40) + 1):
        if f:
            solver.advance(state, (f - 1) * frame, f * frame)
        p = solver.state_to_numpy(state)["x"]
        near = p[:, 0] < lo + dx
        ts.append(f * frame)
        eta.append(float(np.percentile(p[near, 1], 99)) - (lo + h))
    t, e = np.array(ts), np.array(eta)
    e = e - np.polyval(np.polyfit(t, e, 1), t)  # about the level, which may settle a little
    up = np.flatnonzero((e[:-1] > 0) & (e[1:] <= 0))  # downward zero crossings, one a period
    cross = t[up] + (t[up + 1] - t[up]) * e[up] / (e[up] - e[up + 1])
    T = float(np.mean(np.diff(cross))) if len(cross) > 1 else float("nan")
    # the fundamental's amplitude over the first and the second period (a Fourier coefficient at
    # the measured period: the higher modes a finite amplitude excites average out)
    amps = []
    for j in range(2):
        win = (t >= j * T) & (t < (j + 1) * T) if np.isfinite(T) else np.zeros(len(t), bool)
        if win.sum() > 8:
            ew = e[win] - np.polyval(np.polyfit(t[win], e[win], 1), t[win])  # a drift would read as amplitude
            amps.append(abs(np.mean(ew * np.exp(-2j * math.pi * t[win] / T))) * 2)
    decay = 1 - amps[1] / amps[0] if len(amps) == 2 and amps[0] > 0 else float("nan")
    return T, T_lin, decay


def dam_front(n: int, mu: float, layer: float, device: str) -> float:
    run = ex.dam_break(
        grid_n=n,
        width=0.2,
        t_star=(1.0, 1.5, 2.0, 2.5, 3.0),
        ppz=1,
        wall_friction=mu,
        wall_layer=layer,
        device=device,
    )
    return front_error(run.extra["T"], run.extra["Z"], water_references()["martin_moyce_1952_a2.25in"])


def rest_rows(rest_n: int, pool_n: int, device: str) -> list[tuple[str, str, str]]:
    """The rows of material at rest on the walls and the pool's period."""
    rows = []
    sink, lowest = sand_sink(rest_n, device)
    rows.append(("sand: bottom layer moves / lowest particle", f"grid {rest_n}", f"{sink:+.3f} / {lowest:+.3f} cells"))
    climb, j = water_at_rest(rest_n, device)
    rows.append(("water at rest: climb at the walls / min J", f"grid {rest_n}", f"{climb:.3f} cells / {j:.3f}"))
    for depth in (8, 16):
        T, T_lin, decay = pool_period(pool_n, depth, device)
        rows.append(
            (
                f"pool period, {depth} cells deep",
                f"grid {pool_n}",
                f"{T:.4f} s vs {T_lin:.4f} s ({T / T_lin - 1:+.2%}); amplitude lost a period {decay:.1%}",
            )
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--quick", action="store_true", help="small grids: a check that the script runs")
    ap.add_argument("--dams", action="store_true", help="the dam-break rows only")
    ap.add_argument("--layer", type=float, default=SolverConfig.wall_layer, help="wall_layer, domain units (1 m)")
    a = ap.parse_args()
    rest_n, pool_n, dams = (24, 32, (16, 24, 32)) if a.quick else (64, 64, (64, 128, 256))
    rows = []
    t0 = time.perf_counter()
    if not a.dams:
        rows += rest_rows(rest_n, pool_n, a.device)
    for n in dams:  # each row said as it lands: a run cut short keeps what it measured
        free = dam_front(n, 0.0, a.layer, a.device)
        nodes, layer = dam_front(n, 0.3, 0.0, a.device), dam_front(n, 0.3, a.layer, a.device)
        rows.append(
            (
                f"dam front vs M&M: mu 0 / 0.3 nodes / 0.3 layer {a.layer:g}",
                f"grid {n}",
                f"{free:+.1%} / {nodes:+.1%} / {layer:+.1%}; effect {(free - nodes) * 100:.1f} / "
                f"{(free - layer) * 100:.1f} points",
            )
        )
        print(*rows[-1], f"({time.perf_counter() - t0:.0f} s)", flush=True)
    print(f"\n{'case':<52} {'grid':<9} result   (device {a.device}, {time.perf_counter() - t0:.0f} s)")
    for case, grid, result in rows:
        print(f"{case:<52} {grid:<9} {result}")


if __name__ == "__main__":
    main()
