"""``mpmfx check ASSET``: thickness report for one asset, as a table or JSON, and its heatmap.

The check is mpmfx.geometry.check's; the heatmap is drawn here, above both geometry and render.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from mpmfx.diskspace import diagnosed, message
from mpmfx.geometry.check import check_asset, topology_line
from mpmfx.geometry.thickness import Verdict
from mpmfx.render.thickness import render_thickness_heatmap


def run_check(
    asset: str,
    *,
    grid_n: int,
    origin=None,
    size=None,
    as_json: bool = False,
    out_dir: str | Path | None = None,
    prim_path: str | None = None,
) -> int:
    """Check ``asset``'s thickness at ``grid_n`` cells per domain edge (only its part
    ``prim_path``, as mpmfx.geometry.mesh.load_mesh takes it, where given).

    origin (3,) m and size (m) give the domain (default: the mesh bbox cube, padded 10 %).
    Prints the table (or JSON with ``as_json``) to stdout, writes ``report.json`` and
    ``thickness.png`` to ``out_dir`` (default ./renders/check/<asset stem>/).
    Returns 0 on PASS or WARN, 1 on FAIL, 2 on bad input (message on stderr).
    """
    try:
        checked = check_asset(asset, grid_n=grid_n, origin=origin, size=size, prim_path=prim_path)
    except ValueError as exc:  # MeshError included
        print(f"mpmfx check: {exc}", file=sys.stderr)
        return 2
    report = checked.report
    out = Path(out_dir) if out_dir is not None else Path("renders/check") / Path(asset).stem
    data = checked.to_dict()
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.json").write_text(json.dumps(data, indent=2) + "\n")
        png = render_thickness_heatmap(
            checked.mesh, report.vertex_thickness_cells, out / "thickness.png", warn_cells=report.warn_cells
        )
    except Exception as exc:
        if (said := diagnosed(exc, out)) is None:  # said as the output folder
            raise
        print(f"mpmfx check: {message(said, cache_root=None)}", file=sys.stderr)
        return 2
    if as_json:
        print(json.dumps(data, indent=2))
    else:
        print(report.format_table())
        print(f"  mesh               {topology_line(checked.topology)}")
        if any(r.thickness_cells == 0 for r in report.regions):
            print("  (0.00 cells: parts thinner than the measuring lattice, which no grid_n here resolves)")
        print(f"  wrote {out / 'report.json'} and {png}")
    return 1 if report.verdict is Verdict.FAIL else 0
