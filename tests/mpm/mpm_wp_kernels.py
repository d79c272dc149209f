"""Tiny Warp kernels that evaluate the solver's own wp.funcs per particle, for unit tests."""

import warp as wp

from mpmfx.mpm.constitutive import (
    MaterialParams,
    bspline_weights,
    fixed_corotated_tau,
    from_sym,
    hardening_factor,
    sand_plastic,
    sand_return_map,
    snow_plastic,
    snow_return_map,
    unpack_f,
)


@wp.kernel
def eval_weights(fx: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    out[i] = bspline_weights(fx[i])


@wp.kernel
def eval_return_map(
    mat: MaterialParams,
    F: wp.array(dtype=wp.mat33),
    jp: wp.array(dtype=float),
    F_out: wp.array(dtype=wp.mat33),
    jp_out: wp.array(dtype=float),
    cauchy: wp.array(dtype=wp.mat33),
):
    """Return map of snow (mode 0) or sand (mode 1), then the Cauchy stress tau / J of
    the (hardened, for snow) elastic part."""
    i = wp.tid()
    r = wp.mat44(0.0)
    if mat.mode == 0:
        r = snow_return_map(mat, F[i], jp[i])
    else:
        r = sand_return_map(mat, F[i], jp[i])
    Fe = unpack_f(r)
    F_out[i] = Fe
    jp_out[i] = r[3, 3]
    h = hardening_factor(mat, r[3, 3])
    cauchy[i] = fixed_corotated_tau(Fe, mat.mu0 * h, mat.lambda0 * h) / wp.determinant(Fe)


@wp.kernel
def eval_plastic_stress(
    mat: MaterialParams, F: wp.array(dtype=wp.mat33), jp: wp.array(dtype=float), tau: wp.array(dtype=wp.mat33)
):
    """The Kirchhoff stress a return map hands the next P2G (snow_plastic's or sand_plastic's)."""
    i = wp.tid()
    if mat.mode == 0:
        Fe, jp_new, t = snow_plastic(mat, F[i], jp[i])
        tau[i] = from_sym(t)
    else:
        Fe, vc_new, t = sand_plastic(mat, F[i], jp[i])
        tau[i] = from_sym(t)
