"""Stage 2: MLS-MPM from the voxelised particles, one particle file per frame, resumable.

World units stop here: particles enter the solver in the normalised domain [0,1]^3
(x_dom = (x - origin) / size, v_dom = v / size, gravity_dom = g / size; guide section 2) and
frames are written back in world units. Frames: `frames/NNNN.npz` with x, v (n,3) float32
(m, m/s), id, material, body (n,) int32 and Jp, J (n,) float32; `checkpoints/NNNN.npz` hold the
full solver state every `solver.checkpoint_every` frames so a killed run resumes exactly.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mpmfx.cache import code_hash, write_json
from mpmfx.config import Shot, ShotError
from mpmfx.io.frames import read_arrays, write_arrays
from mpmfx.stages import colliders as collider_build
from mpmfx.stages.base import Context, StageError, quiet_warp

NAME, VERSION, PER_FRAME, FRAME_EXT = "simulate", 1, True, "npz"
KEEP_CHECKPOINTS = 2


def params(shot: Shot) -> dict:
    # frame_end is left out on purpose: a longer shot continues from the cached frames.
    mats, object_material = materials(shot)
    return {"domain": shot.domain.model_dump(mode="json"),
            "solver": shot.solver.model_dump(mode="json", exclude={"checkpoint_every"}),
            "materials": [m.__dict__ | {"mode": int(m.mode)} for m in mats],
            "object_material": object_material,
            "colliders": [c.model_dump(mode="json") for c in shot.colliders],
            "time": {"fps": shot.shot.fps, "frame_start": shot.shot.frame_start}}


def inputs(shot: Shot) -> dict[str, str]:
    return {"code": code_hash("mpmfx.mpm", __file__), **collider_build.inputs(shot)}


def materials(shot: Shot) -> tuple[list, list[int]]:
    """Distinct materials of the shot and, per object, its index into them."""
    from mpmfx.mpm.materials import preset
    mats, index = [], []
    for i, obj in enumerate(shot.objects):
        try:
            mat = preset(obj.material, **obj.overrides)
        except (ValueError, TypeError) as exc:
            raise ShotError(f"{shot.base_dir}: objects[{i}] ({obj.name}) material: {exc}") from None
        if mat not in mats:
            mats.append(mat)
        index.append(mats.index(mat))
    return mats, index


def solver_config(shot: Shot):
    from mpmfx.mpm import SolverConfig, WallType
    s, L = shot.solver, shot.domain.size
    walls = [s.walls] * 6 if isinstance(s.walls, str) else s.walls
    return SolverConfig(grid_n=shot.domain.grid_n, cfl=s.cfl, gravity=tuple(g / L for g in s.gravity),
                        damping=s.damping, drag=s.drag, time_scale=s.time_scale,
                        walls=tuple(WallType(w) for w in walls), wall_friction=s.wall_friction,
                        dt_max=s.dt_max, dt_min=s.dt_min, deterministic=s.deterministic,
                        multi_field=s.multi_field, contact_friction=s.contact_friction,
                        out_of_domain=s.out_of_domain)


def run(ctx: Context) -> dict:
    from mpmfx.mpm import Particles, SimulationError, Solver
    from mpmfx.stages import voxelise

    quiet_warp(ctx.device)
    shot, entry = ctx.shot, ctx.entry
    origin, size = np.asarray(shot.domain.origin), shot.domain.size
    mats, obj_mat = materials(shot)
    solver = Solver(mats, solver_config(shot), colliders=collider_build.build(shot), device=ctx.device)
    start, fps = shot.shot.frame_start, shot.shot.fps
    last = max(ctx.frames)
    ckpt = _latest_checkpoint(entry.root / "checkpoints", entry.done_frames(FRAME_EXT))
    if ckpt is None:
        p = voxelise.load(ctx.upstream["voxelise"])
        body = p["body"].astype(np.int32)
        parts = Particles(x=((p["x"] - origin) / size).astype(np.float32), v=(p["v"] / size).astype(np.float32),
                          volume=(p["volume"] / size**3).astype(np.float32),
                          material=np.asarray(obj_mat, np.int32)[body], body=body)
        state, frame = solver.init_state(parts), start
        _write_frame(ctx, solver, state, frame, origin, size)
    else:
        frame = ckpt
        state, _ = solver.restore(read_arrays(entry.root / "checkpoints" / f"{ckpt:04d}.npz"))
    for f in ctx.progress(range(frame + 1, last + 1), total=last - frame, desc="simulate"):
        try:
            report = solver.advance(state, (f - 1 - start) / fps, (f - start) / fps)
        except SimulationError as exc:
            raise StageError(f"frame {f}: {exc}") from None
        _write_frame(ctx, solver, state, f, origin, size)
        write_json(entry.root / "qa" / f"{f:04d}.json", _qa(report, size))
        if (f - start) % shot.solver.checkpoint_every == 0 or f == last:
            _checkpoint(entry.root / "checkpoints", solver, state, f, (f - start) / fps)
    qa = {int(p.stem): json.loads(p.read_text()) for p in sorted((entry.root / "qa").glob("*.json"))}
    n = solver.state_to_numpy(state)["x"].shape[0]
    return {"qa": qa, "particles": int(n), "device": str(solver.device),
            "materials": [m.mode.name for m in mats]}


def _write_frame(ctx, solver, state, frame: int, origin, size: float) -> None:
    s = solver.state_to_numpy(state)
    alive = s.get("alive", np.ones(len(s["x"]), bool)).astype(bool)
    out = {"x": (s["x"][alive] * size + origin).astype(np.float32),
           "v": (s["v"][alive] * size).astype(np.float32),
           "id": np.flatnonzero(alive).astype(np.int32),
           "material": s["material"][alive].astype(np.int32), "body": s["body"][alive].astype(np.int32)}
    for k in ("Jp", "J"):
        if k in s:
            out[k] = s[k][alive].astype(np.float32)
    if not all(np.isfinite(a).all() for a in out.values()):
        raise StageError(f"frame {frame}: the solver returned non-finite values; nothing was cached. "
                         f"Lower solver.cfl or the stiffest material's youngs_modulus / bulk_modulus")
    write_arrays(ctx.entry.frame_path(frame, FRAME_EXT), out)


def _qa(report, size: float) -> dict:
    """The frame's observables (issue 5), JSON-safe: max_speed in m/s; mass, momentum and
    energies in the solver's domain units (the presets' units), comparable frame to frame."""
    d = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in vars(report).items()}
    if "max_speed" in d:
        d["max_speed"] = float(d["max_speed"]) * size
    return d


def _checkpoint(folder: Path, solver, state, frame: int, t: float) -> None:
    write_arrays(folder / f"{frame:04d}.npz", solver.checkpoint(state, t))
    for old in sorted(folder.glob("[0-9]*.npz"))[:-KEEP_CHECKPOINTS]:
        old.unlink()


def _latest_checkpoint(folder: Path, done: list[int]) -> int | None:
    """The newest checkpoint whose frame file also exists (a frame is written before its checkpoint)."""
    if not folder.is_dir():
        return None
    frames = sorted(int(p.stem) for p in folder.glob("[0-9]*.npz"))
    ok = [f for f in frames if f in set(done)]
    return ok[-1] if ok else None


def load_frame(entry, frame: int) -> dict[str, np.ndarray]:
    return read_arrays(entry.frame_path(frame, FRAME_EXT))
