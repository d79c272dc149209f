"""`mpmfx bench solver`: particle-substeps per second for each material family.

A block of particles (8 per cell) is dropped in the domain; after warm-up (compilation and a
few substeps) a fixed number of substeps at a fixed dt is timed with the device synchronised.
Full run: about one million particles per material (GPU). --quick: ~20k on the CPU.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from mpmfx.bench.report import print_table, write_rows
from mpmfx.mpm import Particles, Solver, SolverConfig, preset

MATERIALS = ("Elastic", "Mushy", "Granular", "Water")


def block_particles(n_target: int, grid_n: int, ppc: int = 8, seed: int = 0):
    """A cube of side s (domain units) holding ~n_target particles at ppc per cell, on a jittered lattice."""
    dx = 1.0 / grid_n
    cells = max(1, round((n_target / ppc) ** (1 / 3)))
    k = round(ppc ** (1 / 3))
    side = cells * k
    idx = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    x = 0.5 - cells * dx / 2 + (idx + 0.5 + rng.uniform(-0.3, 0.3, idx.shape)) * dx / k
    x[:, 1] += 0.5 - x[:, 1].min() - cells * dx / 2 - 0.15  # sit in the lower half
    return x.astype(np.float32), np.float32(dx**3 / k**3)


def run_case(material: str, n_target: int, grid_n: int, substeps: int, device):
    x, vol = block_particles(n_target, grid_n)
    n = len(x)
    parts = Particles(
        x=x,
        v=np.zeros_like(x),
        volume=np.full(n, vol, np.float32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
    )
    solver = Solver([preset(material)], SolverConfig(grid_n=grid_n, gravity=(0, -9.8, 0)), device=device)
    state = solver.init_state(parts)
    dt = 1e-4
    for _ in range(5):
        solver.step(state, dt)
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    for _ in range(substeps):
        solver.step(state, dt)
    wp.synchronize_device(solver.device)
    wall = time.perf_counter() - t0
    x_out = solver.state_to_numpy(state)["x"]
    return {
        "material": material,
        "particles": n,
        "grid_n": grid_n,
        "substeps": substeps,
        "wall_s": wall,
        "Mparticle_substeps_per_s": n * substeps / wall / 1e6,
        "finite": bool(np.isfinite(x_out).all()),
        "device": _device_name(solver.device),
    }


def _device_name(device) -> str:
    d = wp.get_device(device)
    return d.name if d.is_cuda else "cpu"


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    n, grid_n, steps = (20_000, 64, 20) if quick else (1_000_000, 256, 200)
    rows = [run_case(m, n, grid_n, steps, device) for m in MATERIALS]
    print_table(rows)
    write_rows(rows, out, "solver")
    return 0 if all(r["finite"] for r in rows) else 1
