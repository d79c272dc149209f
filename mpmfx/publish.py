"""Where artists and DCC scenes look: stable paths per shot, updated by every run.

- `renders/<shot>/`: the render entry's PNG frames, movie, contact sheet and .blend, copied, with
  `published.json` naming the variant (its --set overrides and cache entry). Replaced whole,
  so no frame of another variant stays behind.
- `published/<shot>`: a symlink to the export entry, so `published/<shot>/shot.usda` (and
  its frames/ and vdb/, reached through the link) is always the last run's stage and a DCC
  scene never needs re-pointing. Switched with one rename, so a reader sees the old stage or
  the new one. `mpmfx cache prune` never deletes an entry a link points at.

Both run after every `mpmfx run` that reaches the stage, cached or not (a run of the plain
shot after a variant publishes the plain shot again).
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path

from mpmfx.cache import child, write_json

RENDERS = Path("renders")
PUBLISHED = Path("published")


def publish_renders(shot, entry, *, root: Path = RENDERS) -> Path:
    """Replace `renders/<shot>/` with the render entry's frames, movie and contact sheet."""
    out = child(root, shot.shot.name)
    tmp = out.with_name(f".{out.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    tmp.mkdir(parents=True)
    extras = (entry.root / f"{shot.shot.name}.mp4", entry.root / "contact.png", entry.root / f"{shot.shot.name}.blend")
    files = sorted(entry.frames_dir.glob("[0-9]*.png")) + [p for p in extras if p.is_file()]
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
        raise FileExistsError(f"{link} exists and is not a link mpmfx made: move it away")
    tmp = link.with_name(f".{link.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    os.symlink(os.path.relpath(entry.root.resolve(), link.parent.resolve()), tmp)
    os.replace(tmp, link)
    return link / "shot.usda"


def published_entries(roots: tuple[Path, ...] = (PUBLISHED, RENDERS)) -> set[Path]:
    """Cache entries that a published output uses (resolved paths), for prune to keep."""
    used = set()
    if roots[0].is_dir():
        used |= {p.resolve() for p in roots[0].iterdir() if p.is_symlink()}
    if roots[1].is_dir():
        for meta in roots[1].glob("*/published.json"):
            try:
                used.add(Path(json.loads(meta.read_text())["render_entry"]).resolve())
            except (OSError, ValueError, KeyError):
                continue
    return used
