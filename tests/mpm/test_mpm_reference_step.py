"""The numpy reference step's return maps (mpmfx.bench.reference_step) against the solver's
own wp.funcs, particle by particle: the two must be the same formulas."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from mpmfx.bench.reference_step import sand_project, snow_clamp
from mpmfx.mpm import preset
from mpmfx.mpm.constitutive import pack_material
from tests.mpm.mpm_wp_kernels import eval_return_map


def _production(mat, F, jp):
    n = len(F)
    arrs = [
        wp.array(np.asarray(F, np.float32), dtype=wp.mat33, device="cpu"),
        wp.array(np.asarray(jp, np.float32), dtype=float, device="cpu"),
    ]
    outs = [
        wp.zeros(n, dtype=wp.mat33, device="cpu"),
        wp.zeros(n, dtype=float, device="cpu"),
        wp.zeros(n, dtype=wp.mat33, device="cpu"),
    ]
    wp.launch(eval_return_map, dim=n, inputs=[pack_material(mat), *arrs, *outs], device="cpu")
    return outs[0].numpy(), outs[1].numpy()


@pytest.mark.parametrize("fit", ["compression", "plane_strain", "repose"])
def test_sand_cone_projection_matches_production(fit):
    rng = np.random.default_rng(3)
    F = np.eye(3) + 0.08 * rng.standard_normal((64, 3, 3))
    F[np.linalg.det(F) <= 0] = np.eye(3)
    vc = np.where(rng.random(64) < 0.3, 0.02, 0.0)
    mat = preset("Granular", friction_fit=fit)
    F_ref, vc_ref = sand_project(mat, F, vc)
    F_prod, vc_prod = _production(mat, F.astype(np.float32), vc.astype(np.float32))
    np.testing.assert_allclose(F_prod, F_ref, atol=5e-5)
    np.testing.assert_allclose(vc_prod, vc_ref, atol=5e-6)


def test_snow_clamp_matches_production():
    rng = np.random.default_rng(4)
    F = np.eye(3) + 0.03 * rng.standard_normal((64, 3, 3))
    jp = 1.0 + 0.1 * rng.standard_normal(64)
    mat = preset("Mushy")
    F_ref, jp_ref = snow_clamp(mat, F, jp)
    F_prod, jp_prod = _production(mat, F.astype(np.float32), jp.astype(np.float32))
    np.testing.assert_allclose(F_prod, F_ref, atol=5e-5)
    np.testing.assert_allclose(jp_prod, jp_ref, rtol=5e-5)


def test_plane_strain_fit_is_mohr_coulomb_in_plane_strain():
    """sqrt(J2) = (3 / sqrt 2) alpha p on the cone; plane strain (Lode angle 0) Mohr-Coulomb
    is sqrt(J2) = p sin(phi), triaxial compression 2 sqrt(3) sin(phi) / (3 - sin(phi)) p."""
    for phi in (20.0, 30.0, 38.0):
        s = np.sin(np.radians(phi))
        ps = preset("Granular", friction_angle=phi, friction_fit="plane_strain").dp_alpha
        cc = preset("Granular", friction_angle=phi, friction_fit="compression").dp_alpha
        assert 3 / np.sqrt(2) * ps == pytest.approx(s)
        assert 3 / np.sqrt(2) * cc == pytest.approx(2 * np.sqrt(3) * s / (3 - s))
    # Klar et al. 2016's compression cone in plane strain is Mohr-Coulomb at 43.9 deg for 30
    cc30 = preset("Granular", friction_angle=30.0, friction_fit="compression").dp_alpha
    assert np.degrees(np.arcsin(3 / np.sqrt(2) * cc30)) == pytest.approx(43.9, abs=0.05)
    with pytest.raises(ValueError, match="friction_fit"):
        preset("Granular", friction_fit="triaxial")


def test_repose_fit_takes_the_angle_of_repose_as_the_friction_coefficient():
    """friction_fit "repose": sqrt(J2) / p = tan(phi) on the cone (mu = tan of the angle of
    repose, granular rheology's convention), i.e. the plane-strain cone at asin(tan(phi))."""
    for phi in (22.0, 31.6, 40.0):
        rp = preset("Granular", friction_angle=phi, friction_fit="repose").dp_alpha
        assert 3 / np.sqrt(2) * rp == pytest.approx(np.tan(np.radians(phi)))
        ps = preset(
            "Granular", friction_angle=np.degrees(np.arcsin(np.tan(np.radians(phi)))), friction_fit="plane_strain"
        ).dp_alpha
        assert rp == pytest.approx(ps)
    with pytest.raises(ValueError, match="angle of repose must be < 45"):
        preset("Granular", friction_angle=45.0, friction_fit="repose")
