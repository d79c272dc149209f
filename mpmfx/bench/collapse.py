"""`mpmfx bench collapse`: granular column collapse against the published scaling laws.

A column of aspect ratio a = H0 / L0 is released in a channel (quasi-2D, against Lube et al.
2005, "Collapses of two-dimensional granular columns") and as a quarter cylinder in a corner
(axisymmetric, against Lube et al. 2004, "Axisymmetric collapses of granular columns"), at
several grid resolutions (mpmfx.bench.experiments.column_collapse). Two sands:

- "Granular": the preset as shipped (friction_angle 38, the `repose` fit);
- "fit 30": the same preset at friction_angle 30, the angle that puts the quasi-2D runout
  on Lube et al. 2005's law.

Each row: runout (L_inf - L0) / L0 (the tip: the far edge of the last covered one-cell column,
so it moves in steps of 1 / cells_across) and final height H_inf / L0 against the law's, their
relative errors, and the cells across the column (L0 / dx), which sets the resolution;
runout_q (JSON only): the runout to the 99.8 % quantile of the particles' x, a front that is
not quantised to cells, for comparing two runs on one grid.
Below the table, per sand and geometry: the error at the finest grid, and the coarsest grid
whose runout is within CONVERGED of the finest's (the resolution the runout needs).
Imports numpy, warp and mpmfx.mpm only.
"""

from __future__ import annotations

import math
import sys
import time

from mpmfx.bench import experiments as ex
from mpmfx.bench.report import print_table, write_rows
from mpmfx.mpm import preset

SANDS = {"Granular": {}, "fit 30": {"friction_angle": 30.0}}  # name -> preset("Granular") overrides
FULL = {"sizes": (32, 64, 128), "quasi2d": (0.5, 1.0, 2.0, 4.0, 8.0), "axisymmetric": (0.5, 1.0, 2.0, 4.0)}
QUICK = {"sizes": (16, 24, 32), "quasi2d": (0.5, 2.0), "axisymmetric": (0.5, 2.0)}
CONVERGED = 0.1  # a grid "resolves" the runout when it is within 10 % of the finest grid's
COLUMNS = [
    "geometry",
    "sand",
    "a",
    "grid_n",
    "cells_across",
    "runout",
    "law_runout",
    "runout_error",
    "height",
    "law_height",
    "height_error",
    "particles",
    "wall_s",
    "device",
]


def collapse_row(sand: str, a: float, grid_n: int, *, axisymmetric: bool, device=None) -> dict:
    """One collapse of `sand` (a key of SANDS) at aspect ratio a on grid_n^3 cells.
    Errors are relative: simulated / law - 1 (< 0: the column stops short / ends lower)."""
    mat = preset("Granular", **SANDS[sand])
    r = ex.column_collapse(a=a, grid_n=grid_n, material=mat, ppz=1, axisymmetric=axisymmetric, device=device)
    e = r.extra
    return {
        "geometry": "axisymmetric" if axisymmetric else "quasi2d",
        "sand": sand,
        "friction_angle": mat.friction_angle,
        "a": a,
        "grid_n": grid_n,
        "cells_across": round(e["cells_across"], 1),
        "runout": e["runout"],
        "law_runout": e["law_runout"],
        "runout_error": e["runout"] / e["law_runout"] - 1.0,
        "runout_q": e["runout_q"],
        "height": e["height"],
        "law_height": e["law_height"],
        "height_error": e["height"] / e["law_height"] - 1.0,
        "reference": e["source"],
        "particles": r.particles,
        "steps": r.steps,
        "wall_s": round(r.wall_s, 2),
        "device": r.device,
    }


