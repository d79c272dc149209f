"""The solver's input: particles on the host, and the checks they must pass before upload."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .variation import check_variation


@dataclass
class Particles:
    """Solver input (host, numpy).

    x: (n, 3) float32 domain units, inside [0, 1]; v: (n, 3) float32 domain/s;
    volume: (n,) float32 rest volume, domain^3 (mass = volume * material density);
    material: (n,) int32 index into the solver's materials; body: (n,) int32 object id;
    birth: (n,) float32 shot time (s) at which each particle enters, or None (all there at the
    start): one with birth > 0 is dormant until the first substep starting at or after it
    (emission.py), with its x and v then.
    variation: (n, 5) float32 multipliers (> 0) of each particle's material fields, columns
    materials.VARIED_FIELDS, for a Solver made with variation=True; else None.
    """

    x: np.ndarray
    v: np.ndarray
    volume: np.ndarray
    material: np.ndarray
    body: np.ndarray
    birth: np.ndarray | None = None
    variation: np.ndarray | None = None


def check_particles(p: Particles, n_materials: int, *, varied: bool) -> int:
    """The particle count n, after refusing (ValueError naming the field and the fix) wrong
    shapes, non-finite values, positions outside the domain, unknown materials, volumes <= 0 and
    variation given without a varied solver (or the other way round)."""
    x = np.asarray(p.x)
    n = x.shape[0] if x.ndim == 2 else -1
    shapes = {"x": (n, 3), "v": (n, 3), "volume": (n,), "material": (n,), "body": (n,)}
    for name, shape in shapes.items():
        arr = np.asarray(getattr(p, name))
        if n < 1 or arr.shape != shape:
            raise ValueError(f"Particles.{name}: shape {arr.shape}, expected {shape} with n >= 1")
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise ValueError(f"Particles.{name}: contains NaN or inf; fix the particle source")
    if x.min() < 0.0 or x.max() > 1.0:
        raise ValueError(
            "Particles.x: positions outside the domain [0, 1]^3 (min %.3g, max %.3g); map world "
            "space into the domain before simulating" % (x.min(), x.max())
        )
    mat = np.asarray(p.material)
    if mat.min() < 0 or mat.max() >= n_materials:
        raise ValueError(
            f"Particles.material: indices must be in [0, {n_materials - 1}] "
            f"(the solver has {n_materials} materials), got {mat.min()}..{mat.max()}"
        )
    if np.any(np.asarray(p.volume) <= 0):
        raise ValueError("Particles.volume: rest volumes must be > 0 (domain units^3)")
    check_variation(p.variation, n, varied)
    return n
