"""`mpmfx bench accuracy`: speed against error on the validation cases (docs/physics.md, "Validation").

Sweeps grid_n and CFL per case (mpmfx.bench.cases), prints one table (error, wall time,
particle-substeps/s, device), the observed convergence orders in space (halve dx at fixed CFL
and particles per cell, error against the exact solution) and in time (halve dt at fixed grid,
error against the smallest-CFL run: self-convergence, since the spatial error does not vanish
with dt), and writes accuracy.csv/json, orders.csv/json and accuracy.png (speed against error,
log-log) under `out`. Then the experiments section (mpmfx.bench.lab): dam break and granular
column collapse against published laboratory data, and a poured pile's repose angle against
the friction angle (mpmfx.bench.pile), at three resolutions, with their error trend,
experiments.csv/json, experiments_trend.csv and experiments_{water,sand}.png. Needs numpy +
warp + mpmfx.mpm only; the PNG needs pyvista and is skipped with a message without it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpmfx.bench import cases, lab
from mpmfx.bench.plot import speed_error_plot
from mpmfx.bench.report import print_table, write_rows
from mpmfx.bench.snow_table import snow_compression


@dataclass(frozen=True)
class Sweep:
    """Which settings to run. grids: grid_n per case; cfls: CFL values of the time sweep."""

    free_fall: tuple = (16, 32)
    rotation: tuple = (16,)
    revolutions: float = 1.0
    bar: tuple = (20, 40)
    wave: tuple = (16, 32, 64)
    wave_cfls: tuple = (0.4, 0.2, 0.1)
    wave_cfl_grid: int = 16
    wave_cfl_ref: float = 0.0125
    hydrostatic: tuple = (16, 32)
    disks: tuple = (24, 32)


QUICK = Sweep()
FULL = Sweep(
    free_fall=(32, 64, 128),
    rotation=(32, 64),
    revolutions=10.0,
    bar=(40, 80, 160),
    wave=(16, 32, 64, 128, 256),
    wave_cfls=(0.8, 0.4, 0.2, 0.1, 0.05),
    wave_cfl_grid=64,
    wave_cfl_ref=0.00625,
    hydrostatic=(32, 64, 128),
    disks=(32, 64, 128),
)


def observed_order(h: list[float], err: list[float]) -> list[float]:
    """Orders log(e_i / e_{i+1}) / log(h_i / h_{i+1}) between successive settings."""
    return [
        math.log(err[i] / err[i + 1]) / math.log(h[i] / h[i + 1]) if err[i] > 0 and err[i + 1] > 0 else float("nan")
        for i in range(len(err) - 1)
    ]


def time_sweep(sweep: Sweep, device) -> tuple[list[cases.CaseResult], list[float]]:
    """Standing wave at one grid, CFL halved each run; errors are RMS |x - x_ref| / A against
    the run at sweep.wave_cfl_ref (same particles, same end time)."""
    ref = cases.standing_wave(grid_n=sweep.wave_cfl_grid, cfl=sweep.wave_cfl_ref, device=device)
    runs = [cases.standing_wave(grid_n=sweep.wave_cfl_grid, cfl=c, device=device) for c in sweep.wave_cfls]
    amp = 0.2 / (math.pi / 0.5)  # A = strain / k of cases.standing_wave
    errs = [float(np.sqrt(np.mean((r.x_final - ref.x_final) ** 2)) / amp) for r in runs]
    return runs, errs


def run_sweep(sweep: Sweep, device=None) -> tuple[list[dict], list[dict]]:
    """All cases of `sweep`; returns (rows, order rows)."""
    results: list[cases.CaseResult] = []
    results += [cases.free_fall(grid_n=n, device=device) for n in sweep.free_fall]
    for n in sweep.rotation:
        for pic in (False, True):
            results.append(cases.rigid_rotation(grid_n=n, revolutions=sweep.revolutions, pic=pic, device=device))
    results += [cases.vibrating_bar(grid_n=n, device=device) for n in sweep.bar]
    wave = [cases.standing_wave(grid_n=n, device=device) for n in sweep.wave]
    results += wave
    results += [cases.hydrostatic_column(grid_n=n, device=device) for n in sweep.hydrostatic]
    results += [cases.colliding_disks(grid_n=n, device=device) for n in sweep.disks]
    t_runs, t_errs = time_sweep(sweep, device)
    rows = [r.row() for r in results]
    for r, e in zip(t_runs, t_errs):
        row = r.row()
        row.update(case="standing_wave_dt", error=e, metric=f"rms|x-x(cfl={sweep.wave_cfl_ref})|/A")
        rows.append(row)
    snow = snow_compression(device=device)
    rows.append({k: v for k, v in snow.items() if k != "table"})
    orders = _order_rows(results, t_runs, t_errs)
    return rows, orders


# Why an observed order is far from the scheme's 2 in space (or says nothing in time): printed
# beside the order, so a low number is read as what it measures, not as a broken solver.
WHY = {
    ("hydrostatic", "space"): "stress error is the particle quadrature's (cell-crossing noise and the "
    "-2.6..-2.9 % bias CB-Geo also reports), which refining dx at fixed particles "
    "per cell does not reduce: order ~0 is expected",
    ("colliding_disks", "space"): "energy lost at single-field contact shrinks with dx at first order at best",
    ("standing_wave", "time"): "the error is spatial: at grid 64 the time-step error is below it for every "
    "CFL tried, so halving dt changes nothing (order ~0); spend on grid_n",
}
LOW_ORDER = 1.5  # below this a space order gets its WHY note


def _order_rows(results, t_runs, t_errs) -> list[dict]:
    out = []
    by_case: dict[str, list] = {}
    for r in results:
        by_case.setdefault(r.case, []).append(r)
    for case in ("standing_wave", "vibrating_bar", "hydrostatic", "colliding_disks"):
        rs = sorted(by_case.get(case, []), key=lambda r: r.grid_n)
        orders = observed_order([1 / r.grid_n for r in rs], [r.error for r in rs])
        out += [
            {
                "case": case,
                "in": "space",
                "from": f"grid_n={a.grid_n}",
                "to": f"grid_n={b.grid_n}",
                "error_from": a.error,
                "error_to": b.error,
                "order": o,
            }
            for a, b, o in zip(rs, rs[1:], orders)
        ]
    orders = observed_order([r.extra["dt"] for r in t_runs], t_errs)
    out += [
        {
            "case": "standing_wave",
            "in": "time",
            "from": f"cfl={a.cfl}",
            "to": f"cfl={b.cfl}",
            "error_from": ea,
            "error_to": eb,
            "order": o,
        }
        for a, b, ea, eb, o in zip(t_runs, t_runs[1:], t_errs, t_errs[1:], orders)
    ]
    for row in out:
        low = row["in"] == "time" or not (row["order"] >= LOW_ORDER)  # NaN counts as low
        row["why"] = WHY.get((row["case"], row["in"]), "") if low else ""
    return out


COLUMNS = [
    "case",
    "grid_n",
    "cfl",
    "ppc",
    "particles",
    "substeps",
    "error",
    "metric",
    "wall_s",
    "Mparticle_substeps_per_s",
    "device",
]


LAB_COLUMNS = [
    "case",
    "reference",
    "a",
    "grid_n",
    "cells_across",
    "value",
    "law",
    "error",
    "metric",
    "particles",
    "wall_s",
    "device",
]


def experiments(*, quick: bool, device, out) -> list[dict]:
    """The experiments section: prints its table, trend and summary; writes its files."""
    rows, series = lab.run_lab(lab.QUICK if quick else lab.FULL, device)
    print("\nexperiments (laboratory data; error = simulation / experiment - 1)")
    print_table(rows, LAB_COLUMNS)
    trend = lab.trend(rows)
    print()
    print_table(trend)
    print()
    for line in lab.summary(rows):
        print(line)
    write_rows(rows, out, "experiments")
    write_rows(trend, out, "experiments_trend")
    (Path(out) / "experiments_series.json").write_text(json.dumps(series))
    try:
        for path in lab.lab_plot(series, out):
            print(f"plot: {path}")
    except ImportError as err:
        print(f"plot skipped: {err}")
    return rows


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    sweep = QUICK if quick else FULL
    rows, orders = run_sweep(sweep, device)
    print_table(rows, COLUMNS)
    print()
    print_table(orders)
    write_rows(rows, out, "accuracy")
    write_rows(orders, out, "accuracy_orders")
    try:
        path = speed_error_plot(rows, out)
        print(f"plot: {path}")
    except ImportError as err:
        print(f"plot skipped: {err} (pip install pyvista to draw accuracy.png; the CSV/JSON are written)")
    lab_rows = experiments(quick=quick, device=device, out=out)
    ok = all(np.isfinite(r["error"]) for r in rows + lab_rows)
    return 0 if ok else 1
