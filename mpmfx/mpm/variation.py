"""Per-particle material variation, host side (docs/physics.md, "Variation").

A varied particle carries multipliers of its material's fields (Particles.variation, columns
VARIED_FIELDS). G2P multiplies its material row by the device factors made here
(constitutive.vary_material), the density multiplier goes into its mass at init, and the CFL
step follows the fastest particle: a snow particle's stiffness / density factor multiplies the
hardening factor it reports (the clock's max_hardening), and a sand material's wave speed takes
its particles' largest. Scenes without variation compile none of it (SceneFlags.varied).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .materials import Material, Mode

__all__ = ["VARIED_FIELDS", "VARIED_BY_MODE", "check_variation", "variation_factors", "device_factors"]

VARIED_FIELDS = ("youngs_modulus", "hardening", "friction_angle", "cohesion", "density")
"""The columns of a particle's variation multipliers, in order. Each multiplies the material's
field, except friction_angle's, which multiplies the friction coefficient tan(friction_angle):
any factor > 0 keeps the angle in [0, 90) degrees."""

VARIED_BY_MODE = {
    Mode.SNOW: ("youngs_modulus", "hardening", "density"),
    Mode.SAND: ("youngs_modulus", "friction_angle", "cohesion", "density"),
}
"""The fields a mode has a use for (water and tracers: none)."""

STIFF, DENSITY = VARIED_FIELDS.index("youngs_modulus"), VARIED_FIELDS.index("density")


def check_variation(variation, n: int, varied: bool) -> None:
    """ValueError unless `variation` is (n, 5) finite multipliers > 0 exactly when `varied`."""
    if (variation is not None) != varied:
        raise ValueError(
            "Particles.variation: give it exactly when the Solver was made with variation=True "
            f"(it was made with variation={varied})"
        )
    if variation is not None:
        var = np.asarray(variation)
        if var.shape != (n, len(VARIED_FIELDS)) or not np.all(np.isfinite(var) & (var > 0)):
            raise ValueError(
                f"Particles.variation: shape {var.shape}, expected ({n}, {len(VARIED_FIELDS)}) finite "
                f"multipliers > 0 of {', '.join(VARIED_FIELDS)}"
            )


def variation_factors(m: Material, mult: np.ndarray) -> np.ndarray:
    """What G2P multiplies a varied particle's material row by: (n, 5) float32 factors of
    (mu0 and lambda0, hardening, dp_alpha, cohesion) and its stiffness / density multiplier
    (c^2 of its waves relative to the material's), from (n, 5) multipliers of VARIED_FIELDS
    (> 0). Density acts on the particle's mass only (Solver.init_state)."""
    mult = np.asarray(mult, np.float64).reshape(-1, len(VARIED_FIELDS))
    alpha = np.ones(len(mult))
    phi = math.radians(m.friction_angle)
    if m.mode == Mode.SAND and phi > 0.0:
        f = mult[:, VARIED_FIELDS.index("friction_angle")]
        s = np.sin(np.arctan(math.tan(phi) * f))  # sin of the particle's friction angle
        if m.friction_fit == "repose":
            alpha = f  # alpha = sqrt(2) tan(phi) / 3
        elif m.friction_fit == "plane_strain":
            alpha = (math.sqrt(2.0) * s / 3.0) / m.dp_alpha
        else:
            alpha = (math.sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s)) / m.dp_alpha
    hard, coh = mult[:, VARIED_FIELDS.index("hardening")], mult[:, VARIED_FIELDS.index("cohesion")]
    return np.stack([mult[:, STIFF], hard, alpha, coh, mult[:, STIFF] / mult[:, DENSITY]], axis=1).astype(np.float32)


def device_factors(materials, mult: np.ndarray, material: np.ndarray) -> tuple[np.ndarray, tuple, float]:
    """(n, 5) device factors of particles in particle order (variation_factors of each one's
    material); the materials for the CFL step: a sand material with youngs_modulus times the
    largest stiffness / density multiplier among its particles (c = sqrt((lambda + 2 mu) / rho)
    scales by the root of that ratio), a snow one as it is (G2P reports each snow particle's
    factor times its hardening); and the clock's first max_hardening, the largest snow
    particle's factor (>= 1), for the substeps before G2P has reported one."""
    mult = np.asarray(mult, np.float32)
    out = np.ones((len(material), 5), np.float32)
    waves, hardening = list(materials), 1.0
    for i, m in enumerate(materials):
        rows = material == i
        if rows.any():
            out[rows] = variation_factors(m, mult[rows])
            scale = float(np.max(out[rows, 4]))
            if m.mode == Mode.SNOW:
                hardening = max(hardening, scale)
            else:
                waves[i] = dataclasses.replace(m, youngs_modulus=m.youngs_modulus * scale)
    return out, tuple(waves), hardening
