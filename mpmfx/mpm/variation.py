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
import warp as wp

from .materials import VARIED_BY_MODE, VARIED_FIELDS, Material, Mode
from .stepper import WaveParams, wave_table

__all__ = ["VARIED_FIELDS", "VARIED_BY_MODE", "check_variation", "variation_factors", "device_factors", "state_factors"]

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


def state_factors(solver, data: dict) -> np.ndarray:
    """The (n, 5) device factors of a state's particles from its data (Solver._build_state:
    particle order), (1, 5) ones where the solver does not vary; sets the solver's CFL materials
    and first max_hardening (device_factors) and the device stepper's wave table."""
    if not solver.flags.varied:
        return np.ones((1, 5), np.float32)
    if "variation" not in data:
        raise ValueError("checkpoint: no 'variation' array, but this Solver varies its materials; re-simulate")
    out, solver._wave_materials, solver._first_hardening = device_factors(
        solver.materials, data["variation"], np.asarray(data["material"])
    )
    with wp.ScopedDevice(solver.device):  # into the stepper's table (a captured chunk keeps its address)
        wp.copy(solver._device_advance.waves, wp.array(wave_table(solver._wave_materials), dtype=WaveParams))
    return out
