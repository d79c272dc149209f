"""Shared helpers for the solver tests: small particle blocks on CPU."""

import numpy as np
import warp as wp

from mpmfx.mpm import Particles
from mpmfx.mpm.state import m33_assign

wp.config.quiet = True


def block(
    lo, hi, *, grid_n: int, material: int = 0, body: int | None = None, v=(0.0, 0.0, 0.0), ppc: int = 2
) -> Particles:
    """Particles on a lattice filling the box [lo, hi] (domain units), ppc per cell and axis."""
    h = 1.0 / (grid_n * ppc)
    axes = [np.arange(lo[a] + h / 2, hi[a], h) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    n = len(x)
    return Particles(
        x=x,
        v=np.tile(np.asarray(v, np.float32), (n, 1)),
        volume=np.full(n, h**3, np.float32),
        material=np.full(n, material, np.int32),
        body=np.full(n, material if body is None else body, np.int32),
    )


def concat(*parts: Particles) -> Particles:
    return Particles(
        *[np.concatenate([getattr(p, k) for p in parts]) for k in ("x", "v", "volume", "material", "body")]
    )


def free_bar(*, grid_n: int, half_width: float, length: float = 0.6, E: float = 100.0, v0: float = 0.1):
    """The axially vibrating bar (Buzzi et al. 2008), free-free, in its first mode: v = v0 cos(kx) and C = dv/dx (for
    APIC). Returns (solver, state, particles, k). No gravity, nu = 0, an Elastic-like clamp."""
    from mpmfx.mpm import Material, Mode, Solver, SolverConfig

    x0 = 0.5 - length / 2
    p = block(
        (x0, 0.5 - half_width, 0.5 - half_width), (x0 + length, 0.5 + half_width, 0.5 + half_width), grid_n=grid_n
    )
    k = np.pi / length
    p.v[:, 0] = v0 * np.cos(k * (p.x[:, 0] - x0))
    mat = Material(Mode.SNOW, youngs_modulus=E, poisson_ratio=0.0, theta_c=1e9, theta_s=1e9)
    # free-free: the walls' planes 2 cells in keep the bar's ends (0.2 and 0.8) out of their reach at grid 16
    cfg = SolverConfig(grid_n=grid_n, gravity=(0.0, 0.0, 0.0), boundary_cells=2)
    solver = Solver([mat], cfg, device="cpu")
    state = solver.init_state(p)
    C = np.zeros((state.n, 3, 3), np.float32)
    C[:, 0, 0] = -v0 * k * np.sin(k * (p.x[:, 0] - x0))
    m33_assign(state.cur.C, C)
    return solver, state, p, k
