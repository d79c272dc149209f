"""Cycles frames spread over Dask workers: one Blender process a chunk of frames, the same
files and pixels as one Blender for the whole shot; a failed chunk says which frames and where."""

from __future__ import annotations

import json
import os
import shutil

import pytest

import mpmfx
from mpmfx.blender import bpy_available
from mpmfx.cache import TEMP_GLOB
from mpmfx.render.cycles import STALL_ENV
from mpmfx.shotfile import load_shot_config
from mpmfx.stages import render
from mpmfx.stages.parallel import Frames, TaskError
from mpmfx.stages.runner import ShotRun
from mpmfx.threads import usable_cores
from tests.conftest import write_tiny_shot

pytestmark = pytest.mark.skipif(
    not bpy_available(), reason="bpy (Blender as a module) is part of the test set-up: bash setup.sh test installs it"
)

TINY_CYCLES = ["render.engine=cycles", "render.samples=2", "render.width=32", "render.height=18"]


@pytest.fixture(scope="module")
def one_blender(tmp_path_factory):
    """The tiny shot rendered in Cycles by one Blender process (workers=1): the reference."""
    folder = tmp_path_factory.mktemp("cycles_workers")
    shot = write_tiny_shot(folder, frame_end=4)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        run = mpmfx.load_shot(shot, cache_root=folder / "one", quiet=True, overrides=TINY_CYCLES, workers=1)
        entries = {r.stage: r.entry for r in run.run()}
    finally:
        os.chdir(cwd)
    return folder, shot, entries


@pytest.fixture(scope="module")
def cluster():
    """One two-worker LocalCluster for the module (starting one costs seconds)."""
    with Frames(workers=2) as ex:
        yield ex


def _run(shot, cache, cluster) -> ShotRun:
    return ShotRun(load_shot_config(shot, TINY_CYCLES), cache_root=cache, quiet=True, executor=cluster)


def _upstream_only(one_blender, cache):
    """A cache holding the reference's entries up to export: only the render is left to do."""
    folder, shot, entries = one_blender
    for stage in ("voxelise", "simulate", "surface", "export"):
        shutil.copytree(entries[stage], cache / "tiny" / stage / entries[stage].name)
    return cache


def test_chunks_are_strided_at_most_16_frames_and_one_a_worker_at_least():
    frames = list(range(1, 41))
    parts = render.chunks(frames, 2)
    assert sorted(f for p in parts for f in p) == frames
    assert len(parts) == 3 and max(map(len, parts)) <= 16
    assert parts[0][:3] == [1, 4, 7]  # spread over the shot, not its first 14 frames
    assert render.chunks([1, 2, 3], 8) == [[1], [2], [3]]


def test_two_workers_render_the_one_blender_frames_pixel_for_pixel(one_blender, cluster, tmp_path, monkeypatch):
    folder, shot, ref = one_blender
    cache = _upstream_only(one_blender, tmp_path / "cache")
    monkeypatch.chdir(tmp_path)
    got = {r.stage: r for r in _run(shot, cache, cluster).run()}
    assert got["render"].state == "ran"
    entry = got["render"].entry
    want = sorted(p.name for p in (ref["render"] / "frames").glob("*.png"))
    assert want == [f"{f:04d}.png" for f in range(1, 5)]
    assert sorted(p.name for p in (entry / "frames").glob("*.png")) == want
    for name in want:
        assert (entry / "frames" / name).read_bytes() == (ref["render"] / "frames" / name).read_bytes(), name
    assert (entry / "tiny.blend").exists()  # saved once, by the first chunk
    # one Blender a chunk, each on its worker's share of the two cores
    logs = sorted(p.name for p in entry.glob("cycles_*.log"))
    assert logs == ["cycles_0001_2.log", "cycles_0002_2.log"]
    threads = {json.loads((entry / f"{log[:-4]}_job.json").read_text())["threads"] for log in logs}
    assert threads == {max(1, usable_cores() // 2)}
    assert not list(cache.rglob(TEMP_GLOB))
    assert sorted(p.name for p in tmp_path.glob("renders/*/[0-9]*.png")) == want


def test_a_failed_chunk_names_its_frames_and_worker_and_leaves_no_temp_file(
    one_blender, cluster, tmp_path, monkeypatch
):
    folder, shot, _ = one_blender
    cache = _upstream_only(one_blender, tmp_path / "cache")
    monkeypatch.chdir(tmp_path)
    # every Blender stopped while it loads the scene: no frame within a tenth of a second
    client = cluster.client()
    client.run(exec, f"import os; os.environ[{STALL_ENV!r}] = '0.1'")  # (a bound method would pickle a copy)
    try:
        with pytest.raises(TaskError) as caught:
            _run(shot, cache, cluster).run()
    finally:
        client.run(exec, f"import os; os.environ.pop({STALL_ENV!r}, None)")
    message = str(caught.value)
    assert "\n" not in message
    assert "render (cycles) frames 1, 3 of tiny" in message or "render (cycles) frames 2, 4 of tiny" in message
    assert "failed on worker tcp://" in message and "loading the scene" in message
    assert not list(cache.rglob(TEMP_GLOB))
