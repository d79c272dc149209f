"""Material variation on a GPU, through the device stepper (brick P2G, CUDA graphs): unit
multipliers give the unvaried run bit for bit, a varied run replays bit for bit, and a varied
snow slab and sand column cost per frame against their unvaried runs. One table.

    python lab/variation_gpu.py [--device cuda:0] [--grid 128] [--frames 6]
"""

import argparse
import dataclasses
import time

import numpy as np
import warp as wp

from mpmfx.bench.report import print_table
from mpmfx.geometry.noise import fourier_noise
from mpmfx.mpm import Particles, Solver, SolverConfig, preset
from mpmfx.mpm.variation import VARIED_FIELDS

FPS = 24.0


def column(grid: int) -> Particles:
    """A column of 8 particles a cell standing on the floor, (0.3..0.7, 0.05..0.6, 0.3..0.7)."""
    h = 1.0 / (2 * grid)
    lo, hi = (0.3, 3.0 / grid, 0.3), (0.7, 0.6, 0.7)
    axes = [np.arange(lo[a] + h / 2, hi[a], h) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    n = len(x)
    return Particles(x, np.zeros_like(x), np.full(n, h**3, np.float32), np.zeros(n, np.int32), np.zeros(n, np.int32))


def varied(p: Particles, amplitude: float) -> np.ndarray:
    """(n, 5) multipliers exp(amplitude * noise), feature size 0.05 domain units, seed 7."""
    n = np.stack([fourier_noise(p.x, 0.05, (7, j)) for j in range(len(VARIED_FIELDS))], axis=1)
    return np.exp(amplitude * n).astype(np.float32)


def run(material, p, mult, device, grid, frames):
    """(final x, v; seconds a frame; substeps) of `frames` frames, compiled and warm."""
    s = Solver([preset(material)], SolverConfig(grid_n=grid), device=device, variation=mult is not None)
    st = s.init_state(dataclasses.replace(p, variation=mult))
    s.advance(st, 0.0, 0.25 / FPS)
    wp.synchronize_device(device)
    t0, subs = time.perf_counter(), 0
    for f in range(frames):
        subs += s.advance(st, (f + 0.25) / FPS, (f + 1.25) / FPS).substeps
    wp.synchronize_device(device)
    return st.cur.x.numpy(), st.cur.v.numpy(), (time.perf_counter() - t0) / frames, subs


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--grid", type=int, default=128)
    ap.add_argument("--frames", type=int, default=6)
    a = ap.parse_args()
    wp.config.quiet = True
    rows = []
    for material in ("Mushy", "Granular"):
        p = column(a.grid)
        plain = run(material, p, None, a.device, a.grid, a.frames)
        ones = run(material, p, np.ones((len(p.x), len(VARIED_FIELDS)), np.float32), a.device, a.grid, a.frames)
        vary = run(material, p, varied(p, 0.3), a.device, a.grid, a.frames)
        again = run(material, p, varied(p, 0.3), a.device, a.grid, a.frames)
        rows.append(
            {
                "material": material,
                "particles": len(p.x),
                "unit_equals_plain": bool(np.array_equal(plain[0], ones[0]) and np.array_equal(plain[1], ones[1])),
                "replay_identical": bool(np.array_equal(vary[0], again[0]) and np.array_equal(vary[1], again[1])),
                "moved_by_variation_cells": float(np.abs(vary[0] - plain[0]).max() * a.grid),
                "frame_ms_plain": round(1e3 * plain[2], 1),
                "frame_ms_varied": round(1e3 * vary[2], 1),
                "substeps_plain_varied": [plain[3], vary[3]],
            }
        )
    print_table(rows, list(rows[0]))


if __name__ == "__main__":
    main()
