"""Stage 2: MLS-MPM from the voxelised particles, one particle file per frame, resumable.

World units stop here: particles enter the solver in the normalised domain [0,1]^3
(x_dom = (x - origin) / size, v_dom = v / size, gravity_dom = g / size; docs/physics.md) and
frames are written back in world units. Frames: `frames/NNNN.npz` with x, v (n,3) float32
(m, m/s), id, material, body (n,) int32 and Jp, J (n,) float32; `checkpoints/NNNN.npz` hold the
full solver state every `solver.checkpoint_every` frames (default every frame; the last
KEEP_CHECKPOINTS are kept), written just before the frame file, so a killed run resumes
exactly from its last complete frame. The files are written on a background thread while the
next frame simulates (`FrameWriter`).
Frame files are `mpmfx.io.frames.ParticleFrame` records.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from mpmfx import checksum
from mpmfx.cache import DamagedError, file_hash, write_json
from mpmfx.config import ColliderShape, Shot, ShotError
from mpmfx.geometry import MESH_LOADING
from mpmfx.geometry.colliders import keyframes, mesh_sdf
from mpmfx.geometry.noise import fourier_noise
from mpmfx.io.frames import ParticleFrame, SeedParticles, read_arrays, write_arrays
from mpmfx.mpm import AnimatedMesh, Collider, ColliderKind, Particles, SimulationError, Solver
from mpmfx.mpm.emission import device_bytes
from mpmfx.mpm.materials import VARIED_FIELDS, preset
from mpmfx.mpm.modules import solver_modules
from mpmfx.mpm.readback import HostStaging
from mpmfx.stages.base import Context, StageError, device_turn, quiet_warp
from mpmfx.stages.colliders import animated_collider, collider_geometry, collider_key, static_collider_mesh
from mpmfx.stages.writer import FrameWriter

NAME, VERSION, PER_FRAME, FRAME_EXT = "simulate", 1, True, ParticleFrame.EXT
CODE = (
    "mpmfx.stages.simulate",
    "mpmfx.mpm",
    "mpmfx.stages.colliders",
    "mpmfx.geometry.colliders",
    "mpmfx.geometry.animated",
    "mpmfx.geometry.noise",
    *MESH_LOADING,
    "mpmfx.geometry.voxelise",
    "mpmfx.geometry.inside",
    "mpmfx.io.frames",
)
KEEP_CHECKPOINTS = 2


def params(shot: Shot) -> dict:
    # frame_end is left out on purpose: a longer shot continues from the cached frames.
    # The solver's resolved config, not the [solver] section: a changed default re-runs simulate.
    mats, object_material = materials(shot)
    cfg = {
        k: [w.value for w in v] if k == "walls" else getattr(v, "value", v)
        for k, v in vars(shot.solver_config()).items()
    }
    return {
        "domain": shot.domain.model_dump(mode="json"),
        "solver": cfg,
        "materials": [m.__dict__ | {"mode": int(m.mode)} for m in mats],
        "object_material": object_material,
        "colliders": [collider_key(c) for c in shot.colliders],
        "time": {"fps": shot.shot.fps, "frame_start": shot.shot.frame_start},
        # (only where an object has one: a shot without variation keeps its key's inputs)
        **({"variation": [o.variation and o.variation.model_dump() for o in shot.bodies]} if _varied(shot) else {}),
    }


def _varied(shot: Shot) -> bool:
    return any(o.variation is not None for o in shot.bodies)


STREAM_SPEED = 1.0  # m/s: the stream an emitter without a velocity is taken to pour down at


def variation(shot: Shot, x: np.ndarray, body: np.ndarray, birth: np.ndarray | None = None) -> np.ndarray:
    """(n, 5) float32 multipliers of VARIED_FIELDS at rest positions x (n, 3), m, of the
    particles of bodies `body` (n,; objects, then emitters): exp(amplitude * noise), one seeded
    noise per body and field (mpmfx.geometry.noise); 1 for bodies without variation. An emitter's
    particles, born at birth (n,) s at its source, sample the noise at their stream position x -
    velocity * birth (STREAM_SPEED down with no velocity): successive puffs differ and a steady
    pour varies smoothly along its length."""
    out = np.ones((len(x), len(VARIED_FIELDS)), np.float32)
    for b, obj in enumerate(shot.bodies):
        var, rows = obj.variation, body == b
        if var is None or not rows.any():
            continue
        at = x[rows]
        if b >= len(shot.objects) and birth is not None:
            v = np.asarray(obj.velocity, np.float64)
            v = v if np.any(v) else np.array([0.0, -STREAM_SPEED, 0.0])
            at = at - v * birth[rows, None]
        for j, name in enumerate(VARIED_FIELDS):
            if getattr(var, name) > 0:
                out[rows, j] = np.exp(getattr(var, name) * fourier_noise(at, var.feature_size, (var.seed, j)))
    return out


def inputs(shot: Shot) -> dict[str, str]:
    return {
        f"collider:{c.name}": file_hash(shot.resolve(c.mesh))
        for c in shot.colliders
        if c.shape is ColliderShape.MESH and c.mesh is not None
    }


def materials(shot: Shot) -> tuple[list, list[int]]:
    """Distinct materials of the shot and, per body (objects, then emitters), its index into them."""
    mats, index = [], []
    for i, obj in enumerate(shot.bodies):
        try:
            mat = preset(obj.material, **obj.overrides)
        except (ValueError, TypeError) as exc:
            where = f"objects[{i}]" if i < len(shot.objects) else f"emitters[{i - len(shot.objects)}]"
            raise ShotError(
                f"{shot.source or shot.base_dir}: {where} ({obj.name}) material / overrides: {exc}"
            ) from None
        if mat not in mats:
            mats.append(mat)
        index.append(mats.index(mat))
    return mats, index


def colliders(shot: Shot) -> list:
    """The shot's colliders as `mpmfx.mpm.Collider`s in domain units (positions / domain.size,
    about domain.origin); keyframe times stay on the shot clock, as the solver expects."""
    origin, L = np.asarray(shot.domain.origin, float), shot.domain.size
    out = []
    for i, col in enumerate(shot.colliders):
        if col.animated:
            continue  # animated_meshes
        geom = collider_geometry(col)
        t, tr, rot = keyframes(geom)
        common = dict(
            friction=col.friction,
            times=t,
            translations=((tr - origin) / L).astype(np.float32),
            rotations=rot.astype(np.float32),
        )
        if col.shape is ColliderShape.PLANE:
            out.append(Collider(kind=ColliderKind.PLANE, normal=tuple(col.normal), **common))
        elif col.shape is ColliderShape.BOX:
            out.append(Collider(kind=ColliderKind.BOX, half_extents=tuple(h / L for h in col.half_extents), **common))
        elif col.shape is ColliderShape.SPHERE:
            out.append(Collider(kind=ColliderKind.SPHERE, radius=col.radius / L, **common))
        else:
            mesh = static_collider_mesh(shot, i)
            sdf, sdf_origin, voxel = mesh_sdf(mesh, dx=L / shot.domain.grid_n)
            out.append(
                Collider(
                    kind=ColliderKind.SDF,
                    sdf=(sdf / L).astype(np.float32),
                    sdf_origin=tuple(sdf_origin / L),
                    sdf_voxel=voxel / L,
                    **common,
                )
            )
    return out


def kernel_modules(shot: Shot, device: str | None) -> list:
    """(warp.Module, block_dim) of each Warp module this stage's solver will launch on `device`
    (mpmfx.mpm.modules), known before anything is voxelised: for compiling them ahead."""
    return solver_modules(
        materials(shot)[0],
        shot.solver_config(),
        device=device,
        colliders=any(not c.animated for c in shot.colliders),
        animated=any(c.animated for c in shot.colliders),
        emission=bool(shot.emitters) or any(o.start_time > 0 for o in shot.objects),
        variation=_varied(shot),
    )


def animated_meshes(shot: Shot) -> list:
    """The shot's animated colliders as `mpmfx.mpm.AnimatedMesh`es in domain units, sampled
    at every shot frame (times on the shot clock)."""
    origin, L = np.asarray(shot.domain.origin, float), shot.domain.size
    out = []
    for i, col in enumerate(shot.colliders):
        if col.animated:
            times, pts, faces = animated_collider(shot, i)
            out.append(AnimatedMesh(times, ((pts - origin) / L).astype(np.float32), faces, friction=col.friction))
    return out


def run(ctx: Context) -> dict:
    quiet_warp(ctx.device)
    shot, entry = ctx.shot, ctx.entry
    origin, size = np.asarray(shot.domain.origin), shot.domain.size
    mats, obj_mat = materials(shot)
    with FrameWriter() as writer:
        with device_turn(ctx.device):  # the set-up and the first frame (see device_turn)
            solver = Solver(
                mats,
                shot.solver_config(),
                colliders=colliders(shot),
                animated=animated_meshes(shot),
                device=ctx.device,
                variation=_varied(shot),
            )
            start, fps = shot.shot.frame_start, shot.shot.fps
            last = max(ctx.frames)
            ckpt, restored = _restore(ctx, solver)
            staging = HostStaging(solver.device)  # two sets of host buffers: the frame written, the frame made
            if ckpt is None:
                vox = ctx.upstream["voxelise"]
                p = vox.read(vox.root / SeedParticles.FILE, lambda path: SeedParticles.read(path.parent))
                body = p.body.astype(np.int32)
                parts = Particles(
                    x=((p.x - origin) / size).astype(np.float32),
                    v=(p.v / size).astype(np.float32),
                    volume=(p.volume / size**3).astype(np.float32),
                    material=np.asarray(obj_mat, np.int32)[body],
                    body=body,
                    birth=None if p.birth is None else p.birth.astype(np.float32),
                    variation=variation(shot, p.x, body, p.birth) if _varied(shot) else None,
                )
                _budget(ctx, solver, p)
                state, frame = solver.init_state(parts), start
                qa0 = _qa(solver.advance(state, 0.0, 0.0), size)  # a zero-length advance: the initial observables
                qa0 |= _entered(solver, state)
                here = slice(None) if p.birth is None else p.birth <= 0  # (late ones are not there yet)
                qa0["max_speed"] = float(
                    np.linalg.norm(p.v[here], axis=1).max(initial=0.0)
                )  # m/s; no substep measured it
                consts = _consts(solver, state)  # material and body: the same every frame, copied once
                writer.submit(
                    _write_frame, entry, frame, qa0, None, _host(solver, state, consts, staging), origin, size
                )
            else:
                frame, state = ckpt, restored
                consts = _consts(solver, state)
                if not entry.frame_path(frame, FRAME_EXT).exists():  # killed between checkpoint and frame
                    writer.submit(
                        _write_frame, entry, frame, None, None, _host(solver, state, consts, staging), origin, size
                    )
        split = dict.fromkeys(("advance", "host_copy", "writer_wait"), 0.0)  # s, summed over the frames
        for f in ctx.progress(range(frame + 1, last + 1), total=last - frame, desc="simulate"):
            t0 = time.perf_counter()
            with device_turn(ctx.device):  # (the frames that follow simulate take theirs between)
                try:
                    report = solver.advance(state, (f - 1 - start) / fps, (f - start) / fps)
                except SimulationError as exc:
                    raise StageError(f"frame {f}: {_advice(shot, exc)}") from None
                t1 = time.perf_counter()
                ckpt_data = None
                if (f - start) % shot.solver.checkpoint_every == 0 or f == last:
                    ckpt_data = solver.checkpoint(state, (f - start) / fps, staging)
                # the frame's arrays are the checkpoint's where there is one (one copy off the device)
                host = _host(solver, state, consts, staging, ckpt_data)
                qa = _qa(report, size) | _entered(solver, state)
            t2 = time.perf_counter()
            writer.submit(_write_frame, entry, f, qa, ckpt_data, host, origin, size)
            for k, dt in zip(split, (t1 - t0, t2 - t1, time.perf_counter() - t2)):
                split[k] += dt
        t0 = time.perf_counter()
    split["writer_wait"] += time.perf_counter() - t0  # the last frame's files
    qa = {int(p.stem): json.loads(p.read_text()) for p in sorted((entry.root / "qa").glob("*.json"))}
    return {
        "qa": qa,
        "particles": int(state.n),
        "device": str(solver.device),
        "materials": [m.mode.name for m in mats],
        "seconds_split": {k: round(v, 3) for k, v in split.items()},
    }


def _budget(ctx: Context, solver, p: SeedParticles) -> None:
    """State the particle count (emitted ones included) and the device memory before the run,
    and stop (a ShotError: exit 2) when the count is over solver.max_particles."""
    shot, n = ctx.shot, len(p.x)
    late = 0 if p.birth is None else int(np.count_nonzero(p.birth > 0))
    det, births = shot.solver.deterministic, p.birth is not None
    b = device_bytes(n, solver.flags, shot.domain.grid_n, deterministic=det, births=births)
    mem = f"{b / 1e9:.1f} GB" if b >= 1e9 else f"{b / 1e6:.0f} MB"
    line = f"{n:,} particles ({n - late:,} at the start, {late:,} entering later); device memory ~{mem}"
    ctx.notes.append(line)
    if not ctx.quiet:
        print(f"[simulate] {line}", file=sys.stderr)
    if n > shot.solver.max_particles:
        raise ShotError(
            f"{shot.source or shot.base_dir}: solver.max_particles: the shot has {n:,} particles, over the budget "
            f"({shot.solver.max_particles:,}): lower the emitters' rates or domain.grid_n, or raise solver.max_particles"
        )


def _advice(shot: Shot, exc) -> str:
    """The solver's diagnosis with its advice in shot keys, each a `--set` that helps here
    (the solver's own text names SolverConfig fields, which a shot file cannot set)."""
    what = str(exc).split(". Lower", 1)[0].split(". Raise", 1)[0]
    stiff = " or ".join(f"objects[{i}].overrides.youngs_modulus" for i in range(len(shot.objects)))
    if exc.field == "dt_min" and getattr(exc, "speed_bound", False):
        moving = " or ".join(
            f"objects[{i}].{k}"
            for i, o in enumerate(shot.objects)
            for k in ("velocity", "angular_velocity")
            if k == "velocity" or any(o.angular_velocity)
        )
        return (
            f"{what}. The particles' own speed sets this step, not a stiffness: check {moving} "
            f"(m/s; the domain is {shot.domain.size:g} m across) and solver.gravity"
        )
    if exc.field == "dt_min":
        dt = float(f"{exc.needed / 10:.0e}")  # a decade of room: the step keeps shrinking as things speed up
        return (
            f"{what}. If this material is meant to be this stiff, --set solver.dt_min={dt:g} (not a "
            f"smaller solver.cfl: it would only shrink the step further); else soften it ({stiff}) or raise "
            f"solver.damping"
        )
    if exc.field == "max_substeps_per_frame":
        n = 2 * int(exc.needed)
        return (
            f"{what}. --set solver.max_substeps_per_frame={n} (about {int(exc.needed)} are needed), "
            f"or soften the stiffest material ({stiff}) or lower domain.grid_n"
        )
    return str(exc)


FRAME_ARRAYS = ("x", "v", "Jp", "alive")  # what a frame file is made of, besides J and the constants


def _consts(solver, state) -> dict:
    """material and body, host copies in particle order (which no substep changes)."""
    # (copies: on the CPU device numpy() views the solver's own memory)
    return {k: np.array(a) for k, a in solver.host_arrays(state, ("material", "body")).items()}


def _host(solver, state, consts: dict, staging: HostStaging, checkpoint: dict | None = None) -> dict:
    """The particles' host copy for the frame file (a checkpoint's arrays where there is one: one
    copy off the device), in `staging`'s buffers (the writer thread reads them while the next
    frame is made: FrameWriter(1) and two sets), with J, the volume ratio, computed on the
    device; the rest of its making (masks, checks) is the writer thread's."""
    if checkpoint:
        arrays = {k: checkpoint[k] for k in FRAME_ARRAYS}
    else:
        arrays = solver.host_arrays(state, FRAME_ARRAYS, staging)
    return {**arrays, **consts, "J": solver.volume_ratios(state)}


def _particles(s: dict, frame: int, origin, size: float) -> ParticleFrame:
    """The frame's particle record (world units) of the live particles of a host copy (_host)."""
    alive = s["alive"] != 0
    live = slice(None) if alive.all() else alive  # a slice views; a mask copies (~0.3 s at 2.6M)
    out = ParticleFrame(
        x=(s["x"][live] * size + origin).astype(np.float32),
        v=(s["v"][live] * size).astype(np.float32),
        id=np.flatnonzero(alive).astype(np.int32),
        material=s["material"][live].astype(np.int32, copy=False),
        body=s["body"][live].astype(np.int32, copy=False),
        **{k: s[k][live].astype(np.float32, copy=False) for k in ("Jp", "J") if k in s},
    )
    if not all(np.isfinite(a).all() for a in out.arrays().values()):
        raise StageError(
            f"frame {frame}: the solver returned non-finite values; nothing was cached. "
            f"Lower solver.cfl or the stiffest material's youngs_modulus / bulk_modulus"
        )
    return out


def _write_frame(entry, frame: int, qa: dict | None, checkpoint: dict | None, state: dict, origin, size: float) -> None:
    """One frame's files from its host copies, in the order resuming relies on: QA and
    checkpoint before the frame file (a complete frame always has its resume point), and
    none of them if the particles are not finite."""
    particles = _particles(state, frame, origin, size)
    if qa is not None:
        write_json(entry.root / "qa" / f"{frame:04d}.json", qa)
    if checkpoint is not None:
        folder = entry.root / "checkpoints"
        write_arrays(folder / f"{frame:04d}.npz", checkpoint)
        for old in sorted(folder.glob("[0-9]*.npz"))[:-KEEP_CHECKPOINTS]:
            old.unlink()
    particles.write(entry.frame_path(frame, FRAME_EXT))


def _qa(report, size: float) -> dict:
    """The frame's observables, JSON-safe: max_speed in m/s; mass, momentum and
    energies in the solver's domain units (the presets' units), comparable frame to frame."""
    d = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in vars(report).items()}
    if "max_speed" in d:
        d["max_speed"] = float(d["max_speed"]) * size
    return d


