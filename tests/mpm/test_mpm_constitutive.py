"""Per-particle functions: B-spline weights and return maps, evaluated by the solver's
own wp.funcs (through tiny test kernels)."""

import math

import numpy as np
import pytest
import warp as wp

from mpmfx.mpm import Material, Mode, preset
from mpmfx.mpm.constitutive import pack_material
from tests.mpm.mpm_wp_kernels import eval_plastic_stress, eval_return_map, eval_weights


def _weights(fx):
    out = wp.zeros(len(fx), dtype=wp.mat33, device="cpu")
    wp.launch(eval_weights, dim=len(fx), inputs=[wp.array(fx, dtype=wp.vec3, device="cpu"), out], device="cpu")
    return out.numpy()  # (n, 3 offsets, 3 axes)


def test_bspline_partition_of_unity_and_reproduction():
    rng = np.random.default_rng(0)
    fx = rng.uniform(0.5, 1.5, size=(500, 3)).astype(np.float32)
    W = _weights(fx)
    assert np.all(W >= 0)
    np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-6)  # partition of unity
    # first moment: sum_k w_k (k - fx) = 0, so affine fields transfer exactly
    offsets = np.arange(3, dtype=np.float64)[None, :, None]
    np.testing.assert_allclose((W * (offsets - fx[:, None, :])).sum(axis=1), 0.0, atol=1e-6)
    # the tutorial's worked example: fx = 1.3 -> (0.02, 0.66, 0.32)
    np.testing.assert_allclose(_weights(np.full((1, 3), 1.3, np.float32))[0, :, 0], [0.02, 0.66, 0.32], atol=1e-6)


def _return_map(mat: Material, F, jp):
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
    return [o.numpy() for o in outs]


# confined compression with Stomakhin et al. 2013's constants: eps -> (Jp, hardening, sigma_axial, sigma_lateral)
SNOW_TABLE = [
    (0.025, 1.000, 1.00, -3889, -972),
    (0.05, 0.974, 1.29, -5026, -1256),
    (0.10, 0.923, 2.16, -8393, -2098),
    (0.20, 0.821, 6.02, -23406, -5852),
    (0.30, 0.718, 16.8, -65277, -16319),
]


def test_snow_confined_compression_matches_stomakhin_table():
    mat = Material(Mode.SNOW, youngs_modulus=1.4e5, poisson_ratio=0.2, density=400.0, hardening=10.0)
    F = np.array([np.diag([1.0, 1.0, 1.0 - row[0]]) for row in SNOW_TABLE])
    Fe, jp, sigma = _return_map(mat, F, np.ones(len(F)))
    for k, (eps, jp_ref, h_ref, s_ax, s_lat) in enumerate(SNOW_TABLE):
        assert jp[k] == pytest.approx(jp_ref, rel=1e-3, abs=5e-4), eps
        assert math.exp(10.0 * (1.0 - jp[k])) == pytest.approx(h_ref, rel=0.01), eps
        assert sigma[k][2, 2] == pytest.approx(s_ax, rel=0.01), eps
        assert sigma[k][0, 0] == pytest.approx(s_lat, rel=0.01), eps
        assert sigma[k][1, 1] == pytest.approx(s_lat, rel=0.01), eps
        # the elastic part never leaves the clamp box
        assert np.linalg.svd(Fe[k], compute_uv=False).min() >= 1 - 2.5e-2 - 1e-6


def test_elastic_preset_never_yields_and_jp_is_clamped():
    F = np.array([np.diag([1.0, 1.0, 0.5]), np.diag([1.6, 1.0, 1.0])])
    Fe, jp, _ = _return_map(preset("Elastic"), F, np.ones(2))
    np.testing.assert_allclose(Fe, F, atol=1e-6)
    np.testing.assert_allclose(jp, 1.0)
    _, jp, _ = _return_map(preset("Soft", jp_min=0.9), np.array([np.diag([1.0, 1.0, 0.5])]), np.ones(1))
    assert jp[0] == pytest.approx(0.9)


def _hencky(F):
    s = np.linalg.svd(F, compute_uv=False)
    return np.log(s)


