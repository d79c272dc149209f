"""The experiments section of `mpmfx bench accuracy`: the solver against the laboratory.

- water: dam-break surge front against Martin & Moyce 1952 (n^2 = 2, two column widths) and
  Koshizuka & Oka 1996, frictionless walls and a rough (sticky) floor;
- sand: granular column collapse runout and final height against Lube et al. 2005 and
  Lajeunesse et al. 2005 (quasi-2D) and Lube et al. 2004 (axisymmetric): the Granular preset
  as shipped, and the "repose" fit at a range of angles of repose (the materials differ:
  Lube's natural sands, rice and sugar, Lajeunesse's glass beads);
- pile: sand poured from a hopper heaps into a cone whose slope (its angle of repose) is
  compared with the material's friction angle (mpmfx.bench.pile);
- snow: the confined-compression table derived from Stomakhin et al. 2013 (the paper's
  constants; docs/physics.md, "Validation"), a per-particle check of the return map (no grid, so one resolution).
Each at the sweep's resolutions; rows carry the source, the error and the cells across the
column. Reference data: mpmfx/bench/data/*.csv (each names its source in its header).
Imports numpy, warp and mpmfx.mpm only, except the plot (pyvista, skipped without it).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpmfx.bench import experiments as ex
from mpmfx.bench import pile
from mpmfx.bench.plot import COLORS
from mpmfx.bench.snow_table import snow_compression
from mpmfx.render import import_pyvista

DATA = Path(__file__).parent / "data"


@dataclass(frozen=True)
class LabSweep:
    """dam_grids / sand_grids / axi_grids: grid_n of each resolution; ppz: particles per cell
    across the channel depth (the flow is uniform there); aspects: a = H0 / L0; materials:
    (friction_fit, friction_angle in degrees) of each Granular variant; pile_grids: grid_n of
    each poured pile, of the Granular preset as shipped."""

    dam_grids: tuple = (16,)
    dam_width: float = 0.25
    dam_t_star: tuple = (1.0, 1.6, 2.2)
    sand_grids: tuple = (16,)
    aspects: tuple = (1.0,)
    materials: tuple = (("compression", 38.0), ("repose", 32.0))  # (friction_fit, friction_angle)
    axi_grids: tuple = ()
    axi_aspects: tuple = (1.0,)
    ppz: int = 1
    pile_grids: tuple = (32,)


QUICK = LabSweep(axi_grids=(16,))
FULL = LabSweep(
    dam_grids=(32, 64, 128),
    dam_width=0.2,
    dam_t_star=(0.8, 1.2, 1.6, 2.0, 2.4, 2.8),
    sand_grids=(32, 64, 128),
    aspects=(0.5, 1.0, 2.0, 4.0, 8.0),
    materials=(("compression", 38.0),) + tuple(("repose", p) for p in (24.0, 28.0, 32.0, 36.0)),
    axi_grids=(32, 64, 128),
    axi_aspects=(0.5, 1.0, 2.0, 4.0),
    pile_grids=(32, 48, 64),
)


def read_csv(name: str) -> list[dict]:
    """Rows of data/<name>.csv as dicts of floats (or str where not numeric); '#' lines skipped."""
    with open(DATA / name) as f:
        lines = [ln for ln in f if not ln.startswith("#")]
    out = []
    for r in csv.DictReader(lines):
        out.append({k: _num(v) for k, v in r.items()})
    return out


def _num(v: str):
    try:
        return float(v)
    except ValueError:
        return v


def water_references() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """name -> (T, Z) of each digitised dam-break front."""
    mm = read_csv("martin_moyce_1952.csv")
    refs = {f"martin_moyce_1952_a{a:g}in": [(r["T"], r["Z"]) for r in mm if r["a_in"] == a] for a in (1.125, 2.25)}
    refs["koshizuka_oka_1996"] = [(r["T"], r["Z"]) for r in read_csv("koshizuka_oka_1996.csv")]
    return {k: tuple(np.array(c) for c in zip(*v)) for k, v in refs.items()}


def front_error(T, Z, ref) -> float:
    """Mean signed relative front error (Z - Z_exp) / Z_exp over the sim samples inside the
    data's T range (> 0: the simulated surge runs ahead)."""
    Tr, Zr = ref
    T, Z = np.asarray(T), np.asarray(Z)
    keep = (T >= Tr.min()) & (T <= Tr.max())
    if not keep.any():
        return float("nan")
    return float(np.mean(Z[keep] / np.interp(T[keep], Tr, Zr) - 1.0))


