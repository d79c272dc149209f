"""`mpmfx wedge`: side-by-side variants of one shot that differ in exactly one field.

One axis a round, side by side, as the tutorial "Material Point Method: Step by Step" advises
in "How to tune, as a process".

    mpmfx wedge SHOT --vary surface.smooth_iters=0,2,6
    mpmfx wedge SHOT --vary objects.bear.overrides.youngs_modulus=300:1200:3 --log --keep renders/jelly_splash
    mpmfx wedge SHOT --vary surface.smooth_iters=0,2,6 --pick 6     # writes a copy of SHOT with it

Each variant is the shot with one `--set` more, plus `solver.deterministic=true`; the scene seed
is the shot's own in every variant. The variants keep the shot's name, so they share its cache
and every stage entry the field does not touch (vary a surfacing field: one simulation, N
surfacings). Stages run in order over all variants at once: each distinct entry of a stage once
(a whole-shot stage as one task), and every frame of every variant of a per-frame stage as one
Dask task each (`mpmfx.stages.parallel`). Output, under `renders/<shot>/wedge-<field>/`: one sheet
per frame (`NNNN.png`, the tiles labelled field=value), `wedge.mp4`, `contact.png` (a row per
variant, four frames each) and `wedge.json`.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from mpmfx.cache import Cache, atomic_path, default_root
from mpmfx.cli_args import frame_range
from mpmfx.config import RenderEngine, ShotError
from mpmfx.render.frames import write_movie
from mpmfx.render.sheets import columns_for, evenly_spaced, read_tile
from mpmfx.render.sheets import grid as sheets_grid
from mpmfx.shotfile import apply_override, load_shot_config
from mpmfx.stages import STAGES
from mpmfx.stages.base import Context
from mpmfx.stages.parallel import Frames, task_key
from mpmfx.stages.render import framing_camera, shown_bounds
from mpmfx.stages.runner import ShotRun, stage_module

CONTACT_FRAMES = 4  # columns of contact.png


def _bad(message: str) -> Exception:
    """Bad input (exit 2)."""
    return ShotError(message)


# ---------------------------------------------------------------------------------------------
# Values and keys


def parse_vary(text: str, *, log: bool = False) -> tuple[str, list[Any]]:
    """`key=1,2,3` or `key=lo:hi:n` (`log`: geometric steps) -> (key, values)."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip() or not raw.strip():
        raise _bad(f"--vary {text!r}: expected KEY=V1,V2,... or KEY=LO:HI:N, e.g. --vary surface.smooth_iters=0,2,6")
    key, raw = key.strip(), raw.strip()
    span = raw.split(":")
    if len(span) == 3 and "," not in raw:
        try:
            lo, hi, n = float(span[0]), float(span[1]), int(span[2])
        except ValueError:
            raise _bad(f"--vary {text!r}: LO:HI:N needs two numbers and a count") from None
        if n < 2:
            raise _bad(f"--vary {text!r}: N must be at least 2")
        if log and (lo <= 0 or hi <= 0):
            raise _bad(f"--vary {text!r}: --log needs LO and HI above 0")
        if log:
            values = [lo * (hi / lo) ** (i / (n - 1)) for i in range(n)]
        else:
            values = [lo + (hi - lo) * i / (n - 1) for i in range(n)]
        values = [float(f"{v:.6g}") for v in values]
        if all(s.strip().lstrip("+-").isdigit() for s in span[:2]) and all(v == int(v) for v in values):
            values = [int(v) for v in values]
        return key, values
    if log:
        raise _bad(f"--vary {text!r}: --log goes with LO:HI:N, not a list of values")
    values = [_toml_value(part.strip()) for part in raw.split(",")]
    if len(values) < 2 or len(set(map(_same_as, values))) != len(values):
        raise _bad(f"--vary {text!r}: give two or more different values")
    return key, values