def _entered(solver, state) -> dict:
    """With particles entering during the shot, the QA's mass_entered: the mass (domain units) of
    those in it so far, what the mass should be (stages/qa.py); else nothing."""
    if state.birth is None:
        return {}
    mass = solver.host_arrays(state, ("mass",))["mass"]  # particle order, as the births
    return {"mass_entered": float(mass[np.isinf(state.birth.numpy())].sum(dtype=np.float64))}


def _restore(ctx: Context, solver) -> tuple[int | None, object]:
    """(frame, solver state) of the newest checkpoint to resume from that holds what was written,
    or (None, None): start from the voxelised particles. A damaged checkpoint (changed, cut short
    or unreadable) is deleted, said in one line, and an earlier one (or the start) is used."""
    entry, start = ctx.entry, ctx.shot.shot.frame_start
    candidates = _checkpoints(entry.root / "checkpoints", entry.done_frames(FRAME_EXT), start)
    for i, c in enumerate(candidates):
        path = entry.root / "checkpoints" / f"{c:04d}.npz"
        try:
            return c, solver.restore(entry.read(path, read_arrays))[0]
        except DamagedError as exc:
            checksum.forget(path)
            then = f"an earlier one (frame {candidates[i + 1]})" if i + 1 < len(candidates) else "the start"
            ctx.warn(f"checkpoint {path.name}: {exc.why}; deleted, resuming from {then}")
    return None, None


def _checkpoints(folder: Path, done: list[int], start: int) -> list[int]:
    """The checkpoints c to resume from, newest first: those with every frame file before them
    present (c's own frame may be missing: a checkpoint is written just before its frame, and
    resuming writes it; a frame lost later must be redone, so resume before it)."""
    have, f = set(done), start - 1
    if not folder.is_dir():
        return []
    while f + 1 in have:
        f += 1  # start..f: the unbroken run of frames from the first
    return sorted((c for c in (int(p.stem) for p in folder.glob("[0-9]*.npz")) if start < c <= f + 1), reverse=True)