def water_rows(sweep: LabSweep, device) -> tuple[list[dict], list]:
    refs = water_references()
    rows, runs = [], []
    for walls, kw in (
        ("frictionless", {"floor": "separate", "wall_friction": 0.0}),
        ("rough floor", {"floor": "sticky", "wall_friction": 0.0}),
    ):
        for n in sweep.dam_grids:
            r = ex.dam_break(
                grid_n=n, width=sweep.dam_width, t_star=sweep.dam_t_star, ppz=sweep.ppz, device=device, **kw
            )
            runs.append((walls, r))
            print(
                f"  dam_break {walls} grid {n}: Z {r.extra['Z'][-1]:.3f} at T {r.extra['T'][-1]:.2f}, "
                f"{r.particles} particles, {r.wall_s:.1f} s",
                flush=True,
            )
            for name, ref in refs.items():
                rows.append(
                    {
                        "case": f"dam_break {walls}",
                        "reference": name,
                        "grid_n": n,
                        "cells_across": r.extra["cells_across"],
                        "error": front_error(r.extra["T"], r.extra["Z"], ref),
                        "metric": "mean (Z-Z_exp)/Z_exp",
                        "value": r.extra["Z"][-1],
                        "T": r.extra["T"][-1],
                        "particles": r.particles,
                        "wall_s": r.wall_s,
                        "device": r.device,
                    }
                )
    return rows, runs


def sand_rows(sweep: LabSweep, device) -> tuple[list[dict], list]:
    rows, runs = [], []
    todo = [(False, a, n) for a in sweep.aspects for n in sweep.sand_grids]
    todo += [(True, a, n) for a in sweep.axi_aspects for n in sweep.axi_grids]
    for fit, phi in sweep.materials:
        for axi, a, n in todo:
            r = ex.column_collapse(
                a=a, grid_n=n, fit=fit, friction_angle=phi, ppz=sweep.ppz, axisymmetric=axi, device=device
            )
            e = r.extra
            runs.append(r)
            print(
                f"  collapse {'axi' if axi else '2d'} {fit} {phi:g} a={a:g} grid {n}: runout {e['runout']:.3f} "
                f"(law {e['law_runout']:.3f}) height {e['height']:.3f} (law {e['law_height']:.3f}) "
                f"flank {e['flank_angle']:.1f} deg, "
                f"{e['cells_across']:.1f} cells, {r.particles} particles, {r.wall_s:.1f} s",
                flush=True,
            )
            geom = "axisymmetric" if axi else "quasi2d"
            base = {
                "case": f"collapse {geom} {fit} {phi:g}",
                "grid_n": n,
                "a": a,
                "cells_across": e["cells_across"],
                "friction_angle": phi,
                "flank_angle": e["flank_angle"],
                "particles": r.particles,
                "wall_s": r.wall_s,
                "device": r.device,
            }
            for source in ("lube2004",) if axi else ("lube2005", "lajeunesse2005"):
                law_run, law_h = ex.runout_law(a, source)
                rows.append(
                    {
                        **base,
                        "reference": source,
                        "metric": "runout (L-L0)/L0 / law - 1",
                        "value": e["runout"],
                        "law": law_run,
                        "error": e["runout"] / law_run - 1.0,
                    }
                )
                rows.append(
                    {
                        **base,
                        "reference": source,
                        "metric": "height H/L0 / law - 1",
                        "value": e["height"],
                        "law": law_h,
                        "error": e["height"] / law_h - 1.0,
                    }
                )
    return rows, runs


def pile_rows(sweep: LabSweep, device) -> list[dict]:
    """The poured pile's repose angle against the Granular preset's friction angle."""
    rows = []
    for n in sweep.pile_grids:
        p = pile.pour(grid_n=n, device=device)
        phi = p.extra["friction_angle"]
        print(
            f"  pile grid {n}: repose angle {p.angle:.1f} deg (outer flank {p.extra['outer_angle']:.1f}; "
            f"friction angle {phi:g}), radius "
            f"{p.extra['cells_across']:.1f} cells, {p.particles} particles, {p.wall_s:.1f} s",
            flush=True,
        )
        rows.append(
            {
                "case": f"pile {p.extra['fit']} {phi:g}",
                "reference": "friction_angle",
                "grid_n": n,
                "cells_across": p.extra["cells_across"],
                "value": p.angle,
                "law": phi,
                "error": p.angle / phi - 1.0,
                "metric": "repose angle / friction angle - 1",
                "outer_angle": p.extra["outer_angle"],
                "particles": p.particles,
                "wall_s": p.wall_s,
                "device": p.device,
            }
        )
    return rows


def snow_rows(device) -> list[dict]:
    row = snow_compression(device=device)
    return [
        {
            "case": "snow confined compression",
            "reference": "Stomakhin et al. 2013 (derived table)",
            "grid_n": 0,
            "error": row["error"],
            "metric": row.get("metric", "max rel stress error"),
            "device": row.get("device", ""),
        }
    ]