def _same_as(v: Any) -> tuple:
    """What makes two values one variant: 1 and 1.0 are one number, true is no number."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return ("number", float(v))
    return (type(v).__name__, repr(v))


def _toml_value(raw: str) -> Any:
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw  # a bare string, as --set takes it


def resolve_key(data: dict, key: str, *, source: str) -> str:
    """`objects.bear.overrides.x` -> `objects.0.overrides.x`: list items may be named by their
    `name`, as in the shot file; `--set` itself takes indexes."""
    node: Any = data
    out = []
    for part in key.split("."):
        if isinstance(node, list):
            names = [item.get("name") for item in node if isinstance(item, dict)]
            if not part.isdigit():
                if part not in names:
                    raise _bad(f"{source}: --vary {key}: no item named '{part}' (names: {', '.join(map(str, names))})")
                part = str(names.index(part))
            node = node[int(part)] if int(part) < len(node) else None
        elif isinstance(node, dict):
            node = node.get(part)
        else:
            node = None
        out.append(part)
    return ".".join(out)


def label(field: str, value: Any) -> str:
    return f"{field.split('.')[-1]}={value}"


# ---------------------------------------------------------------------------------------------
# Running


def variant_shots(path: str | Path, field: str, values: list[Any], overrides: list[str] = ()) -> list:
    """One validated shot per value: the shot, `overrides`, deterministic mode, field = value."""
    fixed = [*overrides, "solver.deterministic=true"]
    return [load_shot_config(path, [*fixed, f"{field}={_toml_text(v)}"]) for v in values]


def run_wedge(
    shots: list,
    *,
    cache_root: str | Path | None = None,
    executor=None,
    frames: list[int] | None = None,
    device: str | None = None,
    quiet: bool = False,
) -> list[dict[str, Any]]:
    """Run every variant to `render`, stage by stage over all variants; each distinct entry once.
    Returns, per variant, each stage's entry root. `executor`: `mpmfx.stages.parallel.Frames`."""
    if not shots:
        return []
    ex = executor or Frames(workers=1)
    root = Path(cache_root or default_root()).resolve()
    cache = Cache(root, shots[0].shot.name)
    # The variants share the shot's cache folder: this process holds its lock for them all
    # (their runs and tasks write under it and never take it themselves).
    with cache.lock():
        cache.remove_orphans()

        def bind(shots):
            return [
                ShotRun(s, cache_root=root, device=device, quiet=quiet, executor=ex, publish=False, locked=True)
                for s in shots
            ]

        runs = bind(shots)
        runs[0].check(frames=frames)
        entries = [r.entries() for r in runs]
        for name in STAGES:
            framed = one_camera(shots, entries, frames) if name == "render" and len(shots) > 1 else shots
            if framed is not shots:  # the render entries of the variants framed by one camera
                shots, runs = framed, bind(framed)
                entries = [r.entries() for r in runs]
            first: dict[str, int] = {}  # distinct entry key -> first variant that has it
            for i, e in enumerate(entries):
                first.setdefault(e[name].key, i)
            mod = stage_module(name)
            if hasattr(mod, "frame"):
                _frame_stage(mod, [runs[i] for i in first.values()], [entries[i] for i in first.values()], frames)
                continue
            todo = [i for i in first.values() if not entries[i][name].complete(runs[i]._wanted(name, frames))]
            in_tasks = ex.parallel(len(todo), auto_min=2)
            ex.calls(
                _run_stage,
                [(shots[i], root, name, frames, device, quiet or in_tasks) for i in todo],
                keys=[task_key(entries[i][name]) for i in todo],
                desc=name,
                quiet=quiet or not in_tasks,
            )
        return [{name: e[name].root for name in STAGES} for e in entries]


def one_camera(shots: list, entries: list[dict], frames: list[int] | None) -> list:
    """Cycles variants, each with the render camera that frames all of them (the union of what
    each shows over `frames`), so the tiles of a sheet share one view; a shot that sets its
    own camera, or the preview (a view of the domain), keeps it."""
    if any(s.render.engine is not RenderEngine.CYCLES or s.render.camera_position is not None for s in shots):
        return shots
    boxes = []
    for s, e in zip(shots, entries):
        wanted = frames or list(s.frames)
        boxes.append(shown_bounds(s, {n: e[n].root for n in ("simulate", "surface")}, wanted))
    boxes = [b for b in boxes if b is not None]
    if not boxes:
        return shots
    lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    return [framing_camera(s, lo, hi) for s in shots]


def _run_stage(shot, cache_root: Path, name: str, frames, device, quiet: bool):
    """One variant's whole-shot stage (voxelise, simulate), its upstream already cached: a task."""
    return ShotRun(shot, cache_root=cache_root, device=device, quiet=quiet, workers=1, publish=False, locked=True).run(
        until=name, frames=frames
    )[-1]


