"""Stage 1: meshes become material points; the five-cell thickness rule is checked first.

Output (world units): `particles.npz`, an `mpmfx.io.frames.SeedParticles` record; `thickness.json`, one heatmap PNG and one
`sdf_<object>.npz` per object.
"""

from __future__ import annotations

import warnings

import numpy as np

from mpmfx.cache import file_hash, write_json
from mpmfx.config import Shot, ShotError, Thickness
from mpmfx.geometry import MESH_LOADING
from mpmfx.geometry.emitters import EmitterError, emit, shape_mesh, source_points
from mpmfx.geometry.mesh import MeshError, check_in_domain, load_mesh, transform_mesh
from mpmfx.geometry.thickness import Verdict, check_thickness, refine_for_heatmap
from mpmfx.geometry.voxelise import voxelise
from mpmfx.io.frames import SeedParticles, write_arrays
from mpmfx.render.camera import solver_floor
from mpmfx.render.thickness import render_thickness_heatmap
from mpmfx.stages.base import Context, StageError, quiet_warp

NAME, VERSION, PER_FRAME, FRAME_EXT = "voxelise", 1, False, "npz"
CODE = (
    "mpmfx.stages.voxelise",
    *MESH_LOADING,
    "mpmfx.geometry.inside",
    "mpmfx.geometry.voxelise",
    "mpmfx.geometry.emitters",
    "mpmfx.geometry.thickness",
    "mpmfx.render.thickness",
    "mpmfx.mpm.materials",
    "mpmfx.io.frames",
)


def params(shot: Shot) -> dict:
    objects = [
        o.model_dump(
            mode="json",
            include={"name", "prim_path", "translate", "rotate", "scale", "velocity", "angular_velocity", "start_time"},
        )
        for o in shot.objects
    ]
    emitters = [e.model_dump(mode="json", exclude={"material", "overrides"}) for e in shot.emitters]
    for o, fluid in zip(objects, shot.fluid_objects()):
        o["fluid"] = fluid
    return {
        "domain": shot.domain.model_dump(mode="json"),
        "objects": objects,
        "emitters": emitters,
        "voxelise": shot.voxelise.model_dump(mode="json"),
    }


def inputs(shot: Shot) -> dict[str, str]:
    out = {o.name: file_hash(shot.resolve(o.mesh)) for o in shot.objects}
    return out | {f"emitter:{e.name}": file_hash(shot.resolve(e.mesh)) for e in shot.emitters if e.shape == "mesh"}


def run(ctx: Context) -> dict:
    quiet_warp()  # the inside tests may start Warp: without its no-driver warning on a CPU
    shot, dom = ctx.shot, ctx.shot.domain
    xs, vs, vols, bodies, births, reports = [], [], [], [], [], {}
    fluid = shot.fluid_objects()
    for body, obj in enumerate(ctx.progress(shot.objects, total=len(shot.objects), desc="voxelise", unit="object")):
        path = shot.resolve(obj.mesh)
        try:
            mesh = transform_mesh(
                load_mesh(path, prim_path=obj.prim_path),
                translate=obj.translate,
                rotate_deg=obj.rotate,
                scale=obj.scale,
            )
            check_in_domain(
                mesh, origin=dom.origin, size=dom.size, name=f"objects.{obj.name} ({path})", floor=solver_floor(shot)
            )
        except MeshError as exc:  # the asset or its placement: bad input, exit 2 like the README says
            raise ShotError(f"objects.{obj.name}: {exc}") from None
        if fluid[body]:
            reports[obj.name] = {"skipped": "fluid: the five-cell rule is about holding a shape"}
        else:
            reports[obj.name] = _thickness(ctx, obj, mesh, check_thickness, Verdict).to_dict()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            vox = voxelise(
                mesh,
                origin=dom.origin,
                size=dom.size,
                grid_n=dom.grid_n,
                ppc=shot.voxelise.ppc,
                seed=shot.voxelise.seed + body,
            )
        for w in caught:
            ctx.warn(f"objects.{obj.name}: {w.message}")
        if len(vox.points) == 0:
            raise StageError(
                f"objects.{obj.name}: {path} produced no particles at domain.grid_n = {dom.grid_n}: "
                f"the mesh is thinner than a cell; raise domain.grid_n or the object's scale"
            )
        _check_walls(ctx, f"objects.{obj.name}", vox.points)
        centroid = vox.points.mean(axis=0)
        v = np.asarray(obj.velocity) + np.cross(np.asarray(obj.angular_velocity), vox.points - centroid)
        xs.append(vox.points), vs.append(v), vols.append(vox.volume)
        bodies.append(np.full(len(vox.points), body, np.int32))
        births.append(np.full(len(vox.points), obj.start_time))
        write_arrays(
            ctx.entry.root / f"sdf_{obj.name}.npz",
            {"sdf": vox.sdf, "origin": np.asarray(vox.sdf_origin), "voxel": np.float64(vox.sdf_voxel)},
        )
    for i, em in enumerate(shot.emitters):
        out = _emit(shot, i, em)
        xs.append(out.points), vs.append(np.tile(np.asarray(em.velocity, float), (len(out.points), 1)))
        vols.append(np.full(len(out.points), out.volume)), births.append(out.birth)
        bodies.append(np.full(len(out.points), len(shot.objects) + i, np.int32))
    write_json(ctx.entry.root / "thickness.json", reports)
    birth = np.concatenate(births)
    SeedParticles(
        x=np.concatenate(xs),
        v=np.concatenate(vs),
        volume=np.concatenate(vols),
        body=np.concatenate(bodies),
        birth=birth if np.any(birth > 0) else None,  # a shot without late entries: as before
    ).write(ctx.entry.root)
    n = sum(len(x) for x in xs)
    extra = {"entering_later": int(np.count_nonzero(birth > 0))} if np.any(birth > 0) else {}
    return {"particles": n, **extra, "thickness": {k: r.get("verdict", "skipped") for k, r in reports.items()}}


