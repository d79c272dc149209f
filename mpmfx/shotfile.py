"""Loading a shot file: the TOML read, `--set` overrides applied, the schema validated
(mpmfx.config) and the checks that need the whole shot; every error names the file, the key and
the fix (`ShotError`, exit 2)."""

from __future__ import annotations

import difflib
import tomllib
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from mpmfx.config import ColliderShape, Shot, ShotError, Variation
from mpmfx.mpm.config import SolverConfigError
from mpmfx.mpm.materials import PRESETS, VARIED_BY_MODE


def parse_override(text: str) -> tuple[list[str], Any]:
    """`solver.cfl=0.3` -> (["solver", "cfl"], 0.3). Values are TOML (strings may be bare)."""
    if "=" not in text:
        raise ShotError(f"--set {text!r}: expected key=value, e.g. --set solver.cfl=0.3")
    key, raw = text.split("=", 1)
    if "[" in key or "]" in key:
        dotted = key.replace("[", ".").replace("]", "").strip()
        raise ShotError(f"--set {text!r}: list items are numbered with dots: --set {dotted}={raw}")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # bare string, e.g. --set objects.0.material=Water
    return key.strip().split("."), value


def apply_override(data: dict, path: list[str], value: Any, *, source: str) -> None:
    node: Any = data
    for i, part in enumerate(path[:-1]):
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ShotError(
                    f"{source}: --set {'.'.join(path)}: '{part}' is not an index of "
                    f"[{'.'.join(path[:i])}] (0..{len(node) - 1})"
                )
            node = node[int(part)]
        elif isinstance(node, dict):
            node = node.setdefault(part, {})
        if not isinstance(node, (dict, list)):
            have = ".".join(path[: i + 1])
            raise ShotError(
                f"{source}: --set {'.'.join(path)}: {have} is a single value ({node!r}), not a table; "
                f"--set {have}=VALUE"
            )
    last = path[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            raise ShotError(f"{source}: --set {'.'.join(path)}: bad list index '{last}'")
        node[int(last)] = value
    else:
        node[last] = value


def _loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _model_at(loc: tuple) -> type[BaseModel] | None:
    model: Any = Shot
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(part) if model else None
        if field is None:
            return None
        ann = field.annotation
        args = getattr(ann, "__args__", ())
        model = next((a for a in (ann, *args) if isinstance(a, type) and issubclass(a, BaseModel)), None)
    return model


_UNION_TAGS = {"float", "bool", "int", "str", "list", "tuple"}
_TYPE_ERRORS = {"float_type", "int_type", "bool_type", "float_parsing", "int_parsing", "bool_parsing"}


def _format_error(err: dict, source: str) -> str:
    # a union's members add their tag to the location (overrides.x.float): the key is without it
    loc = tuple(p for p in err["loc"] if not (isinstance(p, str) and (p in _UNION_TAGS or "[" in p)))
    key = _loc(loc) or "(the file)"
    if err["type"] == "extra_forbidden" and loc:
        model = _model_at(loc)
        # keys a shot file may hold: not the internal ones the loader fills in (exclude=True)
        known = [k for k, f in model.model_fields.items() if not f.exclude] if model else []
        close = difflib.get_close_matches(str(loc[-1]), known, n=1)
        hint = f"did you mean '{close[0]}'?" if close else f"known keys: {', '.join(known)}"
        return f"{source}: unknown key '{key}': {hint}"
    if err["type"] == "missing":
        return f"{source}: missing key '{key}': add it (see pipeline/shots/*.toml for examples)"
    model = _model_at(loc) if loc else None
    field = model.model_fields.get(str(loc[-1])) if model else None
    doc = f" ({field.description})" if field is not None and field.description else ""
    hint = ""
    if err["type"] in _TYPE_ERRORS and isinstance(err.get("input"), str):
        hint = "; write numbers and true/false without quotes"
    return f"{source}: '{key}' = {err.get('input')!r}: {err['msg']}{hint}{doc}"


def _either(errs: list[dict]) -> str:
    """One message for a key's errors, one per union member: "Input should be 'auto' or a valid
    boolean" (the first alone when they do not all say what the input should be)."""
    msgs = list(dict.fromkeys(e["msg"] for e in errs))
    head = "Input should be "
    if len(msgs) > 1 and all(m.startswith(head) for m in msgs):
        return head + " or ".join(m[len(head) :] for m in msgs)
    return msgs[0]


def load_shot_config(path: str | Path, overrides: list[str] = ()) -> Shot:
    """Read, override and validate a shot file. Raises ShotError naming file, key and fix."""
    path = Path(path)
    if not path.is_file():
        raise ShotError(
            f"{path}: shot file not found (run from the project root, e.g. mpmfx run pipeline/shots/jelly_splash.toml)"
        )
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ShotError(f"{path}: not valid TOML: {exc}") from None
    for text in overrides:
        key, value = parse_override(text)
        apply_override(data, key, value, source=str(path))
    try:
        shot = Shot.model_validate(
            {**data, "base_dir": path.resolve().parent, "source": path, "overrides": tuple(overrides)}
        )
    except ValidationError as exc:
        by_key: dict[str, list[dict]] = {}
        for e in exc.errors():  # a union ("auto" | bool) reports each member: one line per key says all
            by_key.setdefault(_format_error(e, str(path)).split("' = ")[0], []).append(e)
        raise ShotError(
            "\n".join(_format_error({**errs[0], "msg": _either(errs)}, str(path)) for errs in by_key.values())
        ) from None
    _check_semantics(shot, str(path))
    return shot


MAX_GRAVITY = 1000.0  # m/s^2: 100 g, far past any stylised shot, far below a typo's 1e30


def _too_fast(shot: Shot, source: str, dx: float) -> list[str]:
    """Initial velocities no time step can follow: the CFL step at that speed alone (cfl * dx /
    |v|; the material's sound speed only shortens it) under solver.dt_min."""
    fastest = shot.solver.cfl * dx / shot.solver.dt_min  # m/s
    out = []
    for what, items in (("objects", shot.objects), ("emitters", shot.emitters)):
        for i, item in enumerate(items):
            speed = sum(v * v for v in item.velocity) ** 0.5
            if speed > fastest:
                out.append(
                    f"{source}: {what}[{i}].velocity = {list(item.velocity)}: {speed:.3g} m/s, faster than "
                    f"any substep can follow (a cell of {dx:.3g} m at solver.cfl = {shot.solver.cfl:g} needs "
                    f"{shot.solver.cfl * dx / speed:.2g} s, under solver.dt_min = {shot.solver.dt_min:g} s); "
                    f"give at most {fastest:.3g} m/s"
                )
    return out


def _check_semantics(shot: Shot, source: str) -> None:
    """Checks that need more than one field: frame order, file existence, time step bounds."""
    problems = []
    if sum(g * g for g in shot.solver.gravity) > MAX_GRAVITY**2:
        problems.append(
            f"{source}: solver.gravity = {list(shot.solver.gravity)}: over {MAX_GRAVITY:g} m/s^2 (100 g) in size, "
            f"no step can follow it; Earth's is [0, -9.81, 0]"
        )
    dx = shot.domain.size / shot.domain.grid_n
    problems += _too_fast(shot, source, dx)
    if shot.surface.voxel_size is not None and shot.surface.voxel_size > dx:
        problems.append(
            f"{source}: surface.voxel_size = {shot.surface.voxel_size:g} m: over one simulation cell "
            f"({dx:.3g} m), a level set cannot follow the particles (the surface comes out empty or "
            f"blocky); leave it unset (half the particle spacing) or give at most {dx:.3g}"
        )
    if shot.shot.frame_end <= shot.shot.frame_start:
        problems.append(
            f"{source}: shot.frame_end ({shot.shot.frame_end}) must be after shot.frame_start ({shot.shot.frame_start})"
        )
    try:
        shot.solver_config()
    except SolverConfigError as exc:
        key = "domain.grid_n" if exc.field == "grid_n" else f"solver.{exc.field}"
        problems.append(f"{source}: {key}: {exc.what}")
    else:
        if shot.solver.dt_max * shot.shot.fps * 0.999 > 1.0 / shot.solver.time_scale:
            problems.append(
                f"{source}: solver.dt_max ({shot.solver.dt_max} s) is longer than one frame "
                f"(1/{shot.shot.fps} s): lower solver.dt_max"
            )
    if shot.surface.sharp_edges is True and shot.surface.smooth_iters == 0:
        problems.append(
            f"{source}: surface.sharp_edges: needs surface.smooth_iters > 0 (the edges are found while "
            f"smoothing): raise surface.smooth_iters or set surface.sharp_edges = false"
        )
    names = [o.name for o in shot.bodies] + [c.name for c in shot.colliders]
    for dup in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"{source}: name '{dup}' is used twice in objects/emitters/colliders: names must be unique")
    if not shot.bodies:
        problems.append(f"{source}: missing key 'objects': a shot needs [[objects]] or [[emitters]]")
    problems += _check_emitters(shot, source)
    for i, obj in enumerate(shot.objects):
        if not shot.resolve(obj.mesh).is_file():
            problems.append(
                f"{source}: objects[{i}].mesh: file not found: {shot.resolve(obj.mesh)} "
                f"(paths are relative to the shot file)"
            )
    problems += _variation_problems(shot, source)
    for i, col in enumerate(shot.colliders):
        if col.shape is ColliderShape.MESH:
            if col.mesh is None:
                problems.append(f'{source}: colliders[{i}].mesh: a shape = "mesh" collider needs mesh = "file"')
            elif not shot.resolve(col.mesh).is_file():
                problems.append(f"{source}: colliders[{i}].mesh: file not found: {shot.resolve(col.mesh)}")
            elif col.animated and col.mesh.suffix.lower() not in (".usd", ".usda", ".usdc", ".usdz", ".blend", ".fbx"):
                problems.append(
                    f"{source}: colliders[{i}].animated: {col.mesh} is not USD, .blend or .fbx; export the "
                    "animation as USD (time-sampled points or transforms)"
                )
        elif col.animated:
            problems.append(f'{source}: colliders[{i}].animated: only a shape = "mesh" collider is animated')
        times = [k.time for k in col.keyframes]
        if times != sorted(times) or len(set(times)) != len(times):
            problems.append(f"{source}: colliders[{i}].keyframes: times must be strictly increasing")
    if problems:
        raise ShotError("\n".join(problems))


