"""Nothing lost. Paths stay inside their roots, clean removes exactly what it lists,
one run per shot at a time, and a failing writer leaves nothing under a final name."""

from __future__ import annotations

import os

import pytest

import mpmfx
from mpmfx.cli import main
from tests.conftest import write_tiny_shot


@pytest.mark.parametrize("name", [".", "..", ".hidden"])
def test_shot_names_that_are_paths_are_refused(tmp_path, monkeypatch, capsys, name):
    work = tmp_path / "work"
    work.mkdir()
    keep = work / "precious.txt"
    keep.write_text("do not delete")
    shot = write_tiny_shot(tmp_path)
    monkeypatch.chdir(work)
    for cmd in (["run", "--until", "voxelise"], ["clean", "--yes"]):
        code = main([cmd[0], str(shot), "--set", f"shot.name={name}", *cmd[1:], "--cache", str(work / "cache")])
        assert code == 2
        assert "shot.name" in capsys.readouterr().err
    assert keep.read_text() == "do not delete" and sorted(p.name for p in work.iterdir()) == ["precious.txt"]


def test_cache_refuses_paths_outside_its_root(tmp_path):
    from mpmfx.cache import Cache, PathError

    with pytest.raises(PathError):
        Cache(tmp_path / "cache", "..")
    with pytest.raises(PathError):
        Cache(tmp_path / "cache", ".")


@pytest.fixture
def two_variants(tmp_path):
    """The tiny shot (3 frames) up to surface, plain and with a surface override."""
    shot = write_tiny_shot(tmp_path, frame_end=3)
    cache = tmp_path / "cache"
    plain = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    plain.run(until="surface")
    variant = mpmfx.load_shot(shot, overrides=["surface.radius_scale=1.3"], cache_root=cache, quiet=True)
    variant.run(until="surface")
    return shot, cache, plain, variant