def sweep(sizes, aspects: dict, device=None, sands=tuple(SANDS)) -> list[dict]:
    """Every sand x geometry x aspect ratio x grid; aspects: {"quasi2d": (a, ...), "axisymmetric": (...)}."""
    rows = []
    for sand in sands:
        for geom, avals in aspects.items():
            for a in avals:
                for n in sizes:
                    r = collapse_row(sand, a, n, axisymmetric=geom == "axisymmetric", device=device)
                    rows.append(r)
                    print(  # progress on stderr: stdout carries the table
                        f"  {geom} {sand} a={a:g} grid {n}: runout {r['runout']:.3f} (law {r['law_runout']:.3f}), "
                        f"{r['cells_across']:g} cells across, {r['particles']} particles, {r['wall_s']:.1f} s",
                        file=sys.stderr,
                        flush=True,
                    )
    return rows


def summary(rows: list[dict]) -> list[dict]:
    """Per sand and geometry: the mean and range of the runout and height errors at the finest
    grid, and `needs`: cells across the column at the coarsest grid whose runout is within
    CONVERGED of the finest grid's for every a (None: only the finest grid is)."""
    out = []
    for key in dict.fromkeys((r["sand"], r["geometry"]) for r in rows):
        mine = [r for r in rows if (r["sand"], r["geometry"]) == key]
        finest = max(r["grid_n"] for r in mine)
        top = {r["a"]: r for r in mine if r["grid_n"] == finest}
        grids = sorted({r["grid_n"] for r in mine})
        close = {  # grid -> its runout within CONVERGED of the finest grid's at every a
            n: all(
                abs(r["runout"] - top[r["a"]]["runout"]) <= CONVERGED * abs(top[r["a"]]["runout"])
                for r in mine
                if r["grid_n"] == n
            )
            for n in grids
        }
        needs = None
        for i, n in enumerate(grids[:-1]):  # the coarsest grid from which every finer one is close too
            if all(close[m] for m in grids[i:]):
                needs = min(r["cells_across"] for r in mine if r["grid_n"] == n)
                break
        run = [r["runout_error"] for r in top.values()]
        height = [r["height_error"] for r in top.values()]
        out.append(
            {
                "sand": key[0],
                "geometry": key[1],
                "reference": mine[0]["reference"],
                "grid_n": finest,
                "runout_error_mean": sum(run) / len(run),
                "runout_error_min": min(run),
                "runout_error_max": max(run),
                "height_error_mean": sum(height) / len(height),
                "needs_cells_across": needs,
            }
        )
    return out


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench", sizes=None) -> int:
    """`mpmfx bench collapse [--sizes N ...]`: the table, then one line per sand and geometry;
    writes collapse.json / collapse.csv (rows) and collapse_summary.json under `out`."""
    plan = QUICK if quick else FULL
    sizes = tuple(sorted(sizes or plan["sizes"]))
    t0 = time.perf_counter()
    rows = sweep(sizes, {g: plan[g] for g in ("quasi2d", "axisymmetric")}, device=device)
    print_table(rows, COLUMNS)
    lines = summary(rows)
    for s in lines:
        need = (
            f"runout within {100 * CONVERGED:.0f} % of the finest grid's from {s['needs_cells_across']:g} cells across"
            if s["needs_cells_across"] is not None
            else "one grid: no resolution check"
            if len(sizes) < 2
            else f"runout moves by more than {100 * CONVERGED:.0f} % up to the finest grid: finer grids needed"
        )
        print(
            f"{s['sand']} {s['geometry']} vs {s['reference']} at grid {s['grid_n']}: runout "
            f"{100 * s['runout_error_mean']:+.0f} % ({100 * s['runout_error_min']:+.0f} to "
            f"{100 * s['runout_error_max']:+.0f} %), height {100 * s['height_error_mean']:+.0f} %; {need}"
        )
    print(f"{len(rows)} collapses on {rows[0]['device']} in {time.perf_counter() - t0:.0f} s", flush=True)
    write_rows(rows, out, "collapse")
    write_rows(lines, out, "collapse_summary")
    return 0 if all(math.isfinite(r["runout"]) for r in rows) else 1
