"""Where artists and DCC scenes look: stable paths per shot, updated by every run.

- `renders/<shot>/`: the render entry's PNG frames, movie, contact sheet and .blend, copied, with
  `published.json` naming the variant (its --set overrides and cache entry). Replaced whole,
  so no frame of another variant stays behind.
- `published/<shot>`: a symlink to the export entry, so `published/<shot>/shot.usda` (and
  its frames/ and vdb/, reached through the link) is always the last run's stage and a DCC
  scene never needs re-pointing. Switched with one rename, so a reader sees the old stage or
  the new one. `mpmfx cache prune` never deletes an entry a link points at.

Both run after every `mpmfx run` that reaches the stage, cached or not (a run of the plain
shot after a variant publishes the plain shot again). A folder of `renders/` that mpmfx did not
publish (no `published.json`), or one a command of its own writes (`RESERVED`), is never
replaced: such a shot name is refused before anything runs. A wedge's `wedge-*` folders move
with each publish. Leftovers of a killed publish are swept by the next run under the shot's
lock. Each publish is recorded in the cache (`<cache>/<shot>/published_to.json`), so `cache prune`
keeps what is published wherever it was run from.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path

from mpmfx.cache import PathError, child, write_json
from mpmfx.diskspace import ensure_room, named

RENDERS = Path("renders")
PUBLISHED = Path("published")
MARKER = "published.json"  # in every renders/<shot>/ that mpmfx published; nothing else is replaced
RESERVED = ("bench", "check")  # renders/ folders of `mpmfx bench` and `mpmfx check`
RECORD = "published_to.json"  # <cache>/<shot>/published_to.json: where this shot was published


def check_publishable(name: str, *, renders: Path = RENDERS, published: Path = PUBLISHED) -> None:
    """Refuse (PathError, exit 2) a shot whose publish would replace what mpmfx did not make."""
    if name in RESERVED:
        raise PathError(f"shot.name {name!r}: renders/{name}/ belongs to `mpmfx {name}`; choose another name")
    out = child(renders, name)
    if out.is_symlink() or (out.exists() and not _ours(out)):
        raise PathError(
            f"shot.name {name!r}: {out} exists and was not published by mpmfx (no {MARKER}), so a run "
            f"would replace it; choose another shot name, or move that folder away"
        )
    link = child(published, name)
    if link.exists() and not link.is_symlink():
        raise PathError(
            f"shot.name {name!r}: {link} exists and is not the link mpmfx publishes; choose another "
            f"shot name, or move it away"
        )


def _ours(out: Path) -> bool:
    """A renders/<shot>/ that mpmfx made: published (its MARKER), or holding only wedges."""
    if (out / MARKER).is_file():
        return True
    return out.is_dir() and all(p.is_dir() and p.name.startswith("wedge-") for p in out.iterdir())


def sweep(name: str, *, renders: Path = RENDERS, published: Path = PUBLISHED) -> None:
    """Remove what a killed publish of shot `name` left (call under the shot's lock): a
    renders/<shot> renamed away and not replaced comes back, partial copies and old folders go."""
    out = child(renders, name)
    olds = sorted(renders.glob(f".{name}.*.old"), key=lambda p: p.stat().st_mtime) if renders.is_dir() else []
    if olds and not out.exists() and not out.is_symlink() and (olds[-1] / MARKER).is_file():
        os.replace(olds.pop(), out)
    for p in olds + (sorted(renders.glob(f".{name}.*.tmp")) if renders.is_dir() else []):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
    if published.is_dir():
        for p in published.glob(f".{name}.*.tmp"):
            if p.is_symlink():
                p.unlink()


def publish_renders(shot, entry, *, root: Path = RENDERS) -> Path:
    """Replace `renders/<shot>/` with the render entry's frames, movie and contact sheet."""
    out = child(root, shot.shot.name)
    tmp = out.with_name(f".{out.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    extras = (entry.root / f"{shot.shot.name}.mp4", entry.root / "contact.png", entry.root / f"{shot.shot.name}.blend")
    files = sorted(entry.frames_dir.glob("[0-9]*.png")) + [p for p in extras if p.is_file()]
    # A full or unwritable renders/ is said as renders/<shot> (not the cache file copied) before
    # a byte is copied; a copy that still fails leaves renders/<shot> as it was.
    ensure_room(out, sum(p.stat().st_size for p in files))
    try:
        tmp.mkdir(parents=True)
        for p in files:
            shutil.copyfile(p, tmp / p.name)
        write_json(
            tmp / "published.json",
            {
                "shot": shot.shot.name,
                "overrides": list(shot.overrides),
                "render_entry": str(entry.root.resolve()),
                "files": [p.name for p in files],
            },
        )
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise named(exc, out) from exc
    if out.is_dir() and not out.is_symlink():
        for wedge in sorted(out.glob("wedge-*")):  # a wedge's sheets outlive the shot's next run
            os.replace(wedge, tmp / wedge.name)
    old = out.with_name(f".{out.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.old")
    if out.exists():
        os.replace(out, old)
    os.replace(tmp, out)
    shutil.rmtree(old, ignore_errors=True)
    return out


def publish_stage(shot, entry, *, root: Path = PUBLISHED) -> Path:
    """Point `published/<shot>` at the export entry (one atomic rename); returns the stage path."""
    link = child(root, shot.shot.name)
    link.parent.mkdir(parents=True, exist_ok=True)
    if link.exists() and not link.is_symlink():
        raise PathError(f"{link} exists and is not the link mpmfx publishes: move it away, or choose another shot name")
    tmp = link.with_name(f".{link.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        os.symlink(os.path.relpath(entry.root.resolve(), link.parent.resolve()), tmp)
        os.replace(tmp, link)
    except OSError as exc:  # a full or read-only published/: said as published/<shot>
        tmp.unlink(missing_ok=True)
        raise named(exc, link) from exc
    return link / "shot.usda"


def record(shot_dir: Path, published: dict[str, Path]) -> None:
    """Note in the cache where shot outputs were published (absolute paths, every place a run
    published from), so prune finds them from any working directory."""
    path = shot_dir / RECORD
    places = _recorded(path)
    for p in published.values():
        place = str(Path(os.path.abspath(p.parent if p.name == "shot.usda" else p)))
        if place not in places:
            places.append(place)
    write_json(path, {"published": places})


def drop_dangling(shot_dir: Path) -> list[Path]:
    """Remove the recorded `published/<shot>` links whose export entry is gone (after a clean)."""
    gone = [p for p in map(Path, _recorded(shot_dir / RECORD)) if p.is_symlink() and not p.exists()]
    for p in gone:
        p.unlink()
    return gone


def _recorded(path: Path) -> list[str]:
    try:
        places = json.loads(path.read_text())["published"]
        return [p for p in places if isinstance(p, str)]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def published_entries(cache_root: Path, roots: tuple[Path, ...] = (PUBLISHED, RENDERS)) -> set[Path]:
    """Cache entries that a published output uses (resolved paths), for prune to keep: the
    places each shot of `cache_root` recorded, and those under `roots` (the working directory)."""
    links = [p for p in roots[0].iterdir() if p.is_symlink()] if roots[0].is_dir() else []
    folders = list(roots[1].glob(f"*/{MARKER}")) if roots[1].is_dir() else []
    for rec in cache_root.glob(f"*/{RECORD}") if cache_root.is_dir() else []:
        for place in map(Path, _recorded(rec)):
            if place.is_symlink():
                links.append(place)
            elif (place / MARKER).is_file():
                folders.append(place / MARKER)
    used = {p.resolve() for p in links}
    for meta in folders:
        try:
            used.add(Path(json.loads(meta.read_text())["render_entry"]).resolve())
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return used