def _check_emitters(shot: Shot, source: str) -> list[str]:
    """Emitter times and files, and the particle budget of what they emit (before any work)."""
    problems, total, vp = [], 0, (shot.domain.size / shot.domain.grid_n) ** 3 / shot.voxelise.ppc  # m^3, as voxelise
    for i, e in enumerate(shot.emitters):
        if e.end_time <= e.start_time:
            problems.append(f"{source}: emitters[{i}].end_time ({e.end_time}) must be after its start_time")
        if e.shape == "mesh" and (e.mesh is None or not shot.resolve(e.mesh).is_file()):
            problems.append(f'{source}: emitters[{i}].mesh: shape = "mesh" needs an existing mesh file (got {e.mesh})')
        total += round(e.rate * max(0.0, e.end_time - e.start_time) / vp)
    if total > shot.solver.max_particles:
        problems.append(
            f"{source}: emitters[].rate: the emitters emit {total:,} particles, over solver.max_particles "
            f"({shot.solver.max_particles:,}): lower the rates or the emission times, or raise solver.max_particles"
        )
    return problems


def _variation_problems(shot: Shot, source: str) -> list[str]:
    """A variation of a field the object's material has no use for (water; a snow's friction)."""
    by_name, out = {k.lower(): m for k, m in PRESETS.items()}, []
    for i, obj in enumerate(shot.objects):
        var, preset = obj.variation, by_name.get(obj.material.lower())
        if var is None or preset is None:  # (an unknown preset is reported where materials are made)
            continue
        allowed, mode = VARIED_BY_MODE.get(preset.mode, ()), preset.mode.name.lower()
        if not allowed:
            out.append(f"{source}: objects[{i}].variation: {obj.material} is {mode}; only snow and sand vary")
            continue
        for name in set(Variation.model_fields) - {"feature_size", "seed", *allowed}:
            if getattr(var, name) > 0:
                out.append(
                    f"{source}: objects[{i}].variation.{name}: {obj.material} is {mode}, which has no {name}; "
                    f"vary {', '.join(allowed)}"
                )
    return sorted(out)
