"""clean and cache prune delete only real entry folders inside the cache: a link anywhere on
the way is refused before anything is deleted."""

from __future__ import annotations

import os

import pytest

from mpmfx.cache import PathError
from mpmfx.maintain import delete, prune_targets, tree_size


def _entry(root, shot, stage, key, size=10):
    e = root / shot / stage / f"{stage}-{key}"
    (e / "frames").mkdir(parents=True)
    (e / "frames" / "0001.npz").write_bytes(b"x" * size)
    return e


def test_a_linked_stage_folder_is_refused_and_nothing_is_deleted(tmp_path, capsys):
    root, outside = tmp_path / "cache", tmp_path / "outside"
    real = _entry(root, "s", "export", "aaaaaaaaaaaa")
    victim = _entry(outside, "x", "surface", "bbbbbbbbbbbb")
    os.symlink(outside / "x" / "surface", root / "s" / "surface")  # a linked stage folder
    linked = root / "s" / "surface" / "surface-bbbbbbbbbbbb"
    with pytest.raises(PathError, match="symbolic link"):
        delete([real, linked], root=root, dry_run=False, yes=True)
    assert real.is_dir() and victim.is_dir()  # checked first: nothing deleted


def test_a_linked_entry_is_refused_and_its_target_not_counted(tmp_path):
    root = tmp_path / "cache"
    target = _entry(tmp_path / "outside", "x", "surface", "bbbbbbbbbbbb", size=1000)
    (root / "s" / "surface").mkdir(parents=True)
    os.symlink(target, root / "s" / "surface" / "surface-cccccccccccc")
    link = root / "s" / "surface" / "surface-cccccccccccc"
    assert tree_size(link) == 0
    with pytest.raises(PathError):
        delete([link], root=root, dry_run=False, yes=True)
    assert target.is_dir()


def test_prune_lists_old_entries_and_keeps_the_protected(tmp_path):
    root = tmp_path / "cache"
    old, new = _entry(root, "s", "surface", "000000000000"), _entry(root, "s", "surface", "111111111111")
    os.utime(old, (1, 1))
    assert prune_targets(root, keep=1, in_use=set()) == [old]
    assert prune_targets(root, keep=1, in_use={old.resolve()}) == []
    assert delete([old], root=root, dry_run=False, yes=True) == 0 and not old.exists() and new.exists()
