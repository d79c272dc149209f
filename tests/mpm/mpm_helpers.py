"""Shared helpers for the solver tests: small particle blocks on CPU."""

import numpy as np
import warp as wp

from mpmfx.mpm import Particles

wp.config.quiet = True


def block(lo, hi, *, grid_n: int, material: int = 0, body: int | None = None, v=(0.0, 0.0, 0.0),
          ppc: int = 2) -> Particles:
    """Particles on a lattice filling the box [lo, hi] (domain units), ppc per cell and axis."""
    h = 1.0 / (grid_n * ppc)
    axes = [np.arange(lo[a] + h / 2, hi[a], h) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    n = len(x)
    return Particles(
        x=x, v=np.tile(np.asarray(v, np.float32), (n, 1)), volume=np.full(n, h**3, np.float32),
        material=np.full(n, material, np.int32),
        body=np.full(n, material if body is None else body, np.int32),
    )


def concat(*parts: Particles) -> Particles:
    return Particles(*[np.concatenate([getattr(p, k) for p in parts]) for k in ("x", "v", "volume", "material", "body")])
