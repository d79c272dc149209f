"""Shared fixtures: a tiny shot that runs end to end on a 2-core CPU in seconds."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session", autouse=True)
def _run_in_tmp(tmp_path_factory):
    """The suite runs in a folder of its own: a run publishes renders/<shot>/ and
    published/<shot> relative to the working directory, and the suite must not leave them in
    the checkout. For the whole test run, so module fixtures that run shots are covered too."""
    import os

    cwd = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("cwd"))
    yield
    os.chdir(cwd)


TINY = """
[shot]
name = "tiny"
frame_start = 1
frame_end = {frame_end}
fps = 24

[domain]
origin = [0.0, 0.0, 0.0]
size = 1.0
grid_n = 24

[[objects]]
name = "cube"
mesh = "cube.obj"
material = "{material}"
translate = [0.5, 0.45, 0.5]
velocity = [0.0, -0.5, 0.0]

[voxelise]
ppc = 8

[solver]
cfl = 0.4
damping = 1.0
walls = "slip"
checkpoint_every = 2

[surface]
smooth_iters = 1

[render]
engine = "preview"   # seconds a frame; tests/render/ runs the Cycles path itself
width = 160
height = 120
movie = false
"""


def write_tiny_shot(folder: Path, *, material: str = "Elastic", frame_end: int = 6, extra: str = "") -> Path:
    import trimesh

    trimesh.creation.box(extents=[0.25, 0.25, 0.25]).export(folder / "cube.obj")
    path = folder / "tiny.toml"
    path.write_text(TINY.format(material=material, frame_end=frame_end) + extra)
    return path


@pytest.fixture
def tiny_shot(tmp_path: Path) -> Path:
    return write_tiny_shot(tmp_path)