def trend(rows: list[dict]) -> list[dict]:
    """Per (case, reference, a, metric): errors from coarse to fine and whether |error| shrinks."""
    out, groups = [], {}
    for r in rows:
        if r.get("grid_n"):
            groups.setdefault((r["case"], r["reference"], r.get("a", ""), r["metric"]), []).append(r)
    for (case, ref, a, metric), rs in groups.items():
        rs = sorted(rs, key=lambda r: r["grid_n"])
        errs = [r["error"] for r in rs]
        out.append(
            {
                "case": case,
                "reference": ref,
                "a": a,
                "metric": metric,
                "grids": "/".join(str(r["grid_n"]) for r in rs),
                "errors": "/".join(f"{e:+.3f}" for e in errs),
                "shrinks": bool(len(errs) > 1 and abs(errs[-1]) <= abs(errs[0])),
            }
        )
    return out


def run_lab(sweep: LabSweep, device=None) -> tuple[list[dict], dict]:
    """All experiment rows and the plotted series (JSON-able: experiments_series.json)."""
    w_rows, w_runs = water_rows(sweep, device)
    s_rows, s_runs = sand_rows(sweep, device)
    series = {
        "water": [
            {"label": f"{walls} grid {r.grid_n}", "T": list(r.extra["T"]), "Z": list(r.extra["Z"])}
            for walls, r in w_runs
        ],
        "sand": [
            {
                "geom": "axi" if r.extra["source"] == "lube2004" else "2d",
                "fit": f"{r.extra['fit']} {r.extra['friction_angle']:g}",
                "grid_n": r.grid_n,
                "a": r.extra["a"],
                "runout": r.extra["runout"],
            }
            for r in s_runs
        ],
    }
    return w_rows + s_rows + pile_rows(sweep, device) + snow_rows(device), series


def lab_plot(series: dict, out, *, name: str = "experiments") -> list[Path]:
    """Two PNGs: surge front Z(T) against the experiments, and runout against a with the laws."""
    pv = import_pyvista()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    chart = pv.Chart2D(x_label="T = t sqrt(2g/a)", y_label="Z = front / a")
    chart.title = "dam break: surge front (points: experiments)"
    for i, (key, (T, Z)) in enumerate(water_references().items()):
        chart.scatter(T, Z, color=COLORS[i], size=9, style="o", label=key)
    for j, w in enumerate(series["water"]):
        chart.line(np.array(w["T"]), np.array(w["Z"]), color=COLORS[(3 + j) % len(COLORS)], width=2, label=w["label"])
    paths.append(_shot(pv, chart, out / f"{name}_water.png"))
    chart = pv.Chart2D(x_label="a = H0 / L0", y_label="(L - L0) / L0")
    chart.title = "granular collapse runout (lines: published laws)"
    a = np.linspace(0.3, 8.5, 60)
    for i, src in enumerate(("lube2005", "lajeunesse2005", "lube2004")):
        chart.line(a, np.array([ex.runout_law(v, src)[0] for v in a]), color=COLORS[i], width=2, label=src)
    finest = {}
    for r in series["sand"]:  # one series per material: its finest grid
        finest[(r["geom"], r["fit"])] = max(finest.get((r["geom"], r["fit"]), 0), r["grid_n"])
    groups = {}
    for r in series["sand"]:
        if r["grid_n"] == finest[(r["geom"], r["fit"])]:
            groups.setdefault((r["geom"], r["fit"], r["grid_n"]), []).append(r)
    for k, ((geom, fit, n), rs) in enumerate(sorted(groups.items())):
        chart.scatter(
            np.array([r["a"] for r in rs]),
            np.array([r["runout"] for r in rs]),
            color=COLORS[(3 + k) % len(COLORS)],
            size=8,
            style="d" if fit.startswith("compression") else "s",
            label=f"{geom} {fit} grid {n}",
        )
    top = max([r["runout"] for r in series["sand"]] + [ex.runout_law(8.5, "lajeunesse2005")[0]])
    chart.y_range = [0.0, 1.7 * top]  # headroom: the legend sits top right, over no data
    paths.append(_shot(pv, chart, out / f"{name}_sand.png"))
    return paths


def _shot(pv, chart, path: Path) -> Path:
    plotter = pv.Plotter(off_screen=True, window_size=(1000, 700))
    plotter.add_chart(chart)
    plotter.screenshot(str(path))
    plotter.close()
    return path


def summary(rows: list[dict]) -> list[str]:
    """Sentences an artist reads, from the finest grid of each case."""
    lines = []
    finest = {}
    for r in rows:
        key = (r["case"], r["reference"], r.get("a", ""), r["metric"])
        if r.get("grid_n") and (key not in finest or r["grid_n"] > finest[key]["grid_n"]):
            finest[key] = r
    for (case, ref, a, metric), r in sorted(finest.items(), key=lambda kv: str(kv[0])):
        if math.isfinite(r["error"]):
            where = f" a={a:g}" if a != "" else ""
            lines.append(
                f"{case}{where} vs {ref}: {100 * r['error']:+.0f} % at {r['cells_across']:.0f} cells across ({metric})"
            )
    return lines
