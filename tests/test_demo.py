"""The demo (`bash setup.sh demo`): the default shot, every frame rendered, played at 24 fps."""

from __future__ import annotations

import re
from pathlib import Path

from mpmfx.config import RenderEngine
from mpmfx.shotfile import load_shot_config
from mpmfx.stages.render import frame_step

ROOT = Path(__file__).resolve().parents[1]


def test_the_demo_renders_every_frame_in_cycles_at_24_fps():
    (shot_path,) = re.findall(r"demo\).*? run (\S+\.toml)", (ROOT / "setup.sh").read_text())
    shot = load_shot_config(ROOT / shot_path)
    assert shot.render.engine is RenderEngine.CYCLES and shot.render.movie
    assert frame_step(shot) == 1  # no frame held: the movie moves at the shot's rate
    assert shot.shot.fps == 24
    assert shot_path in (ROOT / "README.md").read_text()  # the README's tour is of this shot