def _check_walls(ctx: Context, key: str, points: np.ndarray) -> None:
    """Warn when particles (m, (n, 3)) start beyond the solver's walls (`Shot.wall_box`): they
    start inside a wall, which pushes them out in the first substeps."""
    lo, hi = map(np.asarray, ctx.shot.wall_box())
    below, above = np.clip(lo - points, 0, None).max(axis=0), np.clip(points - hi, 0, None).max(axis=0)
    if not (below.any() or above.any()):
        return
    n = int(np.count_nonzero(np.any((points < lo) | (points > hi), axis=1)))
    dx = ctx.shot.domain.size / ctx.shot.domain.grid_n
    shift = ", ".join(f"{d:.4g}" for d in below - above)
    ctx.warn(
        f"{key}: {n} of {len(points)} particles start beyond the solver's walls, up to "
        f"{max(below.max(), above.max()) / dx:.2g} cells (the walls are the planes of the box "
        f"{tuple(round(c, 4) for c in lo)}..{tuple(round(c, 4) for c in hi)} m; the floor is y = {lo[1]:.4g} m); "
        f"translate it by ({shift}) m"
    )


def _emit(shot: Shot, i: int, em):
    """Emitter i's particles and births (geometry.emitters); bad input is a ShotError naming the key."""
    dom, key = shot.domain, f"{shot.source or shot.base_dir}: emitters[{i}]"
    try:
        if em.shape == "mesh":
            mesh = load_mesh(shot.resolve(em.mesh), prim_path=em.prim_path)
        else:
            mesh = shape_mesh(em.shape, size=em.size, radius=em.radius)
        mesh = transform_mesh(mesh, translate=em.translate, rotate_deg=em.rotate, scale=em.scale)
        check_in_domain(mesh, origin=dom.origin, size=dom.size, name=f"emitters.{em.name}", floor=solver_floor(shot))
        points, h = source_points(mesh, origin=dom.origin, size=dom.size, grid_n=dom.grid_n, ppc=shot.voxelise.ppc)
    except (MeshError, EmitterError) as exc:
        raise ShotError(f"{key}.{'mesh' if em.shape == 'mesh' else 'shape'} ({em.name}): {exc}") from None
    vp = (dom.size / dom.grid_n) ** 3 / shot.voxelise.ppc  # m^3 a particle: the objects' (voxelise) and the budget's
    return emit(
        points,
        h,
        particle_volume=vp,
        rate=em.rate,
        velocity=em.velocity,
        start=em.start_time,
        end=em.end_time,
        seed=em.seed,
    )


def _thickness(ctx, obj, mesh, check_thickness, Verdict):
    """Run the five-cell check and obey voxelise.thickness (error | warn | ignore)."""
    dom, mode = ctx.shot.domain, ctx.shot.voxelise.thickness
    mesh = refine_for_heatmap(mesh, grid_n=dom.grid_n, size=dom.size)
    report = check_thickness(mesh, grid_n=dom.grid_n, origin=dom.origin, size=dom.size, name=obj.name)
    if mode is not Thickness.IGNORE:
        try:
            render_thickness_heatmap(mesh, report.vertex_thickness_cells, ctx.entry.root / f"thickness_{obj.name}.png")
        except ImportError as exc:  # the report still stands; only the picture is missing
            ctx.notes.append(f"objects.{obj.name}: no thickness heatmap ({exc})")
    if report.verdict is not Verdict.PASS and mode is not Thickness.IGNORE:
        msg = (
            f"objects.{obj.name}: thinnest feature {report.min_thickness_cells:.1f} cells at grid_n "
            f"{dom.grid_n} ({sum(not r.ignored for r in report.regions)} thin regions; under ~5 cells a feature cannot hold its "
            f"shape). Thicken the mesh, raise its scale, or set domain.grid_n >= "
            f"{report.min_grid_n_to_pass}; see `mpmfx check {ctx.shot.source or obj.mesh}`"
        )
        if mode is Thickness.ERROR and report.verdict is Verdict.FAIL:
            raise StageError(msg + ' (or set voxelise.thickness = "warn")')
        ctx.warn(msg)
    return report
