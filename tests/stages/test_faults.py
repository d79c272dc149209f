"""A full disk in any stage or in the publish: one line naming the path being written and the
fix, exit 2, no traceback, and nothing cached lost. The disk fills at the write layer
(monkeypatched: a write that raises ENOSPC the way Python's, PIL's, USD's or pyopenvdb's does).
"""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path

import pytest

import mpmfx
import mpmfx.diskspace as diskspace
from mpmfx.cli import main
from tests.conftest import write_tiny_shot

STAGES = ("voxelise", "simulate", "surface", "export", "render")


@pytest.fixture(scope="module")
def done(tmp_path_factory) -> tuple[Path, Path]:
    """A tiny shot (3 frames) run through every stage once: (shot file, cache)."""
    folder = tmp_path_factory.mktemp("faults")
    shot = write_tiny_shot(folder, frame_end=3)
    assert main(["run", str(shot), "--cache", str(folder / "cache"), "-q"]) == 0
    return shot, folder / "cache"


@pytest.fixture
def copy(done, tmp_path, monkeypatch) -> tuple[Path, Path]:
    """The finished shot's cache copied, in a working folder of its own."""
    shot, cache = done
    shutil.copytree(cache, tmp_path / "cache")
    monkeypatch.chdir(tmp_path)
    return shot, tmp_path / "cache"


def _full(_path) -> int:
    return 0


def _intact(shot: Path, cache: Path, upto: str) -> None:
    """Every stage before `upto` is still cached, and its files unchanged in size."""
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    state = {s.stage: s.state for s in run.status()}
    assert all(state[s] == "cached" for s in STAGES[: STAGES.index(upto)]), state


def _said(capsys, *words: str) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Error in" not in err and len(err.strip().splitlines()) == 1, err
    assert "no space left" in err and "free space" in err, err
    for w in words:
        assert w in err, err
    return err


@pytest.mark.parametrize("stage", ["voxelise", "simulate", "surface"])
def test_a_full_disk_writing_frames_names_the_file_and_the_cache(copy, monkeypatch, capsys, stage):
    import mpmfx.io.frames as frames

    shot, cache = copy
    real = frames.write_npz

    def full(f, entries):  # as Python's own file writes fail: errno 28, no file name
        if f"/{stage}/" in f.name:
            f.write(b"PK partial")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(f, entries)

    monkeypatch.setattr(frames, "write_npz", full)
    argv = ["run", str(shot), "--until", stage, "--force", stage, "--cache", str(cache), "-q"]
    assert main(argv) == 2
    err = _said(capsys, f"/{stage}/", "--cache", str(cache.resolve()))
    assert ".npz" in err and ".tmp" not in err  # the file being written, not its temp name
    _intact(shot, cache, stage)
    assert not list(cache.rglob(".*.tmp*"))
    monkeypatch.undo()
    monkeypatch.chdir(cache.parent)
    assert main(argv[:-3] + ["--cache", str(cache), "-q"]) == 0


def test_a_full_disk_is_found_before_usd_writes_a_layer(copy, monkeypatch, capsys):
    from pxr import Sdf

    shot, cache = copy
    exported = []
    monkeypatch.setattr(diskspace, "free_bytes", _full)
    monkeypatch.setattr(Sdf.Layer, "Export", lambda *a, **k: exported.append(a) or True)
    assert main(["run", str(shot), "--until", "export", "--force", "export", "--cache", str(cache), "-q"]) == 2
    _said(capsys, "/export/", ".usdc", "--cache")
    assert not exported  # USD never started on a full disk
    _intact(shot, cache, "export")


def test_usd_failing_on_a_disk_that_fills_says_the_layer_not_usds_errors(copy, monkeypatch, capsys):
    from pxr import Sdf

    shot, cache = copy
    free = [1 << 40]

    def export(layer, path, *a, **k):  # the disk fills during the save: USD raises its error
        free[0] = 0
        return Sdf.Layer.CreateNew("/proc/mpmfx-none/folder.usda")  # a folder USD cannot make

    monkeypatch.setattr(diskspace, "free_bytes", lambda _p: free[0])
    monkeypatch.setattr(Sdf.Layer, "Export", export)
    assert main(["run", str(shot), "--until", "export", "--force", "export", "--cache", str(cache), "-q"]) == 2
    _said(capsys, "/export/", "--cache")
    _intact(shot, cache, "export")


def test_usd_failing_for_another_reason_gives_its_first_line_not_a_traceback(copy, monkeypatch, capsys):
    from pxr import Sdf

    shot, cache = copy
    monkeypatch.setattr(
        Sdf.Layer, "Export", lambda layer, path, *a, **k: Sdf.Layer.CreateNew("/proc/mpmfx-none/x.usda")
    )
    assert main(["run", str(shot), "--until", "export", "--force", "export", "--cache", str(cache), "-q"]) == 1
    err = capsys.readouterr().err
    assert "USD could not write the layer: Could not create directory" in err and ".usdc" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_a_vdb_writer_cut_short_by_a_full_disk_is_said_as_a_full_disk(copy, monkeypatch, capsys):
    from tests.stages.test_safety import truncating_vdb

    shot, cache = copy
    free = [1 << 40]
    truncating_vdb(monkeypatch, after=lambda: free.__setitem__(0, 0))  # no error, half a file; then full
    monkeypatch.setattr(diskspace, "free_bytes", lambda _p: free[0])
    assert main(["run", str(shot), "--until", "export", "--force", "export", "--cache", str(cache), "-q"]) == 2
    _said(capsys, ".vdb", "--cache")
    _intact(shot, cache, "export")


