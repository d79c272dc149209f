"""The shot schema: what an artist's typo produces."""

from pathlib import Path

import pytest

from mpmfx.config import ShotError
from mpmfx.shotfile import load_shot_config
from tests.conftest import write_tiny_shot

REPO = Path(__file__).resolve().parents[1]


def test_example_shots_validate():
    shots = sorted((REPO / "pipeline" / "shots").glob("*.toml"))
    assert shots, "pipeline/shots/ must hold example shots"
    for path in shots:
        shot = load_shot_config(path)
        for obj in shot.objects:
            assert shot.resolve(obj.mesh).is_file()


def test_sand_collapse_rests_without_the_ridges_of_too_little_smoothing():
    """Fewer than 8 smoothing steps leave ridges down the pile at rest (lab/ridge_slope.py)."""
    from mpmfx.stages.surface import surface_params

    sand = load_shot_config(REPO / "pipeline" / "shots" / "sand_collapse.toml")
    assert surface_params(sand, "Granular").smooth_iters >= 8


def test_jelly_splash_keeps_every_drop_of_its_spray():
    """No blob of water is removed as a speck: the spray stays drops, not only the sheets."""
    from mpmfx.stages.surface import surface_params

    splash = load_shot_config(REPO / "pipeline" / "shots" / "jelly_splash.toml")
    assert surface_params(splash, "Water").min_feature_particles == 0


def test_defaults_and_units(tiny_shot):
    shot = load_shot_config(tiny_shot)
    assert shot.domain.grid_n == 24 and shot.solver.gravity == (0.0, -9.81, 0.0)
    assert list(shot.frames) == [1, 2, 3, 4, 5, 6]


def test_unknown_key_names_file_key_and_suggestion(tmp_path):
    path = write_tiny_shot(tmp_path, extra="\n[export]\npointz = true\n")
    with pytest.raises(ShotError) as err:
        load_shot_config(path)
    msg = str(err.value)
    assert str(path) in msg and "export.pointz" in msg and "did you mean 'points'" in msg


def test_wrong_type_and_range(tiny_shot):
    with pytest.raises(ShotError, match=r"solver.cfl: 3.0 must be in \(0, 1\]"):
        load_shot_config(tiny_shot, ["solver.cfl=3.0"])
    with pytest.raises(ShotError, match=r"domain.grid_n"):
        load_shot_config(tiny_shot, ["domain.grid_n=lots"])


def test_missing_mesh_names_the_object(tmp_path):
    path = write_tiny_shot(tmp_path)
    (tmp_path / "cube.obj").unlink()
    with pytest.raises(ShotError, match=r"objects\[0\].mesh: file not found: .*cube.obj"):
        load_shot_config(path)


def test_missing_shot_file():
    with pytest.raises(ShotError, match="shot file not found"):
        load_shot_config("nope/missing.toml")


