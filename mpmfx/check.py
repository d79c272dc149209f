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
from mpmfx.meminfo import host_available
from mpmfx.render.thickness import render_thickness_heatmap

GRID_N = (8, 4096)  # the range domain.grid_n takes
# The check's peak memory, measured (peak RSS of `mpmfx check` on a cube, 2-core CPU): 944 MB
# at --grid-n 96 (its raster already at its cap, geometry.thickness.MAX_RASTER_VOXELS), 1.23 GB
# at 192, 9.48 GB at 1024 (459 s): what grows is the mesh refined to the cell and its samples,
# as grid_n^2 (10.4 and 8.0 kB per grid_n^2 between those points). This bound is over each.
CHECK_BYTES = 1_000_000_000
CHECK_BYTES_PER_GRID2 = 10_500


def _too_big(grid_n: int) -> str | None:
    """Why --grid-n is refused (outside GRID_N, or more memory than the host has), or None."""
    lo, hi = GRID_N
    if not lo <= grid_n <= hi:
        return f"--grid-n {grid_n}: give {lo} to {hi} cells per axis (as domain.grid_n), e.g. --grid-n 64"
    need, free = CHECK_BYTES + grid_n**2 * CHECK_BYTES_PER_GRID2, host_available()
    if free is not None and need > free:
        return (
            f"--grid-n {grid_n}: the check needs ~{need / 1e9:.1f} GB, over the {free / 1e9:.1f} GB of "
            f"memory available; lower --grid-n"
        )
    return None


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
    if (refused := _too_big(grid_n)) is not None:
        print(f"mpmfx check: {refused}", file=sys.stderr)
        return 2
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