def test_a_full_disk_under_a_preview_frame_names_the_frame(copy, monkeypatch, capsys):
    from PIL import Image

    shot, cache = copy

    def full(self, fp, *a, **k):  # PIL fails at close: errno 28, no file name
        Path(fp).write_bytes(b"\x89PNG partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Image.Image, "save", full)
    assert main(["run", str(shot), "--force", "render", "--cache", str(cache), "-q"]) == 2
    _said(capsys, "/render/", "0001.png", "--cache")
    _intact(shot, cache, "render")
    assert not list(cache.rglob(".*.tmp*"))


def test_a_full_disk_under_the_thickness_heatmap_names_it(copy, monkeypatch, capsys):
    from PIL import Image

    shot, cache = copy

    def full(self, fp, *a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Image.Image, "save", full)
    assert main(["run", str(shot), "--until", "voxelise", "--force", "voxelise", "--cache", str(cache), "-q"]) == 2
    _said(capsys, "/voxelise/", "thickness_cube.png", "--cache")
    assert not list(cache.rglob("voxelise/*/thickness_cube.png"))


def test_a_full_disk_under_renders_names_renders_not_the_cache(copy, monkeypatch, capsys):
    shot, cache = copy
    assert main(["run", str(shot), "--cache", str(cache), "-q"]) == 0  # published here once
    before = {p.name: p.read_bytes() for p in Path("renders/tiny").iterdir() if p.is_file()}
    real = shutil.copyfile

    def full(src, dst, *a, **k):  # as shutil says it: the source is the cache file
        real(src, dst)
        exc = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        exc.filename, exc.filename2 = str(src), str(dst)
        raise exc

    monkeypatch.setattr(shutil, "copyfile", full)
    assert main(["run", str(shot), "--cache", str(cache), "-q"]) == 2
    err = _said(capsys, "renders/tiny", "working folder")
    assert "/render/" not in err and "--cache" not in err
    assert {p.name: p.read_bytes() for p in Path("renders/tiny").iterdir() if p.is_file()} == before
    assert not list(Path("renders").glob(".*"))  # no partial copy left
    _intact(shot, cache, "render")


def test_a_renders_folder_too_small_is_refused_before_copying(copy, monkeypatch, capsys):
    shot, cache = copy
    copied = []
    monkeypatch.setattr(shutil, "copyfile", lambda *a, **k: copied.append(a))
    monkeypatch.setattr(diskspace, "free_bytes", lambda p: 0 if "renders" in str(p) else 1 << 40)
    assert main(["run", str(shot), "--cache", str(cache), "-q"]) == 2
    _said(capsys, "renders/tiny")
    assert not copied


def test_a_read_only_cache_is_said_as_such(copy, monkeypatch, capsys):
    import mpmfx.io.frames as frames

    shot, cache = copy

    def denied(f, entries):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), f.name)

    monkeypatch.setattr(frames, "write_npz", denied)
    argv = ["run", str(shot), "--until", "simulate", "--force", "simulate", "--cache", str(cache), "-q"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "read-only" in err and "/simulate/" in err and "--cache" in err and "Traceback" not in err


def test_a_read_error_of_another_file_keeps_its_own_name(tmp_path):
    """Only the write is renamed to the destination: a missing source stays itself."""
    from mpmfx.cache import atomic_path

    with pytest.raises(FileNotFoundError) as caught, atomic_path(tmp_path / "out.png"):
        open(tmp_path / "missing.npz")
    assert caught.value.filename == str(tmp_path / "missing.npz")
    assert not list(tmp_path.iterdir())


def test_the_check_reports_a_full_disk_under_its_output(tmp_path, monkeypatch, capsys):
    import trimesh

    from mpmfx.check import run_check

    trimesh.creation.box(extents=[0.4, 0.4, 0.4]).export(tmp_path / "box.obj")
    monkeypatch.chdir(tmp_path)

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", full)
    assert run_check(str(tmp_path / "box.obj"), grid_n=16) == 2
    err = capsys.readouterr().err
    assert "renders/check/box" in err and "free space" in err and "Traceback" not in err


def test_a_full_disk_met_by_a_writer_that_names_no_file_is_still_one_line(tmp_path, monkeypatch, capsys):
    import mpmfx.stages.runner as runner

    shot = write_tiny_shot(tmp_path, frame_end=2)

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(runner.ShotRun, "run", full)
    assert main(["run", str(shot), "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "no space left" in err and "--cache" in err and "Traceback" not in err


def test_a_disk_too_full_for_the_lock_names_the_lock(tmp_path, monkeypatch, capsys):
    import mpmfx.cache as cache

    shot = write_tiny_shot(tmp_path, frame_end=2)

    def full(*a):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(cache.os, "pwrite", full)
    assert main(["run", str(shot), "--cache", str(tmp_path / "c"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "tiny/.lock" in err and "free space" in err and "Traceback" not in err
