"""Voxelise checks placements against the solver's walls (`Shot.wall_box`), the planes the
solver holds material at and the render draws the ground and the tank on."""

from mpmfx.cli import main
from mpmfx.config import Shot
from tests.conftest import write_tiny_shot


def test_the_wall_box_is_three_cells_inside_the_domain_in_metres():
    shot = Shot.model_validate(
        {"shot": {"name": "s"}, "domain": {"origin": [-0.5, -0.0625, -0.5], "size": 1.0, "grid_n": 48}}
    )
    lo, hi = shot.wall_box()
    assert lo == (-0.4375, 0.0, -0.4375) and hi == (0.4375, 0.875, 0.4375)


def test_particles_placed_beyond_a_wall_are_reported_with_the_shift_that_fixes_them(tmp_path, capsys):
    # the tiny shot's cube (0.25 m, grid 24 over 1 m): its -x face at x = 0.03, the wall at 0.125
    # (one below the floor is refused outright: mpmfx.geometry.mesh.check_in_domain)
    shot = write_tiny_shot(tmp_path)
    shot.write_text(shot.read_text().replace("translate = [0.5, 0.45, 0.5]", "translate = [0.155, 0.45, 0.5]"))
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c")]) == 0
    err = capsys.readouterr().err
    assert "objects.cube:" in err and "beyond the solver's walls" in err and "the floor is y = 0.125 m" in err
    assert "translate it by (0.09" in err
    write_tiny_shot(tmp_path)  # placed above the floor: no warning
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c")]) == 0
    assert "beyond the solver's walls" not in capsys.readouterr().err
