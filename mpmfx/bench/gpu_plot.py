"""Plot of `mpmfx bench gpu`: throughput against particle count, one line per implementation
and scene (fast mode, the default path), log-log, drawn with matplotlib (ImportError where
it is missing).

    python -m mpmfx.bench.gpu_plot renders/bench      # redraw from renders/bench/gpu.csv
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path


def throughput_plot(rows: list[dict], out: str | Path, *, name: str = "gpu") -> Path:
    import matplotlib  # optional: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # optional: matplotlib

    fig, ax = plt.subplots(figsize=(9, 6), dpi=110)
    lines: dict[tuple, list] = {}
    for r in rows:
        if not r.get("G_per_s") or str(r.get("det") or "0") not in ("0", "False") or r.get("scene") == "Mixed":
            continue
        path = r.get("path", "device")
        if r["impl"] == "mpmfx" and path not in ("device", "device-sort32"):
            continue  # the other lever rows (reference loop, no graphs, ...) are in the table, not the plot
        impl = r["impl"] + (" sorted once a chunk" if path == "device-sort32" else "")
        lines.setdefault((impl, r["scene"]), []).append((int(r["particles"]), float(r["G_per_s"])))
    for (impl, sc), pts in sorted(lines.items()):
        pts.sort()
        ax.plot(
            [p for p, _ in pts],
            [g for _, g in pts],
            "o-" if impl == "mpmfx" else "o:" if impl.startswith("mpmfx") else "s--",
            label=f"{impl} {sc}",
        )
    device = next((r.get("device") for r in rows if r.get("device")), "?")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles")
    ax.set_ylabel("G particle-substeps / s")
    ax.set_title(f"MLS-MPM substep throughput through Solver.advance(), {device}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.png"
    fig.savefig(path)
    plt.close(fig)
    return path


if __name__ == "__main__":
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "renders/bench")
    with open(folder / "gpu.csv") as f:
        print(throughput_plot(list(csv.DictReader(f)), folder))
