"""Speed-against-error plot (log-log) drawn offscreen with PyVista's 2D chart API.

Imported only by `mpmfx bench accuracy` when it draws; raises ImportError (with the fix)
where pyvista is missing, e.g. on the GPU machine.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
          "tab:gray", "tab:olive", "tab:cyan"]


def cost(row: dict) -> float:
    """Wall seconds per simulated second (wall seconds of the run where the case has no clock)."""
    sim = float(row.get("sim_s") or 0.0)
    return float(row["wall_s"]) / sim if sim > 0 else float(row["wall_s"])


def speed_error_plot(rows: list[dict], out: str | Path, *, name: str = "accuracy") -> Path:
    """One line per case: x = wall seconds of stepping per simulated second, y = error (both log10). Rows with a
    non-positive error or time (exact to round-off) cannot sit on a log axis and are left
    out. Writes `<out>/<name>.png` (1000 x 700) and returns its path."""
    from mpmfx.render import import_pyvista
    pv = import_pyvista()
    chart = pv.Chart2D(x_label="wall seconds per simulated second (log)", y_label="error against reference (log)")
    chart.title = "mpmfx bench accuracy: speed against error"
    drawn = 0
    cases = list(dict.fromkeys(r["case"] for r in rows))
    for i, case in enumerate(cases):
        pts = sorted((cost(r), float(r["error"])) for r in rows
                     if r["case"] == case and float(r["error"]) > 0 and cost(r) > 0)
        if not pts:
            continue
        x, y = (np.array(a) for a in zip(*pts))
        color = COLORS[i % len(COLORS)]
        chart.line(x, y, color=color, width=2.0, label=case)
        chart.scatter(x, y, color=color, size=8, style="o")
        drawn += 1
    if drawn == 0:
        raise ValueError("speed_error_plot: no row has error > 0 and a positive cost; nothing to plot")
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
