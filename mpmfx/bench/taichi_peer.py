"""Peer for `mpmfx bench gpu`: Taichi's MLS-MPM 3D step, run in its own process.

The algorithm of Taichi's `python/taichi/examples/simulation/mpm3d.py` (dense grid, one
`ti.kernel` per substep holding four parallel loops: clear, P2G with atomics, grid update,
G2P), at our sizes and dt. Materials:
  water: mpm3d's own, verbatim (pressure from the volume ratio J, stress = -4 E V (J-1)/dx^2);
  snow:  mpm3d's step with the snow constitutive model of Taichi's mpm128 example (F update,
         SVD, singular values clamped to [1 - theta_c, 1 + theta_s], hardening exp(xi (1 - Jp)),
         fixed-corotated stress), with the moduli of our Mushy preset.
Particles: a block filling 0.6 x 0.4 x 0.6 of the domain, 8 per cell, at rest, generated
on the device. Prints one JSON row per case on stdout (the parent process reads them).

    python -m mpmfx.bench.taichi_peer '{"cases": [[64, "water", 2e-4, 50]], "arch": "cuda"}'
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def run_case(ti, grid_n: int, material: str, dt: float, substeps: int, snow: dict) -> dict:
    dx, inv_dx = 1.0 / grid_n, float(grid_n)
    lo, size = (0.2, 0.1, 0.2), (0.6, 0.4, 0.6)
    cells = [round(s * grid_n) for s in size]
    n = 8 * cells[0] * cells[1] * cells[2]
    p_vol, p_rho = (dx * 0.5) ** 3, 1.0
    p_mass = p_vol * p_rho
    bound, gravity, E_water = 3, 9.8, 400.0
    mu0, lam0 = snow["mu0"], snow["lambda0"]
    xi, th_c, th_s = snow["hardening"], snow["theta_c"], snow["theta_s"]
    is_snow = material == "snow"

    x = ti.Vector.field(3, float, n)
    v = ti.Vector.field(3, float, n)
    C = ti.Matrix.field(3, 3, float, n)
    J = ti.field(float, n)
    F = ti.Matrix.field(3, 3, float, n if is_snow else 1)
    Jp = ti.field(float, n if is_snow else 1)
    grid_v = ti.Vector.field(3, float, (grid_n,) * 3)
    grid_m = ti.field(float, (grid_n,) * 3)

    @ti.kernel
    def init():
        for p in x:
            c = p // 8
            s = p % 8
            ci = ti.Vector([c // (cells[1] * cells[2]), (c // cells[2]) % cells[1], c % cells[2]])
            si = ti.Vector([s // 4, (s // 2) % 2, s % 2])
            jit = ti.Vector([ti.random() for _ in range(3)]) * 0.6 - 0.3
            x[p] = ti.Vector(lo) + (ci + (si + 0.5 + jit) * 0.5) * dx
            v[p] = ti.zero(v[p])
            C[p] = ti.zero(C[p])
            J[p] = 1.0
            if ti.static(is_snow):
                F[p] = ti.Matrix.identity(float, 3)
                Jp[p] = 1.0

    @ti.func
    def snow_stress(p):
        # mpm128's snow: F update, hardening, SVD clamp, fixed-corotated Kirchhoff stress
        Fp = (ti.Matrix.identity(float, 3) + dt * C[p]) @ F[p]
        h = ti.exp(xi * (1.0 - Jp[p]))
        mu, la = mu0 * h, lam0 * h
        U, sig, V = ti.svd(Fp)
        Je = 1.0
        for d in ti.static(range(3)):
            new_sig = ti.min(ti.max(sig[d, d], 1 - th_c), 1 + th_s)
            Jp[p] *= sig[d, d] / new_sig
            sig[d, d] = new_sig
            Je *= new_sig
        Fp = U @ sig @ V.transpose()
        F[p] = Fp
        return 2 * mu * (Fp - U @ V.transpose()) @ Fp.transpose() + ti.Matrix.identity(float, 3) * la * Je * (Je - 1)

    @ti.kernel
    def substep():
        for I in ti.grouped(grid_m):
            grid_v[I] = ti.zero(grid_v[I])
            grid_m[I] = 0
        ti.loop_config(block_dim=grid_n)  # mpm3d: ti.block_dim(n_grid)
        for p in x:
            Xp = x[p] * inv_dx
            base = int(Xp - 0.5)
            fx = Xp - base
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            affine = p_mass * C[p]
            if ti.static(is_snow):
                affine += (-dt * p_vol * 4 * inv_dx * inv_dx) * snow_stress(p)
            else:
                affine += ti.Matrix.identity(float, 3) * (-dt * 4 * E_water * p_vol * (J[p] - 1) * inv_dx * inv_dx)
            for offset in ti.static(ti.grouped(ti.ndrange(3, 3, 3))):
                dpos = (offset - fx) * dx
                weight = w[offset[0]][0] * w[offset[1]][1] * w[offset[2]][2]
                grid_v[base + offset] += weight * (p_mass * v[p] + affine @ dpos)
                grid_m[base + offset] += weight * p_mass
        for I in ti.grouped(grid_m):
            if grid_m[I] > 0:
                grid_v[I] /= grid_m[I]
            grid_v[I][1] -= dt * gravity
            cond = (I < bound) & (grid_v[I] < 0) | (I > grid_n - bound) & (grid_v[I] > 0)
            grid_v[I] = ti.select(cond, 0, grid_v[I])  # mpm3d: 0 if cond else grid_v[I]
        ti.loop_config(block_dim=grid_n)  # mpm3d: ti.block_dim(n_grid)
        for p in x:
            Xp = x[p] * inv_dx
            base = int(Xp - 0.5)
            fx = Xp - base
            w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1) ** 2, 0.5 * (fx - 0.5) ** 2]
            new_v = ti.zero(v[p])
            new_C = ti.zero(C[p])
            for offset in ti.static(ti.grouped(ti.ndrange(3, 3, 3))):
                dpos = (offset - fx) * dx
                weight = w[offset[0]][0] * w[offset[1]][1] * w[offset[2]][2]
                g_v = grid_v[base + offset]
                new_v += weight * g_v
                new_C += 4 * weight * g_v.outer_product(dpos) * inv_dx * inv_dx
            v[p] = new_v
            x[p] += dt * new_v
            J[p] *= 1 + dt * new_C.trace()
            C[p] = new_C

    init()
    for _ in range(3):  # compile + warm up
        substep()
    ti.sync()
    t0 = time.perf_counter()
    for _ in range(substeps):
        substep()
    ti.sync()
    wall = time.perf_counter() - t0
    xs = x.to_numpy()
    return {
        "impl": "taichi",
        "material": material,
        "grid_n": grid_n,
        "particles": n,
        "dt": dt,
        "substeps": substeps,
        "wall_s": wall,
        "G_per_s": n * substeps / wall / 1e9,
        "ms_substep": 1e3 * wall / substeps,
        "finite": bool(np.isfinite(xs).all()),
    }


def main(spec: dict) -> int:
    import taichi as ti  # optional: taichi

    for grid_n, material, dt, substeps in spec["cases"]:
        ti.init(
            arch=getattr(ti, spec.get("arch", "cuda")),
            default_fp=ti.f32,
            offline_cache=True,
            device_memory_GB=spec.get("memory_GB", 12),
            log_level=ti.WARN,
        )
        try:
            row = run_case(ti, int(grid_n), material, float(dt), int(substeps), spec["snow"])
        except Exception as err:  # report, do not hide: the row says what failed
            row = {"impl": "taichi", "material": material, "grid_n": grid_n, "error": repr(err)[-600:]}
        print("ROW " + json.dumps(row), flush=True)
        ti.reset()
    return 0


if __name__ == "__main__":
    sys.exit(main(json.loads(sys.argv[1])))
