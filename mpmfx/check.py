"""``mpmfx check ASSET``: thickness report for one asset, as a table or JSON, and its heatmap;
``mpmfx check SHOT.toml``: the same for each object of a shot, placed as the shot places it and
measured at the shot's grid (its domain, in its units), and refused where it starts outside
the domain or below the solver's floor.

The check is mpmfx.geometry.check's; the heatmap is drawn here, above both geometry and render.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from mpmfx.config import ShotError
from mpmfx.diskspace import diagnosed, message
from mpmfx.geometry.check import check_asset, check_placed, topology_line
from mpmfx.geometry.mesh import MeshError, check_in_domain, load_mesh, transform_mesh
from mpmfx.geometry.thickness import Verdict
from mpmfx.meminfo import host_available
from mpmfx.render.camera import solver_floor
from mpmfx.render.thickness import render_thickness_heatmap
from mpmfx.shotfile import load_shot_config

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


def run_shot_check(
    path: str, *, grid_n: int | None = None, as_json: bool = False, out_dir: str | Path | None = None
) -> int:
    """Check each solid object of the shot at ``path`` (fluids hold no shape: skipped) where
    the shot places it, at the shot's domain and grid (``grid_n``: another grid, e.g. to try a
    finer one). Prints a table per object (or one JSON document), writes ``report.json`` and
    ``thickness_<object>.png`` to ``out_dir`` (default ./renders/check/<shot name>/).
    Returns 0 on PASS or WARN, 1 on any FAIL, 2 on bad input (an object outside the domain or
    below the solver's floor among it; nothing written then)."""
    try:
        shot = load_shot_config(path, [f"domain.grid_n={grid_n}"] if grid_n is not None else [])
        placed = _placed_objects(shot)
    except (ShotError, ValueError) as exc:  # MeshError included
        print(f"mpmfx check: {exc}", file=sys.stderr)
        return 2
    dom = shot.domain
    out = Path(out_dir) if out_dir is not None else Path("renders/check") / shot.shot.name
    out.mkdir(parents=True, exist_ok=True)
    data = {"shot": str(path), "grid_n": dom.grid_n, "objects": {}}
    code = 0
    for name, (mesh, fluid, source) in placed.items():
        if fluid:
            data["objects"][name] = {"skipped": "fluid: the five-cell rule is about holding a shape"}
            continue
        checked = check_placed(mesh, grid_n=dom.grid_n, origin=dom.origin, size=dom.size, name=name)
        report = checked.report
        data["objects"][name] = checked.to_dict()
        render_thickness_heatmap(
            checked.mesh, report.vertex_thickness_cells, out / f"thickness_{name}.png", warn_cells=report.warn_cells
        )
        code = max(code, 1 if report.verdict is Verdict.FAIL else 0)
        if not as_json:
            print(f"objects.{name} ({source}):")
            print(report.format_table())
            print(f"  mesh               {topology_line(checked.topology)}")
    (out / "report.json").write_text(json.dumps(data, indent=2) + "\n")
    if as_json:
        print(json.dumps(data, indent=2))
    else:
        skipped = [n for n, (_, fluid, _) in placed.items() if fluid]
        if skipped:
            print(f"skipped (fluids hold no shape): {', '.join(skipped)}")
        print(f"wrote {out / 'report.json'} and a heatmap per object")
    return code


def _placed_objects(shot) -> dict:
    """{object name: (its mesh where the shot places it (m), is a fluid, its file as the shot
    names it)}; raises MeshError
    naming the object where one starts outside the domain or below the solver's floor."""
    dom, out = shot.domain, {}
    for obj, fluid in zip(shot.objects, shot.fluid_objects()):
        where = f"objects.{obj.name} ({shot.resolve(obj.mesh)})"
        try:
            mesh = load_mesh(shot.resolve(obj.mesh), prim_path=obj.prim_path)
            mesh = transform_mesh(mesh, translate=obj.translate, rotate_deg=obj.rotate, scale=obj.scale)
            check_in_domain(mesh, origin=dom.origin, size=dom.size, name=where, floor=solver_floor(shot))
        except MeshError as exc:
            raise MeshError(str(exc) if str(exc).startswith(where) else f"{where}: {exc}") from None
        out[obj.name] = (mesh, fluid, obj.mesh)
    return out