def test_bad_toml(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[shot\nname='x'")
    with pytest.raises(ShotError, match="not valid TOML"):
        load_shot_config(p)


def test_set_overrides_any_field(tiny_shot):
    shot = load_shot_config(
        tiny_shot,
        ["solver.cfl=0.25", "objects.0.material=Water", "surface.group=all", "objects.0.overrides.youngs_modulus=3000"],
    )
    assert shot.solver.cfl == 0.25 and shot.objects[0].material == "Water"
    assert shot.surface.group.value == "all" and shot.objects[0].overrides == {"youngs_modulus": 3000}
    with pytest.raises(ShotError, match="not an index"):
        load_shot_config(tiny_shot, ["objects.7.material=Water"])


def test_impossible_time_step(tiny_shot):
    with pytest.raises(ShotError, match="dt_max .* longer than one frame"):
        load_shot_config(tiny_shot, ["solver.dt_max=0.5"])
    with pytest.raises(ShotError, match="solver.dt_min: .* not above dt_max"):
        load_shot_config(tiny_shot, ["solver.dt_min=0.001", "solver.dt_max=0.0001"])


def test_frame_range(tiny_shot):
    with pytest.raises(ShotError, match="frame_end"):
        load_shot_config(tiny_shot, ["shot.frame_end=0"])


def test_a_shot_and_the_python_api_share_the_solver_defaults(tiny_shot):
    """One set of defaults: fields a shot leaves unset are SolverConfig's own."""
    import dataclasses

    from mpmfx.mpm.config import STANDARD_GRAVITY, SolverConfig

    shot = load_shot_config(tiny_shot)  # sets cfl, damping, walls; leaves the rest unset
    cfg, default = shot.solver_config(), SolverConfig()
    for f in dataclasses.fields(SolverConfig):
        if f.name not in {"grid_n", "gravity", "cfl", "damping", "walls"}:
            assert getattr(cfg, f.name) == getattr(default, f.name), f.name
    assert cfg.gravity == (0.0, -STANDARD_GRAVITY / shot.domain.size, 0.0) == default.gravity  # a 1 m domain


def test_the_wall_layer_is_metres_in_a_shot(tiny_shot):
    """solver.wall_layer is a length in the world: 2 cm in a 4 m domain is 0.005 of it."""
    shot = load_shot_config(tiny_shot, ["domain.size=4.0", "solver.wall_layer=0.02"])
    assert shot.solver_config().wall_layer == pytest.approx(0.005)


def test_solver_ranges_are_checked_once_and_named_as_shot_keys(tiny_shot):
    for override, key in (
        ("solver.wall_layer=-0.01", "solver.wall_layer"),
        ("solver.cfl=1.5", "solver.cfl"),
        ("solver.damping=-1.0", "solver.damping"),
        ("solver.flip=1.5", "solver.flip"),
        ("solver.dt_min=0.5", "solver.dt_min"),
        ("domain.grid_n=4", "domain.grid_n"),
    ):
        with pytest.raises(ShotError, match=f"tiny.toml: {key}: "):
            load_shot_config(tiny_shot, [override])


NON_FINITE = [
    "solver.gravity=[0.0, inf, 0.0]",
    "domain.origin=[nan, 0.0, 0.0]",
    "objects.0.translate=[inf, 0, 0]",
    "objects.0.velocity=[0.0, -inf, 0.0]",
    "solver.damping=inf",
    "solver.time_scale=inf",
    "domain.size=inf",
    "surface.dilate=nan",
    "objects.0.overrides.youngs_modulus=inf",
    "surface.voxel_size=inf",
    "shot.fps=nan",
]


@pytest.mark.parametrize("override", NON_FINITE)
def test_non_finite_numbers_are_refused_naming_the_key(tiny_shot, override):
    key = override.split("=")[0]
    with pytest.raises(ShotError) as err:
        load_shot_config(tiny_shot, [override])
    assert key.replace(".0.", "[0].") in str(err.value) and "finite" in str(err.value)


@pytest.mark.parametrize(
    "override", ['solver.cfl="0.3"', 'domain.grid_n="32"', 'objects.0.velocity=["1", 0, 0]', 'export.vdb="yes"']
)
def test_numbers_given_as_strings_are_errors(tiny_shot, override):
    with pytest.raises(ShotError, match="quotes"):
        load_shot_config(tiny_shot, [override])


def test_cli_non_finite_exits_2(tiny_shot, tmp_path, capsys):
    from mpmfx.cli import main

    assert main(["run", str(tiny_shot), "--set", "solver.damping=inf", "--cache", str(tmp_path / "c")]) == 2
    assert "solver.damping" in capsys.readouterr().err


def test_a_bad_material_override_names_the_shot_file_and_the_object(tiny_shot):
    """An angle of repose of 50 deg has no friction coefficient under the default fit: the
    message names the shot file, the object and the limit."""
    from mpmfx.stages.simulate import materials

    shot = load_shot_config(tiny_shot, ["objects.0.material=Granular", "objects.0.overrides.friction_angle=50"])
    with pytest.raises(ShotError, match=rf"{tiny_shot.name}: objects\[0\] .*friction_angle = 50.*must be < 45"):
        materials(shot)


def test_sharp_edges_auto_leaves_fluids_round(tmp_path):
    """surface.sharp_edges = "auto" (the default): sharp edges for each surface group with no
    fluid in it. Water holds no edge, and its narrow faces against a tank's walls sharpened in
    pieces (ledges; docs/benchmarks.md, "Sharp edges and corners"); true and false apply to every group."""
    from mpmfx.stages.surface import surface_params

    pool = '\n[[objects]]\nname = "pool"\nmesh = "cube.obj"\nmaterial = "Water"\ntranslate = [0.5, 0.15, 0.5]\n'
    path = write_tiny_shot(tmp_path, extra=pool)
    shot = load_shot_config(path)
    assert shot.surface.sharp_edges == "auto" and shot.surface_groups() == ["Elastic", "Water"]
    assert (shot.sharp_edges_for("Elastic"), shot.sharp_edges_for("Water")) == (True, False)
    assert (surface_params(shot, "Elastic").sharp_edges, surface_params(shot, "Water").sharp_edges) == (True, False)
    assert not load_shot_config(path, ["surface.group=all"]).sharp_edges_for("all")  # one surface, water in it
    assert load_shot_config(path, ["surface.group=object"]).sharp_edges_for("cube")
    assert load_shot_config(path, ["surface.sharp_edges=true"]).sharp_edges_for("Water")
    assert not load_shot_config(path, ["surface.sharp_edges=false"]).sharp_edges_for("Elastic")
    assert not load_shot_config(path, ["surface.smooth_iters=0"]).sharp_edges_for("Elastic")  # found while smoothing
    with pytest.raises(
        ShotError, match="surface.sharp_edges' = 'sometimes': Input should be 'auto' or a valid boolean"
    ):
        load_shot_config(path, ["surface.sharp_edges=sometimes"])


def test_bracketed_list_items_and_internal_keys_get_a_message_not_a_traceback(tmp_path, capsys):
    from mpmfx.cli import main
    from tests.conftest import write_tiny_shot

    shot = write_tiny_shot(tmp_path)
    args = ["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "cache")]
    assert main([*args, "--set", "objects[0].overrides={hardening=10}"]) == 2
    assert "--set objects.0.overrides={hardening=10}" in capsys.readouterr().err
    assert main([*args, "--set", "bogus_key=1"]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'bogus_key'" in err and "base_dir" not in err and "source" not in err


@pytest.mark.parametrize(
    "override, words",
    [
        ("domain.size=1e300", "domain.size"),
        ("domain.size.x=1", "--set domain.size=VALUE"),
        ("solver.gravity=[0,-1e30,0]", "solver.gravity"),
        ("shot.name=" + "a" * 300, "at most 100 characters"),
        ("surface.voxel_size=100", "surface.voxel_size"),
    ],
)
def test_absurd_values_are_bad_input_naming_the_key(tmp_path, capsys, override, words):
    from mpmfx.cli import main
    from tests.conftest import write_tiny_shot

    shot = write_tiny_shot(tmp_path)
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c"), "--set", override]) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


def test_a_step_set_by_speed_names_the_velocity_not_the_stiffness(tmp_path, capsys):
    from mpmfx.cli import main
    from tests.conftest import write_tiny_shot

    shot = write_tiny_shot(tmp_path, frame_end=2)
    args = ["run", str(shot), "--until", "simulate", "--cache", str(tmp_path / "c"), "-q"]
    assert main([*args, "--set", "objects.0.angular_velocity=[0,0,1e7]"]) == 1  # 1.7e6 m/s at its corners
    err = capsys.readouterr().err
    assert "objects[0].angular_velocity" in err and "soften" not in err


@pytest.mark.parametrize("key", ["objects.0.velocity", "emitters.0.velocity"])
def test_a_speed_no_step_can_follow_is_bad_input_naming_the_key(tmp_path, capsys, key):
    from mpmfx.cli import main
    from tests.conftest import write_tiny_shot

    emitter = '[[emitters]]\nname = "hose"\nrate = 0.001\nend_time = 0.1\ntranslate = [0.5, 0.8, 0.5]\n'
    shot = write_tiny_shot(tmp_path, frame_end=2, extra=emitter)
    assert main(["run", str(shot), "--cache", str(tmp_path / "c"), "--set", f"{key}=[0,-1e6,0]"]) == 2
    err = capsys.readouterr().err
    assert key.replace(".0.", "[0].") in err and "solver.dt_min" in err and "at most" in err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("domain", ["nan,0,0,1", "0,0,0,inf", "0,0,0,-1"])
def test_check_refuses_a_domain_that_is_not_finite_naming_the_option(capsys, domain):
    from pathlib import Path

    from mpmfx.cli import main

    asset = Path(__file__).resolve().parents[1] / "assets" / "snowball.obj"
    assert main(["check", str(asset), f"--domain={domain}"]) == 2
    assert "--domain" in capsys.readouterr().err


FAR = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1e30\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 1 3 4\n"  # a vertex at 1e30 m
COLLIDER = '\n[[colliders]]\nname = "rock"\nshape = "mesh"\nmesh = "{mesh}"\n'


@pytest.mark.parametrize(
    "where, mesh, words",
    [
        ("object", FAR, ["objects.cube", "absurdly far out"]),
        ("collider", FAR, ["colliders[0].mesh (rock)", "absurdly far out"]),
        ("collider", "garbage", ["colliders[0].mesh (rock)", "no triangles"]),
    ],
)
def test_a_broken_asset_is_bad_input_naming_the_key_before_anything_runs(tmp_path, capsys, where, mesh, words):
    from mpmfx.cli import main
    from tests.conftest import write_tiny_shot

    (tmp_path / "bad.obj").write_text(mesh)
    shot = write_tiny_shot(tmp_path, frame_end=2, extra=COLLIDER.format(mesh="bad.obj") if where == "collider" else "")
    if where == "object":
        shot.write_text(shot.read_text().replace('mesh = "cube.obj"', 'mesh = "bad.obj"'))
    assert main(["run", str(shot), "--cache", str(tmp_path / "c"), "-q"]) == 2
    err = capsys.readouterr().err
    assert all(w in err for w in words) and "flat" not in err and "Traceback" not in err, err
    assert not (tmp_path / "c").exists()


def test_check_calls_a_far_vertex_broken_not_flat(tmp_path, capsys):
    from mpmfx.cli import main

    (tmp_path / "far.obj").write_text(FAR)
    assert main(["check", str(tmp_path / "far.obj")]) == 2
    err = capsys.readouterr().err
    assert "absurdly far out" in err and "flat" not in err