def test_clean_removes_exactly_the_variants_entries(two_variants, capsys):
    shot, cache, plain, variant = two_variants
    args = [str(shot), "--cache", str(cache), "--set", "surface.radius_scale=1.3"]
    assert main(["clean", *args, "--stage", "surface", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert variant.entries()["surface"].root.name in out and "B" in out  # listed, with a size
    assert variant.entries()["surface"].root.is_dir()  # a dry run deletes nothing
    assert main(["clean", *args, "--stage", "surface"]) == 0
    assert not variant.entries()["surface"].root.exists()
    assert plain.entries()["surface"].root.is_dir() and plain.entries()["simulate"].complete()


def test_clean_asks_before_deleting_a_simulation(two_variants, capsys, monkeypatch):
    shot, cache, plain, _ = two_variants
    sim = plain.entries()["simulate"].root
    monkeypatch.setattr("sys.stdin", open(os.devnull))  # no one to answer
    assert main(["clean", str(shot), "--cache", str(cache)]) == 2
    assert "--yes" in capsys.readouterr().err and sim.is_dir()
    assert main(["clean", str(shot), "--cache", str(cache), "--yes"]) == 0
    assert not sim.exists() and not plain.entries()["surface"].root.exists()


SLOW = """
import sys, time
import mpmfx.stages.simulate as sim
_write = sim._write_frame
def slow(*a, **k):
    _write(*a, **k)
    time.sleep(0.5)   # keep the run busy while the test tries a second one
sim._write_frame = slow
from mpmfx.cli import main
sys.exit(main(sys.argv[1:]))
"""


def kill_mid_simulate(shot, cache, *, after: int = 3):
    """Run `mpmfx run SHOT --until simulate` in a child whose frame writes are slowed, and kill it
    (SIGKILL) once `after` frames are complete. Returns the shot's run and its simulate frames dir."""
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen(
        [sys.executable, "-c", SLOW, "run", str(shot), "--until", "simulate", "--cache", str(cache), "-q"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    frames = run.entries()["simulate"].frames_dir
    deadline = time.time() + 120
    while time.time() < deadline and len(list(frames.glob("[0-9]*.npz"))) < after:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    return run, frames


def test_a_second_run_on_a_busy_shot_stops_and_names_the_first(tmp_path, capsys):
    import subprocess
    import sys
    import time

    shot = write_tiny_shot(tmp_path, frame_end=8)
    cache = tmp_path / "cache"
    proc = subprocess.Popen(
        [sys.executable, "-c", SLOW, "run", str(shot), "--until", "simulate", "--cache", str(cache), "-q"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    frames = run.entries()["simulate"].frames_dir
    deadline = time.time() + 120
    while time.time() < deadline and len(list(frames.glob("[0-9]*.npz"))) < 2 and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, "the first run must still be going"
    code = main(["run", str(shot), "--until", "simulate", "--force", "simulate", "--cache", str(cache), "-q"])
    err = capsys.readouterr().err
    assert code == 1 and f"pid {proc.pid}" in err and "another run" in err
    assert main(["clean", str(shot), "--cache", str(cache), "--yes"]) == 1
    assert proc.wait(timeout=120) == 0, proc.stderr.read()
    entry = run.entries()["simulate"]
    assert entry.complete(list(range(1, 9))) and entry.done_frames("npz") == list(range(1, 9))


def test_a_lost_frame_is_redone_not_trusted(tmp_path):
    """A frame deleted from a complete entry: the entry is partial, and a run makes it whole again."""
    shot = write_tiny_shot(tmp_path, frame_end=4)
    run = mpmfx.load_shot(shot, cache_root=tmp_path / "c", quiet=True)
    run.run(until="simulate")
    sim = run.entries()["simulate"]
    before = sim.frame_path(2, "npz").read_bytes()
    sim.frame_path(2, "npz").unlink()
    assert {s.stage: s.state for s in run.status()}["simulate"] == "partial"
    assert {r.stage: r.state for r in run.run(until="simulate")}["simulate"] == "resumed"
    assert sim.frame_path(2, "npz").read_bytes() == before and sim.complete(list(range(1, 5)))


def truncating_vdb(monkeypatch, after=lambda: None):
    """pyopenvdb as on a full disk: the write 'succeeds' and leaves half a file; `after` runs
    once it has (e.g. to make the disk read as full from then on)."""
    import mpmfx.io.vdb as vdb_io

    real = vdb_io.import_pyopenvdb()

    class Full:
        def __getattr__(self, name):
            return getattr(real, name)

        @staticmethod
        def write(path, **kw):
            real.write(path, **kw)
            with open(path, "r+b") as f:
                f.truncate(os.path.getsize(path) // 2)
            after()

    monkeypatch.setattr(vdb_io, "import_pyopenvdb", lambda: Full())
    monkeypatch.setenv("MPMFX_VDB_IN_PROCESS", "1")  # the grids made here, where the patch is


def test_a_failing_vdb_writer_leaves_nothing_under_a_final_name(tmp_path, monkeypatch, capsys):
    from mpmfx.io.vdb import read_vdb

    shot = write_tiny_shot(tmp_path, frame_end=3)
    cache = tmp_path / "c"
    truncating_vdb(monkeypatch)
    assert main(["run", str(shot), "--until", "export", "--cache", str(cache), "-q"]) == 1
    err = capsys.readouterr().err
    assert ".vdb" in err and "disk" in err and "Traceback" not in err
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    export = run.entries()["export"]
    assert not list(export.root.rglob("*.vdb")) and not export.done_frames("usdc")  # no half-made frame
    monkeypatch.undo()
    assert main(["run", str(shot), "--until", "export", "--cache", str(cache), "-q"]) == 0
    vdbs = sorted(export.root.rglob("[0-9]*.vdb"))
    assert len(vdbs) == 3 and all(read_vdb(p)["grids"] for p in vdbs)
    with open(vdbs[1], "r+b") as f:  # damaged after the fact: no longer trusted as cached
        f.truncate(100)
    assert {s.stage: s.state for s in run.status()}["export"] == "partial"
    assert {r.stage: r.state for r in run.run(until="export")}["export"] == "resumed"
    assert read_vdb(vdbs[1])["grids"]


@pytest.mark.parametrize("errno_, words", [(28, "free space"), (13, "permission")])
def test_disk_full_and_permission_errors_name_the_path_and_the_fix(tmp_path, monkeypatch, capsys, errno_, words):
    import mpmfx.io.frames as frames

    shot = write_tiny_shot(tmp_path, frame_end=3)
    real = frames.write_arrays

    def failing(path, arrays, **kw):
        if "frames" in str(path):
            raise OSError(errno_, os.strerror(errno_), str(path))
        return real(path, arrays, **kw)

    monkeypatch.setattr(frames, "write_arrays", failing)
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(tmp_path / "c"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "0001.npz" in err and words in err.lower() and "Traceback" not in err


def test_temp_files_of_a_killed_run_are_removed_by_the_next(tmp_path):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    run = mpmfx.load_shot(shot, cache_root=tmp_path / "c", quiet=True)
    orphan = run.entries()["simulate"].frames_dir / ".0002.4242-deadbeef.tmp.npz"
    orphan.parent.mkdir(parents=True)
    orphan.write_bytes(b"half a frame")
    run.run(until="voxelise")
    assert not orphan.exists()


def test_a_killed_simulation_resumes_from_its_last_complete_frame(tmp_path):
    """The README's promise, with the default checkpoints: killed after frame 3 (of 8), the next run
    keeps frames 1-3 as they are."""
    shot = write_tiny_shot(tmp_path, frame_end=8)
    shot.write_text(shot.read_text().replace("checkpoint_every = 2\n", ""))  # the default
    ref = mpmfx.load_shot(shot, cache_root=tmp_path / "ref", quiet=True).run(until="simulate")[1].entry
    run, frames = kill_mid_simulate(shot, tmp_path / "killed")
    kept = {p.name: p.stat().st_ino for p in frames.glob("[0-9]*.npz")}
    assert 3 <= len(kept) < 8
    assert {r.stage: r.state for r in run.run(until="simulate")}["simulate"] == "resumed"
    assert {n: (frames / n).stat().st_ino for n in kept} == kept  # not one complete frame redone
    assert [p.read_bytes() for p in sorted(frames.glob("*.npz"))] == [
        p.read_bytes() for p in sorted((ref / "frames").glob("*.npz"))
    ]


def test_status_reports_sizes_and_prune_keeps_the_newest_and_the_published(tmp_path, monkeypatch, capsys):
    import time

    monkeypatch.chdir(tmp_path)
    shot = write_tiny_shot(tmp_path, frame_end=2)
    cache = tmp_path / "c"
    surfaces = []
    for scale in ("1.1", "1.2", "1.3"):
        run = mpmfx.load_shot(shot, overrides=[f"surface.radius_scale={scale}"], cache_root=cache, quiet=True)
        run.run(until="export")
        surfaces.append(run.entries()["surface"].root)
        time.sleep(0.05)  # distinct manifest times
    published_variant = mpmfx.load_shot(shot, overrides=["surface.radius_scale=1.1"], cache_root=cache, quiet=True)
    published_variant.run(until="export")  # cached, and published again: the oldest surface in use
    (tmp_path / "published" / "tiny@surface.radius_scale=1.2").unlink()  # each variant published beside; not 1.2
    capsys.readouterr()
    assert main(["status", str(shot), "--cache", str(cache)]) == 0
    out = capsys.readouterr().out
    assert " kB" in out or " MB" in out
    assert main(["cache", "prune", "--keep", "1", "--cache", str(cache), "--dry-run"]) == 0
    assert all(s.is_dir() for s in surfaces)
    assert main(["cache", "prune", "--keep", "1", "--cache", str(cache), "--yes"]) == 0
    assert surfaces[0].is_dir()  # the published export uses it (through its upstream key)
    assert not surfaces[1].exists()  # neither newest nor published
    assert surfaces[2].is_dir()  # the newest
    assert published_variant.entries()["simulate"].complete()  # one simulate variant: kept
    assert (tmp_path / "published" / "tiny@surface.radius_scale=1.1" / "shot.usda").is_file()


def test_frames_are_stored_compactly_and_byte_deterministic(tmp_path):
    """The frame files' measured choices: deflate what shrinks much and fast (material and body
    indices, Jp, leaves, faces, vertices); ids and noisy floats are stored as they are (deflating
    them cost a 2.6M-particle frame 450 ms of the writer for 10 % of its size: io/frames.py)."""
    import zipfile

    import numpy as np

    from mpmfx.io.frames import GroupSurface, ParticleFrame, SurfaceFrame

    n = 4000
    rng = np.random.default_rng(1)
    p = ParticleFrame(
        x=rng.random((n, 3), np.float32),
        v=rng.random((n, 3), np.float32),
        id=np.arange(n, dtype=np.int32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
        Jp=np.ones(n, np.float32),
    )
    p.write(tmp_path / "a.npz")
    p.write(tmp_path / "b.npz")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    with zipfile.ZipFile(tmp_path / "a.npz") as z:
        stored = {i.filename: i.compress_size / i.file_size for i in z.infolist() if i.file_size > 1000}
    assert stored["body.npy"] < 0.1 and stored["material.npy"] < 0.1 and stored["Jp.npy"] < 0.1
    assert "id.npy" not in stored and stored["x.npy"] > 0.99  # ids 0..n-1 are rebuilt on read
    # a grid's triangles: the index runs of a mesh's faces (a plain arange is no mesh's, and
    # deflates differently from one deflate library to another)
    i, j = np.meshgrid(np.arange(29), np.arange(29), indexing="ij")
    a, b, c, d = i * 30 + j, (i + 1) * 30 + j, (i + 1) * 30 + j + 1, i * 30 + j + 1
    faces = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], 2).reshape(-1, 3).astype(np.int32)
    g = GroupSurface(
        vertices=rng.random((900, 3)).astype(np.float32),
        faces=faces,
        normals=rng.random((900, 3)).astype(np.float32),
        velocities=rng.random((900, 3)).astype(np.float32),
        block_ijk=np.zeros((4, 3), np.int64),
        blocks=np.full((4, 8, 8, 8), 0.1, np.float32),
        inside_ijk=np.zeros((0, 3), np.int64),
        voxel_size=0.01,
        background=0.03,
        vel_blocks=np.zeros((4, 8, 8, 8, 3), np.float16),
    )
    SurfaceFrame({"g": g}).write(tmp_path / "s.npz")
    with zipfile.ZipFile(tmp_path / "s.npz") as z:
        stored = {i.filename: i.compress_size / i.file_size for i in z.infolist() if i.file_size > 1000}
    assert stored["g.vel_blocks.npy"] < 0.1 and stored["g.faces.npy"] < 0.5


def test_a_surfacing_error_keeps_the_frames_before_it_and_a_rerun_resumes(tmp_path, monkeypatch):
    """Serial frames are written behind on a thread (surface._pipelined): when frame 3 fails, the
    frames surfaced before it are on disk, complete, and the next run does only what is missing."""
    import mpmfx.stages.surface as surface_stage
    from mpmfx.io.frames import SurfaceFrame

    shot = write_tiny_shot(tmp_path, frame_end=4)
    run = mpmfx.load_shot(shot, cache_root=tmp_path / "c", quiet=True)
    run.run(until="simulate")
    real, calls = surface_stage.make_surfaces, []

    def failing(job, particles, f):
        calls.append(1)
        if len(calls) == 3:
            raise RuntimeError("frame 3: the surfacer failed")
        return real(job, particles, f)

    monkeypatch.setattr(surface_stage, "make_surfaces", failing)
    with pytest.raises(RuntimeError, match="frame 3"):
        run.run(until="surface")
    entry = run.entries()["surface"]
    written = sorted(int(p.stem) for p in entry.frames_dir.glob("[0-9]*.npz"))
    assert len(written) == 2 and all(SurfaceFrame.read(entry.frame_path(f, "npz")).groups for f in written)
    assert not list(entry.frames_dir.glob(".*tmp*"))  # no half-written file left behind
    monkeypatch.setattr(surface_stage, "make_surfaces", real)
    assert {r.stage: r.state for r in run.run(until="surface")}["surface"] == "resumed"
    assert len(list(entry.frames_dir.glob("[0-9]*.npz"))) == len(run.entries()["simulate"].done_frames("npz"))


@pytest.mark.parametrize("text", ['{"files": []}', '{"frames": null}', "[1, 2]"])
def test_a_hand_edited_manifest_is_redone_not_a_traceback(tmp_path, monkeypatch, capsys, text):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    monkeypatch.chdir(tmp_path)
    cache = str(tmp_path / "cache")
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q"]) == 0
    run = mpmfx.load_shot(shot, cache_root=cache, quiet=True)
    entry = run.entries()["surface"]
    entry.manifest_path.write_text(text)
    assert main(["status", str(shot), "--cache", cache]) == 0
    assert "surface" in capsys.readouterr().out
    assert main(["run", str(shot), "--until", "surface", "--cache", cache, "-q"]) == 0
    assert entry.complete()  # its frames kept, its manifest written again
