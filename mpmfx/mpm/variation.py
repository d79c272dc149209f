"""Per-particle material variation, host side (docs/physics.md, "Variation").

A varied particle carries multipliers of its material's fields (Particles.variation, columns
VARIED_FIELDS). G2P multiplies its material row by the device factors made here
(constitutive.vary_material), the density multiplier goes into its mass at init, and the CFL
step is taken with the stiffest particle's moduli. Scenes without variation compile none of it
(SceneFlags.varied).
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
    """What G2P multiplies a varied particle's material row by: (n, 4) float32 factors of
    (mu0 and lambda0, hardening, dp_alpha, cohesion), from (n, 5) multipliers of VARIED_FIELDS
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
    cols = [mult[:, STIFF], mult[:, VARIED_FIELDS.index("hardening")], alpha, mult[:, VARIED_FIELDS.index("cohesion")]]
    return np.stack(cols, axis=1).astype(np.float32)


def device_factors(materials, mult: np.ndarray, material: np.ndarray) -> tuple[np.ndarray, tuple]:
    """(n, 4) device factors of particles in particle order (variation_factors of each one's
    material), and the materials for the CFL step: each with youngs_modulus times the largest
    stiffness / density multiplier among its particles, so dt follows the fastest wave
    (c = sqrt((lambda + 2 mu) / rho) scales by sqrt of that ratio)."""
    mult = np.asarray(mult, np.float32)
    out = np.ones((len(material), 4), np.float32)
    waves = list(materials)
    for i, m in enumerate(materials):
        rows = material == i
        if rows.any():
            out[rows] = variation_factors(m, mult[rows])
            scale = float(np.max(mult[rows, STIFF].astype(np.float64) / mult[rows, DENSITY]))
            waves[i] = dataclasses.replace(m, youngs_modulus=m.youngs_modulus * scale)
    return out, tuple(waves)
