"""A shot with an animated collider: bad input (an animation short of the shot, a collider that
cannot be animated) stops with exit 2 and a message naming the file and the key."""

from __future__ import annotations

from mpmfx.cli import main
from tests.anim_assets import growing_cube_usd
from tests.conftest import write_tiny_shot

COLLIDER = """
[[colliders]]
name = "walker"
shape = "{shape}"
mesh = "walker.usda"
animated = true
"""


def test_an_animation_short_of_the_shot_is_exit_2_naming_file_and_key(tmp_path, capsys):
    growing_cube_usd(tmp_path / "walker.usda", centre=(0.5, 0.2, 0.5), half0=0.1, speed=0.1, frames=range(1, 4))
    shot = write_tiny_shot(tmp_path, frame_end=6, extra=COLLIDER.format(shape="mesh"))
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(tmp_path / "c"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "colliders[0].mesh (walker)" in err and "walker.usda" in err and "time codes 1..3" in err


def test_only_a_mesh_collider_is_animated(tmp_path, capsys):
    growing_cube_usd(tmp_path / "walker.usda", centre=(0.5, 0.2, 0.5), half0=0.1, speed=0.1, frames=range(1, 8))
    shot = write_tiny_shot(tmp_path, extra=COLLIDER.format(shape="box"))
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c"), "-q"]) == 2
    assert "colliders[0].animated" in capsys.readouterr().err


def test_a_shot_without_animated_colliders_keeps_its_cache_key_inputs(tmp_path):
    from mpmfx.shotfile import load_shot_config
    from mpmfx.stages import simulate

    box = '\n[[colliders]]\nname = "paddle"\nshape = "box"\n'
    shot = load_shot_config(write_tiny_shot(tmp_path, extra=box))
    assert len(shot.colliders) == 1
    assert all("animated" not in c for c in simulate.params(shot)["colliders"])
