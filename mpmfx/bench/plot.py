"""Speed-against-error plot (log-log) drawn offscreen with PyVista's 2D chart API.

Imported only by `mpmfx bench accuracy` / `mpmfx bench surface` when they draw; raises
ImportError (with the fix) where pyvista is missing, e.g. on the GPU machine.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mpmfx.render import import_pyvista

COLORS = [
    "tab:blue",
    "tab:orange",
    "tab:green",
    "tab:red",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:gray",
    "tab:olive",
    "tab:cyan",
]


def cost(row: dict) -> float:
    """Wall seconds per simulated second (wall seconds of the run where the case has no clock)."""
    sim = float(row.get("sim_s") or 0.0)
    return float(row["wall_s"]) / sim if sim > 0 else float(row["wall_s"])


def _save_loglog(pv, chart, out: str | Path, name: str) -> Path:
    """Both axes log10; render `chart` offscreen to `<out>/<name>.png` (1000 x 700)."""
    chart.x_axis.log_scale = True
    chart.y_axis.log_scale = True
    plotter = pv.Plotter(off_screen=True, window_size=(1000, 700))
    plotter.add_chart(chart)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.png"
    plotter.screenshot(str(path))
    plotter.close()
    return path


def speed_error_plot(rows: list[dict], out: str | Path, *, name: str = "accuracy") -> Path:
    """One line per case: x = wall seconds of stepping per simulated second, y = error (both log10). Rows with a
    non-positive error or time (exact to round-off) cannot sit on a log axis and are left
    out. Writes `<out>/<name>.png` (1000 x 700) and returns its path."""
    pv = import_pyvista()
    chart = pv.Chart2D(x_label="wall seconds per simulated second (log)", y_label="error against reference (log)")
    chart.title = "mpmfx bench accuracy: speed against error"
    drawn = 0
    cases = list(dict.fromkeys(r["case"] for r in rows))
    for i, case in enumerate(cases):
        pts = sorted(
            (cost(r), float(r["error"])) for r in rows if r["case"] == case and float(r["error"]) > 0 and cost(r) > 0
        )
        if not pts:
            continue
        x, y = (np.array(a) for a in zip(*pts))
        color = COLORS[i % len(COLORS)]
        chart.line(x, y, color=color, width=2.0, label=case)
        chart.scatter(x, y, color=color, size=8, style="o")
        drawn += 1
    if drawn == 0:
        raise ValueError("speed_error_plot: no row has error > 0 and a positive cost; nothing to plot")
    return _save_loglog(pv, chart, out, name)


MARKERS = ["o", "s", "d", "x", "+"]  # Chart2D's scatter styles: one per particle count


def count_label(n: int) -> str:
    """100000 -> "100k", 10000000 -> "10M"."""
    return f"{n / 1e6:g}M" if n >= 1_000_000 else f"{n / 1e3:g}k"


def surface_plot(rows: list[dict], out: str | Path, *, name: str = "surface") -> Path:
    """`mpmfx bench surface`: x = particles per second, y = mean distance of the mesh's surface to
    the analytic one in particle spacings h (area-weighted, `surface_cases.surface_error`; the
    vertex mean for rows written before it was measured), both log10. One colour per method, one marker per particle
    count (legend "method @ count"); each series holds every shape and sampling. Rows with a
    non-positive or non-finite value are left out. Writes `<out>/<name>.png` (1000 x 700)."""
    pv = import_pyvista()
    chart = pv.Chart2D(x_label="particles per second (log)", y_label="mean surface error / h (log)")
    chart.title = "mpmfx bench surface: speed against error"
    methods = list(dict.fromkeys(r["method"] for r in rows))
    counts = sorted({int(r.get("count", r["particles"])) for r in rows})
    drawn = 0
    for i, method in enumerate(methods):
        for j, count in enumerate(counts):
            pts = [
                (float(r["particles_per_s"]), float(r.get("err_surface_h", r["err_mean_h"])))
                for r in rows
                if r["method"] == method and int(r.get("count", r["particles"])) == count
            ]
            pts = [(x, y) for x, y in pts if np.isfinite(x) and np.isfinite(y) and x > 0 and y > 0]
            if not pts:
                continue
            x, y = (np.array(a) for a in zip(*pts))
            chart.scatter(
                x,
                y,
                color=COLORS[i % len(COLORS)],
                size=10,
                style=MARKERS[j % len(MARKERS)],
                label=f"{method} @ {count_label(count)}",
            )
            drawn += 1
    if drawn == 0:
        raise ValueError("surface_plot: no row has a positive speed and error; nothing to plot")
    return _save_loglog(pv, chart, out, name)
