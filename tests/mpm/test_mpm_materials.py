"""Material table, presets and solver-config validation (no kernels)."""

import dataclasses

import pytest

from mpmfx.mpm import PRESETS, Material, Mode, SolverConfig, WallType, preset

# the material table of the tutorial "Material Point Method: Step by Step": name -> (mode, E, hardening)
GUIDE_TABLE = {
    "Soft": (Mode.SNOW, 1500, 4),
    "Mushy": (Mode.SNOW, 600, 2),
    "Goopy": (Mode.SNOW, 250, 1),
    "Wet": (Mode.SNOW, 150, 0.7),
    "Slush": (Mode.SNOW, 90, 0.5),
    "Elastic": (Mode.SNOW, 1200, 0),
    "Granular": (Mode.SAND, 400, 0),
    "CohesiveGranular": (Mode.SAND, 400, 0),
}


@pytest.mark.parametrize("name", sorted(GUIDE_TABLE))
def test_presets_match_the_guide_table(name):
    mode, E, xi = GUIDE_TABLE[name]
    m = PRESETS[name]
    assert (m.mode, m.youngs_modulus, m.hardening) == (mode, E, xi)


def test_special_preset_rows():
    assert PRESETS["Elastic"].plastic is False  # yields at 1e9: the clamp never fires
    assert all(PRESETS[n].plastic for n in ("Soft", "Mushy", "Goopy", "Wet", "Slush"))
    assert PRESETS["Granular"].friction_angle == 38 and PRESETS["Granular"].cohesion == 0
    assert PRESETS["CohesiveGranular"].cohesion == 0.0006
    assert PRESETS["Water"].mode == Mode.WATER and PRESETS["Water"].bulk_modulus == 100
    assert PRESETS["Tracer"].mode == Mode.TRACER


def test_preset_overrides_and_case():
    m = preset("soft", hardening=0.0, youngs_modulus=900.0)
    assert m.hardening == 0.0 and m.youngs_modulus == 900.0 and m.mode == Mode.SNOW
    assert PRESETS["Soft"].hardening == 4  # the table itself is untouched


def test_preset_errors_name_the_problem_and_the_choices():
    with pytest.raises(ValueError, match="unknown material preset 'Ice'.*Soft.*Water"):
        preset("Ice")
    with pytest.raises(ValueError, match="youngs_modulos.*valid fields:.*youngs_modulus"):
        preset("Soft", youngs_modulos=3.0)


def test_material_validation_names_the_field():
    with pytest.raises(ValueError, match="poisson_ratio"):
        Material(Mode.SNOW, poisson_ratio=0.5)
    with pytest.raises(ValueError, match="youngs_modulus"):
        dataclasses.replace(PRESETS["Soft"], youngs_modulus=-1.0)
    with pytest.raises(ValueError, match="Material.mode"):
        Material(7)


def test_lame_parameters_and_wave_speed():
    m = Material(Mode.SNOW, youngs_modulus=1.4e5, poisson_ratio=0.2, density=400.0)
    assert m.mu0 == pytest.approx(58333.33, rel=1e-6)
    assert m.lambda0 == pytest.approx(38888.89, rel=1e-6)
    # Stomakhin et al. 2013's snow: 19.7 m/s at h = 1, 146 m/s at h = e^4 (hardened moduli)
    assert m.wave_speed() == pytest.approx(19.7, rel=0.01)
    assert m.wave_speed(hardening_factor=2.718281828**4) == pytest.approx(146, rel=0.01)


def test_solver_config_validation():
    cfg = SolverConfig(walls=["sticky"] * 6, out_of_domain="remove")
    assert cfg.walls == (WallType.STICKY,) * 6 and cfg.out_of_domain.value == "remove"
    with pytest.raises(ValueError, match="walls: 4 entries"):
        SolverConfig(walls=(WallType.SLIP,) * 4)
    with pytest.raises(ValueError, match="out_of_domain"):
        SolverConfig(out_of_domain="wrap")
    with pytest.raises(ValueError, match="cfl"):
        SolverConfig(cfl=0.0)
    with pytest.raises(ValueError, match="damping.*rate"):
        SolverConfig(damping=-1.0)


def test_volume_recovery_rate_is_validated():
    with pytest.raises(ValueError, match="volume_recovery_rate.*rate"):
        preset("Water", volume_recovery=True, volume_recovery_rate=-1.0)