def test_sand_return_map_lands_on_or_inside_the_cone():
    mat = preset("Granular")
    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.08 * rng.normal(size=(200, 3, 3))
    Fe, vc, _ = _return_map(mat, F, np.zeros(200))
    alpha = mat.dp_alpha
    k = (3 * mat.lambda0 + 2 * mat.mu0) / (2 * mat.mu0)
    for f in Fe:
        eps = _hencky(f)
        tr = eps.sum()
        dev = np.linalg.norm(eps - tr / 3)
        # inside the Drucker-Prager cone in Hencky space, or at the apex
        assert tr <= 1e-5 and dev + k * tr * alpha <= 1e-4
    # expansion is projected to the apex and remembered (volume correction)
    Fe, vc, _ = _return_map(mat, np.array([np.eye(3) * 1.05]), np.zeros(1))
    np.testing.assert_allclose(Fe[0], np.eye(3), atol=1e-5)
    assert vc[0] == pytest.approx(3 * math.log(1.05), rel=1e-4)
    _, vc, _ = _return_map(preset("Granular", volume_correction=False), np.array([np.eye(3) * 1.05]), np.zeros(1))
    assert vc[0] == 0.0


def test_cohesion_lets_sand_carry_tension():
    F = np.array([np.eye(3) * 1.0001])  # tr(log strain) = 3e-4 < cohesion 6e-4
    Fe, _, _ = _return_map(preset("CohesiveGranular"), F, np.zeros(1))
    np.testing.assert_allclose(Fe[0], F[0], atol=1e-6)
    Fe, _, _ = _return_map(preset("Granular"), F, np.zeros(1))
    np.testing.assert_allclose(Fe[0], np.eye(3), atol=1e-6)


def _stored_stress(mat: Material, F, jp):
    out = wp.zeros(len(F), dtype=wp.mat33, device="cpu")
    wp.launch(
        eval_plastic_stress,
        dim=len(F),
        device="cpu",
        inputs=[
            pack_material(mat),
            wp.array(np.asarray(F, np.float32), dtype=wp.mat33, device="cpu"),
            wp.array(np.asarray(jp, np.float32), dtype=float, device="cpu"),
            out,
        ],
    )
    return out.numpy()


def _random_f(n, lo, hi, seed):
    """n matrices R1 diag(s) R2^T, s uniform in [lo, hi], R1 and R2 random rotations (float64)."""
    rng = np.random.default_rng(seed)
    R1, R2 = [np.linalg.qr(rng.normal(size=(n, 3, 3)))[0] for _ in range(2)]
    R1 *= np.sign(np.linalg.det(R1))[:, None, None]  # proper rotations
    R2 *= np.sign(np.linalg.det(R2))[:, None, None]
    s = rng.uniform(lo, hi, size=(n, 3))
    return np.einsum("nij,nj,nkj->nik", R1, s, R2), s


@pytest.mark.parametrize("name, lo, hi", [("Mushy", 0.97, 1.01), ("Elastic", 0.7, 1.4)])
def test_snow_stress_for_p2g_matches_float64_inside_and_outside_the_polar_range(name, lo, hi):
    """snow_plastic takes the stress of a particle inside the clamp's range from three Newton
    steps of the polar rotation, of one outside it from the SVD: both must give the
    fixed-corotated stress of the elastic F, the polar one to float32 rounding."""
    mat = preset(name)
    F, s = _random_f(4000, lo, hi, seed=3)
    tau = _stored_stress(mat, F, np.ones(len(F)))
    Fe, jp, _ = _return_map(mat, F, np.ones(len(F)))  # the elastic F and Jp: clamped where the clamp fired
    h = np.exp(mat.hardening * (1.0 - jp.astype(np.float64)))[:, None, None]
    U, sig, Vt = np.linalg.svd(Fe.astype(np.float64))
    R = U @ Vt
    J = np.linalg.det(Fe.astype(np.float64))
    exact = h * (
        2 * mat.mu0 * (Fe - R) @ np.swapaxes(Fe, 1, 2) + (mat.lambda0 * (J - 1) * J)[:, None, None] * np.eye(3)
    )
    scale = np.abs(exact).max()
    polar = np.all((s > max(1 - mat.theta_c, 0.8)) & (s < min(1 + mat.theta_s, 1.25)), axis=1)
    assert 0.2 < polar.mean() < 0.8  # both branches are exercised
    err = np.abs(tau - exact).max(axis=(1, 2)) / scale
    assert err[polar].max() < 2e-5  # the float32 SVD's own error is ~1e-3 of the largest stress here
    assert err[~polar].max() < 5e-3