def _frame_stage(mod, runs: list, entries: list[dict], frames: list[int] | None) -> None:
    """Every frame of every variant of a per-frame stage as one batch of tasks; then each
    variant's finish (in the client) and its manifest."""
    ctxs = [(r, c) for r, e in zip(runs, entries) if isinstance(c := r.begin(mod.NAME, e, frames), Context)]
    if not ctxs:
        return
    calls, owner = [], []
    for k, (_, c) in enumerate(ctxs):
        job = c.job()
        for f in mod.todo(c):
            calls.append((job, f))
            owner.append(k)
    t0 = time.perf_counter()
    ex = runs[0].executor
    try:
        results = ex.map(mod.frame, calls, desc=mod.NAME, quiet=runs[0].quiet)
        for k, (r, c) in enumerate(ctxs):
            with r.failing(c):
                extra = mod.finish(c, [res for res, o in zip(results, owner) if o == k]) or {}
            r.end(c, extra, time.perf_counter() - t0)
    except BaseException:
        for r, c in ctxs:
            r.abandon(c)
        raise
    finally:
        getattr(mod, "close", lambda: None)()


# ---------------------------------------------------------------------------------------------
# Sheets


def write_sheets(
    out: Path, tiles: list[tuple[str, dict[int, Path]]], frames: list[int], *, fps: float, movie: bool = True
) -> dict[str, Path]:
    """Per frame, the tiles side by side (`mpmfx.render.sheets.columns_for`) with their labels;
    then a movie of the sheets and `contact.png` (a row per tile, CONTACT_FRAMES distinct
    frames each). Every sheet is 960 to 1920 px wide (`mpmfx.render.sheets.grid`)."""
    out.mkdir(parents=True, exist_ok=True)
    cols = columns_for(len(tiles))
    sheets = []
    for f in frames:
        sheet = sheets_grid([read_tile(paths.get(f)) for _, paths in tiles], cols, [text for text, _ in tiles])
        with atomic_path(out / f"{f:04d}.png") as tmp:
            _save(sheet, tmp)
        sheets.append(out / f"{f:04d}.png")
    result = {"sheets": out}
    if movie and len(sheets) > 1:
        result["movie"] = write_movie(sheets, out / "wedge.mp4", fps=fps)
    picks = evenly_spaced(frames, CONTACT_FRAMES)
    images = [read_tile(paths.get(f)) for _, paths in tiles for f in picks]
    labels = [f"{text}  frame {f}" if j == 0 else f"frame {f}" for text, _ in tiles for j, f in enumerate(picks)]
    with atomic_path(out / "contact.png") as tmp:
        _save(sheets_grid(images, len(picks), labels), tmp)
    result["contact"] = out / "contact.png"
    return result


def _save(image, path: Path) -> None:
    Image.fromarray(image).save(path, format="PNG")


def _keep_tile(keep: str, frames: list[int]) -> dict[int, Path]:
    """--keep: a folder of NNNN.png (a render or an earlier wedge variant) or one image for all."""
    p = Path(keep)
    if p.is_dir():
        found = {f: p / f"{f:04d}.png" for f in frames if (p / f"{f:04d}.png").is_file()}
        if not found:
            raise _bad(f"--keep {keep}: no frame images NNNN.png for frames {frames[0]}..{frames[-1]} there")
        return found
    if p.is_file():
        return dict.fromkeys(frames, p)
    raise _bad(f"--keep {keep}: no such folder or image")


# ---------------------------------------------------------------------------------------------
# --pick: a copy of the shot file with the chosen value


def pick(path: str | Path, field: str, value: Any, *, out: str | Path | None = None) -> Path:
    """Write a copy of the shot file with `field` = `value` (comments are not kept); relative
    mesh paths are rewritten for the copy's folder. The copy is validated; returns its path."""
    path = Path(path)
    data = tomllib.loads(path.read_text())
    apply_override(data, field.split("."), value, source=str(path))
    target = Path(out) if out else path.with_name(f"{path.stem}-{field.split('.')[-1]}-{_slug(value)}.toml")
    here, there = path.resolve().parent, target.resolve().parent
    for section in ("objects", "emitters", "colliders"):
        for item in data.get(section, []):
            if isinstance(item, dict) and isinstance(item.get("mesh"), str) and not Path(item["mesh"]).is_absolute():
                item["mesh"] = os.path.relpath(here / item["mesh"], there)
    header = f"# {path.name} with {field} = {_toml_text(value)} (picked with mpmfx wedge --pick)\n"
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(header + dump_toml(data))
    load_shot_config(target)
    return target


