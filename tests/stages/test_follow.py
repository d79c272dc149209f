"""Surface and export follow simulate frame by frame (mpmfx.stages.follow): the same files as
the stages one after another, made while the simulation runs, and a failure on either side
leaves caches the next run resumes from."""

from __future__ import annotations

import time

import pytest

import mpmfx
import mpmfx.stages.simulate as simulate_stage
import mpmfx.stages.surface as surface_stage
from tests.conftest import write_tiny_shot


def _files(entry, pattern: str) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(entry.frames_dir.glob(pattern))}


def test_followed_stages_write_what_the_stages_alone_write(tmp_path, monkeypatch):
    shot = write_tiny_shot(tmp_path, frame_end=4, extra="\n[export]\nvdb = false\n")
    alone = mpmfx.load_shot(shot, cache_root=tmp_path / "alone", quiet=True, overlap=False)
    alone.run(until="export")

    # simulate may write frame 3 only once frame 1 is surfaced: stages that do not overlap
    # would wait here for ever (the test then fails on the deadline)
    real = simulate_stage._write_frame
    run = mpmfx.load_shot(shot, cache_root=tmp_path / "followed", quiet=True)
    first = run.entries()["surface"].frame_path(1, "npz")

    def write_frame(entry, frame, *args):
        deadline = time.time() + 120
        while frame == 3 and not first.exists():
            assert time.time() < deadline, "frame 1 was not surfaced while simulate ran"
            time.sleep(0.05)
        real(entry, frame, *args)

    monkeypatch.setattr(simulate_stage, "_write_frame", write_frame)
    states = {r.stage: r.state for r in run.run(until="export")}
    assert states == {"voxelise": "ran", "simulate": "ran", "surface": "ran", "export": "ran"}
    for name, pattern in (("surface", "*.npz"), ("export", "*.usdc")):
        ours, theirs = run.entries()[name], alone.entries()[name]
        assert _files(ours, pattern) == _files(theirs, pattern) and len(_files(ours, pattern)) == len(run.shot.frames)
    man, ref = run.entries()["surface"].manifest(), alone.entries()["surface"].manifest()
    assert man["this_run"] == ref["this_run"]  # the frames made while simulate ran are counted
    assert man["followed_s"]["surface"] > 0
    # where export's time went (mpmfx bench shot prints it): the frames exported while simulate
    # ran, and those after, together every frame's
    ours, theirs = run.entries()["export"].manifest(), alone.entries()["export"].manifest()
    assert set(theirs["seconds_split"]) == {"read", "vdb", "usd", "write"} and theirs["seconds_split"]["write"] > 0
    followed, after = ours.get("followed_s", {}), ours["seconds_split"]
    assert set(followed) | set(after) == {"read", "vdb", "usd", "write"}
    assert followed.get("usd", 0) + after.get("usd", 0) > 0


def test_a_failure_on_either_side_leaves_caches_a_rerun_resumes(tmp_path, monkeypatch):
    shot = write_tiny_shot(tmp_path, frame_end=4)
    ref = mpmfx.load_shot(shot, cache_root=tmp_path / "ref", quiet=True)
    ref.run(until="surface")
    run = mpmfx.load_shot(shot, cache_root=tmp_path / "c", quiet=True)

    # the surfacer fails on its third frame while simulate runs: simulate still finishes, and
    # the error is the surface stage's
    real, calls = surface_stage.make_surfaces, []

    def failing(job, particles, f, **kw):
        calls.append(f)
        if len(calls) == 3:
            raise RuntimeError(f"frame {f}: the surfacer failed")
        return real(job, particles, f, **kw)

    monkeypatch.setattr(surface_stage, "make_surfaces", failing)
    with pytest.raises(RuntimeError, match="the surfacer failed"):
        run.run(until="surface")
    assert run.entries()["simulate"].complete()
    surf = run.entries()["surface"]
    assert len(surf.done_frames("npz")) == 2 and surf.manifest() is None
    monkeypatch.setattr(surface_stage, "make_surfaces", real)

    # simulate fails on its last frame while the follower surfaces: the frames before it stay
    real_write = simulate_stage._write_frame

    def write_frame(entry, frame, *args):
        if frame == 4:
            raise OSError("frame 4: the disk went away")
        real_write(entry, frame, *args)

    monkeypatch.setattr(simulate_stage, "_write_frame", write_frame)
    run.run(until="voxelise")
    with pytest.raises(Exception, match="disk went away"):
        run.run(until="surface", force=["simulate"])
    assert run.entries()["surface"].manifest() is None
    monkeypatch.setattr(simulate_stage, "_write_frame", real_write)

    states = {r.stage: r.state for r in run.run(until="surface")}
    assert states["simulate"] == "resumed" and states["surface"] == "resumed"
    ours, theirs = run.entries()["surface"], ref.entries()["surface"]
    assert _files(ours, "*.npz") == _files(theirs, "*.npz") and len(_files(ours, "*.npz")) == len(run.shot.frames)


def test_device_turns_are_granted_in_the_order_asked():
    """The solver asks for the GPU again as soon as it releases it: a waiting follower must still
    get its turn next (a plain lock may hand it back to the solver frame after frame)."""
    import threading

    from mpmfx.stages.base import Turns

    turns, order, asked = Turns(), [], threading.Event()

    def solver():
        for i in range(4):
            with turns.turn():
                order.append(f"frame {i}")
                if i == 1:
                    asked.wait(10)
                    time.sleep(0.05)  # the follower is now waiting for its turn

    def follower():
        while "frame 1" not in order:
            time.sleep(0.001)
        asked.set()
        with turns.turn():
            order.append("surface")

    threads = [threading.Thread(target=solver), threading.Thread(target=follower)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert order == ["frame 0", "frame 1", "surface", "frame 2", "frame 3"]
