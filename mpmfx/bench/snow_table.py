"""Snow confined compression: the solver's own return map, per particle.

The reference table is derived from Stomakhin et al. 2013's model and constants
(docs/physics.md, "Validation").

One thread per table row drives F = diag(1, 1, 1 - eps) quasi-statically in small increments
through `snow_return_map` (the Stomakhin clamp the solver's G2P calls) and evaluates the
hardened fixed-corotated stress of the elastic part, sigma = tau(Fe) / det(Fe).
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from mpmfx.mpm import preset
from mpmfx.mpm.constitutive import MaterialParams, hardening_factor, pack_material, snow_return_map, solid_tau, unpack_f

# (eps, Jp, hardening h, sigma_axial, sigma_lateral), Stomakhin et al. 2013 defaults, derived
REFERENCE = np.array(
    [
        (0.025, 1.000, 1.00, -3889.0, -972.0),
        (0.05, 0.974, 1.29, -5026.0, -1256.0),
        (0.10, 0.923, 2.16, -8393.0, -2098.0),
        (0.20, 0.821, 6.02, -23406.0, -5852.0),
        (0.30, 0.718, 16.8, -65277.0, -16319.0),
    ]
)


@wp.kernel(enable_backward=False)
def confined_compression(
    mat: MaterialParams, eps: wp.array(dtype=float), increments: int, out: wp.array2d(dtype=float)
):
    """out[i] = (Jp, h, sigma_zz, sigma_xx) after compressing to 1 - eps[i] along z."""
    i = wp.tid()
    F = wp.identity(n=3, dtype=float)
    jp = float(1.0)
    prev = float(1.0)
    for s in range(increments):
        now = 1.0 - eps[i] * float(s + 1) / float(increments)
        F = wp.diag(wp.vec3(1.0, 1.0, now / prev)) * F  # trial F of this increment
        prev = now
        r = snow_return_map(mat, F, jp)
        F = unpack_f(r)
        jp = r[3, 3]
    sigma = solid_tau(mat, F, jp) / wp.determinant(F)
    out[i, 0] = jp
    out[i, 1] = hardening_factor(mat, jp)
    out[i, 2] = sigma[2, 2]
    out[i, 3] = sigma[0, 0]


def _run(mat, eps, increments: int, dev) -> np.ndarray:
    out = wp.zeros((len(REFERENCE), 4), dtype=float, device=dev)
    wp.launch(confined_compression, dim=len(REFERENCE), inputs=[pack_material(mat), eps, increments, out], device=dev)
    return out.numpy().astype(np.float64)


def snow_compression(*, increments: int = 1, drift_increments: int = 200, device=None) -> dict:
    """Run the table in `increments` steps; returns a row dict with `error` = max relative
    error over Jp, h and both stresses (all rows), `table` = the measured (eps, Jp, h,
    s_axial, s_lateral) rows, and `error_after_<drift_increments>` = the same error when
    the path is cut into that many return-map calls (what a simulation does: it shows any
    drift of the SVD round trip U diag(S) V^T that the return map applies every substep)."""
    mat = preset(
        "Soft", youngs_modulus=1.4e5, poisson_ratio=0.2, density=400.0, hardening=10.0, theta_c=2.5e-2, theta_s=7.5e-3
    )
    dev = wp.get_device(device)
    eps = wp.array(REFERENCE[:, 0].astype(np.float32), dtype=float, device=dev)
    drift = _run(mat, eps, drift_increments, dev)  # first launch compiles
    t0 = time.perf_counter()
    got = _run(mat, eps, increments, dev)
    wall = time.perf_counter() - t0
    rel = np.abs(got - REFERENCE[:, 1:]) / np.abs(REFERENCE[:, 1:])
    rel_drift = np.abs(drift - REFERENCE[:, 1:]) / np.abs(REFERENCE[:, 1:])
    return {
        "case": "snow_compression",
        "grid_n": 0,
        "cfl": 0.0,
        "ppc": 1,
        "particles": len(REFERENCE),
        "substeps": increments,
        "error": float(rel.max()),
        "metric": "max rel err (Jp,h,sigma)",
        "wall_s": wall,
        "Mparticle_substeps_per_s": len(REFERENCE) * increments / wall / 1e6,
        "device": dev.name if dev.is_cuda else "cpu",
        f"error_after_{drift_increments}": float(rel_drift.max()),
        "table": np.column_stack([REFERENCE[:, 0], got]).round(4).tolist(),
    }