def _slug(value: Any) -> str:
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", str(value))


def _toml_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return (
            repr(value) if math.isfinite(value) else ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
        )
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_text(v)}" for k, v in value.items()) + "}"
    raise _bad(f"cannot write {value!r} to TOML")


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def dump_toml(data: dict) -> str:
    """A shot's data as TOML: top-level keys, tables, arrays of tables; deeper values inline."""
    lines = [f"{_toml_key(k)} = {_toml_text(v)}" for k, v in data.items() if not _is_table(v)]
    for k, v in data.items():
        if isinstance(v, dict):
            lines += ["", f"[{_toml_key(k)}]", *(f"{_toml_key(a)} = {_toml_text(b)}" for a, b in v.items())]
        elif _is_table(v):
            for item in v:
                lines += ["", f"[[{_toml_key(k)}]]", *(f"{_toml_key(a)} = {_toml_text(b)}" for a, b in item.items())]
    return "\n".join(lines).lstrip("\n") + "\n"


def _is_table(v: Any) -> bool:
    return isinstance(v, dict) or (isinstance(v, list) and bool(v) and all(isinstance(i, dict) for i in v))


# ---------------------------------------------------------------------------------------------
# The command


def main(args) -> int:
    key, values = parse_vary(args.vary, log=args.log) if args.pick is None else (args.vary.partition("=")[0], [])
    path = Path(args.shot)
    if not path.is_file():
        raise _bad(f"{path}: shot file not found")
    field = resolve_key(tomllib.loads(path.read_text()), key.strip(), source=str(path))
    if args.pick is not None:
        print(f"wrote {pick(path, field, _toml_value(args.pick), out=args.out)}")
        return 0
    shots = variant_shots(path, field, values, args.overrides)
    frames = _frames(args.frames, shots[0])
    labels = [label(key, v) for v in values]
    with Frames(workers=args.workers, scheduler=args.scheduler) as ex:
        t0 = time.perf_counter()
        roots = run_wedge(
            shots, cache_root=args.cache, executor=ex, frames=frames, device=args.device, quiet=args.quiet
        )
        seconds = time.perf_counter() - t0
    shot = shots[0]
    out = Path("renders") / shot.shot.name / f"wedge-{_slug(key)}"
    tiles = [(f"champion: {Path(args.keep).name}", _keep_tile(args.keep, frames))] if args.keep else []
    tiles += [(text, {f: r["render"] / "frames" / f"{f:04d}.png" for f in frames}) for text, r in zip(labels, roots)]
    made = write_sheets(out, tiles, frames, fps=shot.shot.fps, movie=shot.render.movie)
    (out / "wedge.json").write_text(
        json.dumps(
            {
                "shot": str(path),
                "field": field,
                "values": values,
                "overrides": args.overrides,
                "keep": args.keep,
                "frames": frames,
                "wall_s": round(seconds, 1),
                "variants": [{"value": v, **{k: str(p) for k, p in r.items()}} for v, r in zip(values, roots)],
            },
            indent=2,
            default=str,
        )
    )
    _report(key, values, roots)
    print(
        f"wedge: {len(values)} variants in {seconds:.1f} s -> {made['sheets']}/ (NNNN.png, "
        f"{'wedge.mp4, ' if 'movie' in made else ''}contact.png, wedge.json)"
    )
    return 0


def _frames(text: str | None, shot) -> list[int]:
    if not text:
        return list(shot.frames)
    try:
        frames = frame_range(text)
    except Exception as exc:  # argparse.ArgumentTypeError
        raise _bad(str(exc)) from None
    bad = sorted(set(frames) - set(shot.frames))
    if bad:
        raise _bad(f"--frames: {bad[0]} is outside the shot's frames {shot.shot.frame_start}..{shot.shot.frame_end}")
    return frames


def _report(key: str, values: list, roots: list[dict[str, Path]]) -> None:
    """Which entries the variants share: one row per stage, the number of distinct entries."""
    print(f"{key}: {', '.join(map(str, values))}", file=sys.stderr)
    for name in STAGES:
        n = len({r[name] for r in roots})
        print(f"  {name:<9} {n} entr{'y' if n == 1 else 'ies'}" + ("  (shared)" if n == 1 else ""), file=sys.stderr)
