"""What was written is what is read and published: a cache file changed after it was written
(same size or not) is found by its checksum where a stage reads it, before a publish and by
`status --verify`, and the stage that wrote it redoes it; a damaged checkpoint is passed over."""

from __future__ import annotations

import json

import pytest

import mpmfx
from mpmfx import checksum
from mpmfx.cli import main
from tests.conftest import write_tiny_shot


def _flip(path) -> bytes:
    """Invert one byte in the middle of `path` (its size unchanged); returns the new bytes."""
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    return bytes(data)


def _states(shot, cache) -> dict[str, str]:
    return {s.stage: s.state for s in mpmfx.load_shot(shot, cache_root=cache, quiet=True).status()}


def test_a_surface_frame_changed_at_equal_size_is_redone_when_export_reads_it(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    shot, cache = write_tiny_shot(tmp_path, frame_end=3), str(tmp_path / "c")
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q"]) == 0
    surface = mpmfx.load_shot(shot, cache_root=cache).entries()["surface"]
    written = surface.frame_path(2, "npz").read_bytes()
    _flip(surface.frame_path(2, "npz"))
    capsys.readouterr()
    assert main(["run", str(shot), "--until", "export", "--cache", cache, "-q"]) == 0
    err = capsys.readouterr().err
    assert "frames/0002.npz" in err and "checksum" in err and "Traceback" not in err
    assert surface.frame_path(2, "npz").read_bytes() == written  # redone by surface, as it was
    assert _states(shot, cache)["export"] == "cached"


def test_status_verify_names_a_changed_surface_frame_and_the_next_run_redoes_it(tmp_path, monkeypatch, capsys):
    """status --verify reads every entry of the shot, another variant's too."""
    monkeypatch.chdir(tmp_path)
    shot, cache = write_tiny_shot(tmp_path, frame_end=3), str(tmp_path / "c")
    assert main(["run", str(shot), "--until", "export", "--cache", cache, "-q"]) == 0
    variant = ["--set", "surface.smooth_iters=0"]
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q", *variant]) == 0
    surface = mpmfx.load_shot(shot, cache_root=cache).entries()["surface"]
    other = mpmfx.load_shot(shot, overrides=variant[1:], cache_root=cache).entries()["surface"]
    written = surface.frame_path(2, "npz").read_bytes()
    _flip(surface.frame_path(2, "npz"))
    _flip(other.frame_path(3, "npz"))
    capsys.readouterr()
    assert main(["status", str(shot), "--cache", cache, "--verify"]) == 1
    out = capsys.readouterr().out
    damaged = sorted(line for line in out.splitlines() if "checksum" in line)
    assert len(damaged) == 2 and all(line.split()[0] == "surface" for line in damaged)
    assert {(surface.root.name in line, "frames/0002.npz" in line) for line in damaged} == {
        (True, True),
        (False, False),
    }
    assert any(other.root.name in line and "frames/0003.npz" in line for line in damaged)
    assert _states(shot, cache)["surface"] == "partial"
    assert main(["run", str(shot), "--until", "export", "--cache", cache, "-q"]) == 0
    assert surface.frame_path(2, "npz").read_bytes() == written
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q", *variant]) == 0
    assert main(["status", str(shot), "--cache", cache, "--verify"]) == 0
    assert "every cached file holds the bytes written" in capsys.readouterr().out


def test_a_changed_vdb_or_png_is_redone_not_published_again(tmp_path, monkeypatch, capsys):
    from PIL import Image

    from mpmfx.io.vdb import read_vdb

    monkeypatch.chdir(tmp_path)
    shot, cache = write_tiny_shot(tmp_path, frame_end=2), str(tmp_path / "c")
    assert main(["run", str(shot), "--cache", cache, "-q"]) == 0
    entries = mpmfx.load_shot(shot, cache_root=cache).entries()
    vdb = sorted(entries["export"].root.glob("vdb/*/0002.vdb"))[0]
    png = entries["render"].frame_path(2, "png")
    bad_vdb, bad_png = _flip(vdb), _flip(png)
    capsys.readouterr()
    assert main(["run", str(shot), "--cache", cache, "-q"]) == 0
    err = capsys.readouterr().err
    assert "0002.vdb" in err and "0002.png" in err
    published_vdb = tmp_path / "published" / "tiny" / vdb.relative_to(entries["export"].root)
    published_png = tmp_path / "renders" / "tiny" / "0002.png"
    assert published_vdb.read_bytes() != bad_vdb and read_vdb(published_vdb)["grids"]
    assert published_png.read_bytes() != bad_png
    Image.open(published_png).load()
    for entry, path in ((entries["export"], vdb), (entries["render"], png)):
        rel = path.relative_to(entry.root).as_posix()
        assert checksum.digest(path) == entry.manifest()["digests"][rel]


@pytest.mark.parametrize("damage, checkpoints", [("truncate", [4]), ("flip", [3, 4])])
def test_a_damaged_checkpoint_is_passed_over_and_the_extension_resumes(tmp_path, capsys, damage, checkpoints):
    """checkpoint_every = 2 on frames 1-4 keeps checkpoints 3 and 4. A damaged newest one: the
    extension to frame 6 resumes from 3; both damaged: from the start. Either way the frames are
    those of a run never stopped, and no traceback."""
    shot = write_tiny_shot(tmp_path, frame_end=4)
    ref = mpmfx.load_shot(shot, overrides=["shot.frame_end=6"], cache_root=tmp_path / "ref", quiet=True)
    ref.run(until="simulate")
    cache = str(tmp_path / "c")
    assert main(["run", str(shot), "--until", "simulate", "--cache", cache, "-q"]) == 0
    sim = mpmfx.load_shot(shot, cache_root=cache).entries()["simulate"]
    assert sorted(sim.manifest()["checkpoints"]) == ["checkpoints/0003.npz", "checkpoints/0004.npz"]
    for c in checkpoints:
        path = sim.root / "checkpoints" / f"{c:04d}.npz"
        if damage == "truncate":
            with open(path, "r+b") as f:
                f.truncate(path.stat().st_size // 2)
        else:
            _flip(path)
    capsys.readouterr()
    assert main(["run", str(shot), "--until", "simulate", "--cache", cache, "-q", "--set", "shot.frame_end=6"]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    notices = [line for line in err.splitlines() if "checkpoint" in line]
    assert len(notices) == len(checkpoints)
    assert ("the start" in notices[-1]) == (checkpoints == [3, 4])
    want = ref.entries()["simulate"].frames_dir
    assert [p.read_bytes() for p in sorted(sim.frames_dir.glob("*.npz"))] == [
        p.read_bytes() for p in sorted(want.glob("*.npz"))
    ]


def test_a_frame_its_manifest_no_longer_lists_is_redone_not_asked_for_again(tmp_path, monkeypatch, capsys):
    """A simulate frame deleted and taken out of the manifest's files by hand: the entry is
    partial, and the next run makes the frame again rather than stop on the missing file."""
    monkeypatch.chdir(tmp_path)
    shot, cache = write_tiny_shot(tmp_path, frame_end=3), str(tmp_path / "c")
    assert main(["run", str(shot), "--until", "simulate", "--cache", cache, "-q"]) == 0
    sim = mpmfx.load_shot(shot, cache_root=cache).entries()["simulate"]
    written = sim.frame_path(2, "npz").read_bytes()
    sim.frame_path(2, "npz").unlink()
    man = json.loads(sim.manifest_path.read_text())
    del man["files"]["frames/0002.npz"]
    sim.manifest_path.write_text(json.dumps(man))
    assert _states(shot, cache)["simulate"] == "partial"
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q"]) == 0
    assert sim.frame_path(2, "npz").read_bytes() == written
    assert _states(shot, cache)["surface"] == "cached"


def test_an_entry_without_checksums_is_checked_by_size_not_called_damaged(tmp_path, monkeypatch, capsys):
    """A manifest without digests (and files without sidecars): unverified, still cached."""
    monkeypatch.chdir(tmp_path)
    shot, cache = write_tiny_shot(tmp_path, frame_end=2), str(tmp_path / "c")
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q"]) == 0
    for entry in mpmfx.load_shot(shot, cache_root=cache).entries().values():
        if entry.manifest_path.is_file():
            man = json.loads(entry.manifest_path.read_text())
            entry.manifest_path.write_text(
                json.dumps({k: v for k, v in man.items() if k not in ("digests", "checkpoints")})
            )
            for side in entry.root.rglob(f".*{checksum.SUFFIX}"):
                side.unlink()
    capsys.readouterr()
    assert main(["status", str(shot), "--cache", cache, "--verify"]) == 0
    out = capsys.readouterr().out
    assert "checked by size only" in out and "damaged" not in out
    assert set(_states(shot, cache).values()) == {"cached", "missing"}


def test_a_damaged_file_that_escapes_a_command_is_marked_and_named_not_a_traceback(tmp_path, monkeypatch, capsys):
    """(A wedge's variants run without the runner's redo: the file is marked for the next run.)"""
    import mpmfx.cli as cli
    from mpmfx.cache import Cache, DamagedError, atomic_path

    e = Cache(tmp_path, "shot").entry("surface", 1, {}, {}, {})
    with atomic_path(e.frame_path(1, "npz"), checksum=True) as tmp:
        tmp.write_bytes(b"a frame")
    e.write_manifest(frames=[1], timings={})

    def damaged(args):
        raise DamagedError(str(e.root), "frames/0001.npz", "its bytes differ from those written (checksum)")

    monkeypatch.setattr(cli, "_dispatch", damaged)
    assert main(["status", "any.toml"]) == 1
    err = capsys.readouterr().err
    assert "frames/0001.npz" in err and "run again" in err and "Traceback" not in err
    assert not e.complete([1]) and e.damaged() == ["frames/0001.npz"]


def test_a_file_damaged_again_after_its_redo_stops_the_run_naming_the_disk(tmp_path, monkeypatch, capsys):
    """Redone once, unreadable again: no endless redo, exit 1 with the path and the likely cause."""
    import zlib

    from mpmfx.io.frames import SurfaceFrame

    monkeypatch.chdir(tmp_path)
    shot, cache = write_tiny_shot(tmp_path, frame_end=2), str(tmp_path / "c")
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q"]) == 0
    real = SurfaceFrame.read.__func__

    def failing(cls, path, **kw):
        if path.name == "0002.npz":
            raise zlib.error("Error -3 while decompressing data: invalid distance too far back")
        return real(cls, path, **kw)

    monkeypatch.setattr(SurfaceFrame, "read", classmethod(failing))
    capsys.readouterr()
    assert main(["run", str(shot), "--until", "export", "--cache", cache, "-q"]) == 1
    err = capsys.readouterr().err
    assert "frames/0002.npz" in err and "again after it was redone" in err and "disk" in err
    assert "Traceback" not in err
