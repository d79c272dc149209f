"""The export's VDB grids, made in child processes (mpmfx.stages.grids): what a child finds
wrong reaches the run with its words, and a child that dies takes no later frame with it."""

import os

import numpy as np
import pytest

from mpmfx.cache import Entry
from mpmfx.io.frames import GroupSurface, SurfaceFrame
from mpmfx.io.vdb import read_vdb
from mpmfx.shotfile import load_shot_config
from mpmfx.stages import grids
from mpmfx.stages.parallel import FrameJob
from tests.conftest import write_tiny_shot


def leaves(value: float) -> GroupSurface:
    """One 8^3 leaf of the level set `value` (and a mesh of nothing)."""
    blocks = np.full((1, 8, 8, 8), value, np.float32)
    blocks[0, :4] = -0.01
    return GroupSurface(
        vertices=np.zeros((0, 3), np.float32),
        faces=np.zeros((0, 3), np.int32),
        normals=np.zeros((0, 3), np.float32),
        velocities=np.zeros((0, 3), np.float32),
        voxel_size=0.01,
        background=0.03,
        block_ijk=np.zeros((1, 3), np.int64),
        blocks=blocks,
        inside_ijk=np.zeros((0, 3), np.int64),
        vel_blocks=np.zeros((1, 8, 8, 8, 3), np.float16),
    )


def job(tmp_path, groups: dict) -> FrameJob:
    surf = Entry(tmp_path / "surface", "surface", "s", {})
    SurfaceFrame(groups).write(surf.frame_path(1, SurfaceFrame.EXT))
    out = Entry(tmp_path / "export", "export", "e", {})
    return FrameJob(load_shot_config(write_tiny_shot(tmp_path)), out, {"surface": surf, "simulate": surf})


def test_each_group_is_written_by_a_child_and_a_childs_error_names_the_grid(tmp_path, monkeypatch):
    monkeypatch.delenv(grids.IN_PROCESS_ENV, raising=False)
    j = job(tmp_path, {"good": leaves(0.01), "bad": leaves(np.nan)})
    pending = grids.submit(j, 1, ["good", "bad"])
    assert grids._pool is not None  # children, not this process
    with pytest.raises(ValueError, match=r"bad/0001\.vdb: grid 'surface': values contain NaN"):
        grids.results(pending)
    assert set(read_vdb(j.entry.root / "vdb/good/0001.vdb")["grids"]) == {"surface", "vel"}
    assert not (j.entry.root / "vdb/bad/0001.vdb").exists()


def test_a_child_that_dies_takes_no_later_frame_with_it(tmp_path, monkeypatch):
    monkeypatch.delenv(grids.IN_PROCESS_ENV, raising=False)
    j = job(tmp_path, {"all": leaves(0.01)})
    died = grids._children().submit(os._exit, 1)  # as a child killed, or out of memory
    with pytest.raises(Exception, match="terminated abruptly"):
        grids.results({"all": died})
    assert grids.results(grids.submit(j, 1, ["all"])) == {
        "all": {"surface": "vdb/all/0001.vdb", "vel": "vdb/all/0001.vdb"}
    }
