"""`mpmfx clean` and `mpmfx cache prune`: delete cache entries, listing each with its size first.

Both act only on entry folders (`<root>/<shot>/<stage>/<stage>-<key>`), each checked to lie
inside the cache root; a simulation (minutes of work) is deleted only after a yes.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from mpmfx.cache import PathError, child, no_links, read_manifest
from mpmfx.stages import STAGES

ASK_BEFORE = ("simulate",)  # stages whose entries cost minutes: deleted only after a yes


def tree_size(path: Path) -> int:
    """Bytes in the files under `path` (0 if absent), links neither followed nor counted."""
    if path.is_symlink():
        return 0
    if path.is_file():
        return path.stat().st_size
    total = 0
    for folder, _dirs, files in os.walk(path):  # os.walk does not enter linked folders
        total += sum(os.lstat(os.path.join(folder, f)).st_size for f in files)
    return total


def check_targets(targets: list[Path], *, root: Path) -> None:
    """Every target must be an entry folder inside `root` reached through real folders (no
    link on the way, none as the entry): all are checked before anything is deleted, so a
    refusal deletes nothing (PathError, exit 2)."""
    bad = []
    for t in targets:
        try:
            child(root, *t.relative_to(root).parts, what="cache entry")
            no_links(t, root=root)
        except (PathError, ValueError) as exc:
            bad.append(str(exc))
    if bad:
        raise PathError("nothing deleted: " + "; ".join(bad))


def human(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    raise AssertionError


def variant(entry: Path) -> str:
    """Which variant an entry holds, from its manifest: its --set overrides, "plain shot" (none),
    or "partial" (no manifest yet)."""
    man = read_manifest(entry)
    if man is None:
        return "(partial: no manifest)"
    overrides = man.get("overrides")
    if not isinstance(overrides, list):
        return "(overrides not recorded)"
    return " ".join(f"--set {o}" for o in overrides) if overrides else "(plain shot)"


def clean_targets(run, *, stage: str | None, all_variants: bool) -> list[Path]:
    """This variant's entries (of `stage`, or of every stage), or every variant's with all_variants."""
    stages = [stage] if stage else list(STAGES)
    if all_variants:
        return [p for s in stages for p in run.cache.entries(s)]
    entries = run.entries()
    return [entries[s].root for s in stages if entries[s].root.exists()]


def delete(targets: list[Path], *, root: Path, dry_run: bool, yes: bool, verb: str = "delete") -> int:
    """List `targets` with sizes, ask before a simulation unless `yes`, delete. Exit code."""
    if not targets:
        print("nothing to delete")
        return 0
    check_targets(targets, root=root)
    sizes = [tree_size(t) for t in targets]
    for t, n in zip(targets, sizes):
        print(f"{'would ' + verb if dry_run else verb:>12}  {human(n):>9}  {os.path.relpath(t)}  {variant(t)}")
    print(f"{'':>12}  {human(sum(sizes)):>9}  in all")
    if dry_run:
        return 0
    costly = [t for t in targets if t.parent.name in ASK_BEFORE]
    if costly and not yes:
        if not sys.stdin.isatty():
            print(
                f"error: this deletes {len(costly)} simulation(s), which take minutes to redo; "
                f"run again with --yes to confirm (or --dry-run to only list)",
                file=sys.stderr,
            )
            return 2
        if input(f"delete {len(costly)} simulation(s)? [y/N] ").strip().lower() not in ("y", "yes"):
            print("nothing deleted")
            return 1
    for t in targets:
        shutil.rmtree(t)  # checked above; rmtree itself never follows a link inside the entry
    return 0


def prune_targets(root: Path, *, keep: int, in_use: set[Path]) -> list[Path]:
    """Per shot and stage, every entry but the `keep` newest (by manifest time, else folder time)
    and those `in_use` (resolved paths; with the entries they were made from, so re-running a
    published variant costs nothing)."""
    protected = set()
    todo = list(in_use)
    while todo:  # a used entry's upstream entries are used too
        entry = todo.pop()
        if entry in protected or not entry.is_dir():
            continue
        protected.add(entry)
        upstream = (read_manifest(entry) or {}).get("key_inputs", {}).get("upstream")
        if not isinstance(upstream, dict):
            continue
        for stage, key in upstream.items():
            todo.append((entry.parent.parent / stage / f"{stage}-{key[:12]}").resolve())
    out = []
    for stage_dir in sorted(p for p in root.glob("*/*") if p.is_dir() and p.name in STAGES):
        entries = sorted(stage_dir.glob(f"{stage_dir.name}-*"), key=_written, reverse=True)
        out += [e for e in entries[keep:] if e.resolve() not in protected]
    return out


def _written(entry: Path) -> float:
    man = entry / "manifest.json"
    return (man if man.exists() else entry).stat().st_mtime
