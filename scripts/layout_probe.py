"""Timing probe for issue 14 (not a product path), on the GPU: how fast the particle arrays'
layouts move (array of mat33 / vec6 / vec3 against structure-of-arrays planes), copied, read and
written: G2P moves ~1.55 TB/s, water and snow alike, against ~4.2 TB/s for a plain copy.

    python3 scripts/layout_probe.py --out $OUT
    ncu ... python3 scripts/layout_probe.py --ncu --scene Mushy   # one scene, graphs off

Measured on an H200 (19.4M particles' worth, GB/s read + write): mat33 1297, vec6 3029, vec3
3736, nine float planes 3215. (Also tried there, by the bench's Mushy / Water / Granular 2.4M
blocks: the brick scatter with 160 or 192 threads a block for its 128 parked slots, so the
~144 (run, stencil row) tasks of a round fit one pass: 0.79 -> 0.85 ms a substep, slower.)
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path



import warp as wp  # noqa: E402

import mpmfx.mpm.p2g_brick as pb  # noqa: E402


def build(name: str, grid_n: int):
    from mpmfx.bench.gpu import scene
    from mpmfx.mpm import Solver, SolverConfig
    mats, parts, _ = scene(name, grid_n)
    solver = Solver(mats, SolverConfig(grid_n=grid_n, deterministic=False), device="cuda")
    state = solver.init_state(parts)
    span = 32 * solver.config.cfl * solver.config.dx / max(m.wave_speed() for m in mats)
    return solver, state, span


@wp.kernel
def _copy_m33(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    b[i] = a[i]


@wp.kernel
def _read_m33(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=float)):
    i = wp.tid()
    m = a[i]
    if wp.trace(m) == 12345.0:  # never: keeps the load
        b[0] = 1.0


@wp.kernel
def _write_m33(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    b[i] = wp.mat33(float(i))


@wp.kernel
def _write_m33_flat(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=float)):
    i = wp.tid()  # the same bytes as _write_m33, nine scalar stores into a float view
    m = wp.mat33(float(i))
    for r in range(3):
        for c in range(3):
            b[9 * i + 3 * r + c] = m[r, c]


@wp.kernel
def _write_m33_rows(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=wp.vec3)):
    i = wp.tid()  # the same bytes as _write_m33, three vec3 stores into a vec3 view
    m = wp.mat33(float(i))
    for r in range(3):
        b[3 * i + r] = m[r]


@wp.kernel
def _write_v6(a: wp.array(dtype=pb.vec6), b: wp.array(dtype=pb.vec6)):
    i = wp.tid()
    b[i] = pb.vec6(float(i))


@wp.kernel
def _write_v3(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    b[i] = wp.vec3(float(i))


@wp.kernel
def _copy_rows(a: wp.array2d(dtype=wp.vec3), b: wp.array2d(dtype=wp.vec3)):
    i = wp.tid()  # three planes of rows
    m = wp.matrix_from_rows(a[0, i], a[1, i], a[2, i])
    b[0, i] = m[0]
    b[1, i] = m[1]
    b[2, i] = m[2]


@wp.kernel
def _copy_v6(a: wp.array(dtype=pb.vec6), b: wp.array(dtype=pb.vec6)):
    i = wp.tid()
    b[i] = a[i]


@wp.kernel
def _copy_v3(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    b[i] = a[i]


@wp.kernel
def _copy_f9(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float)):
    i = wp.tid()  # nine planes (structure of arrays)
    for c in range(9):
        b[c, i] = a[c, i]


def layouts(n: int = 19_352_256, reps: int = 20) -> list[dict]:
    """GB/s of moving n particles' worth of each layout with a kernel (bytes read + written)."""
    m33, f1 = wp.mat33, float
    cases = [("mat33 copy (36 B a thread)", _copy_m33, m33, (n,), m33, (n,), 2),
             ("mat33 read", _read_m33, m33, (n,), f1, (1,), 1),
             ("mat33 write", _write_m33, m33, (n,), m33, (n,), 1),
             ("mat33 write, 9 floats into a float view", _write_m33_flat, m33, (1,), f1, (9 * n,), 1),
             ("mat33 write, 3 vec3 into a vec3 view", _write_m33_rows, m33, (1,), wp.vec3, (3 * n,), 1),
             ("vec6 write", _write_v6, pb.vec6, (1,), pb.vec6, (n,), 1),
             ("vec3 write", _write_v3, wp.vec3, (1,), wp.vec3, (n,), 1),
             ("mat33 as 3 planes of vec3 rows, copy", _copy_rows, wp.vec3, (3, n), wp.vec3, (3, n), 2),
             ("float, 9 planes, copy", _copy_f9, f1, (9, n), f1, (9, n), 2),
             ("vec6 copy (24 B)", _copy_v6, pb.vec6, (n,), pb.vec6, (n,), 2),
             ("vec3 copy (12 B)", _copy_v3, wp.vec3, (n,), wp.vec3, (n,), 2)]
    rows = []
    for label, k, ta, sa, tb, sb, sides in cases:
        a = wp.zeros(sa, dtype=ta)
        b = wp.zeros(sb, dtype=tb)
        wp.launch(k, dim=n, inputs=[a, b])
        wp.synchronize()
        t0 = time.perf_counter()
        for _ in range(reps):
            wp.launch(k, dim=n, inputs=[a, b])
        wp.synchronize()
        s = (time.perf_counter() - t0) / reps
        nbytes = sides * max(a.capacity, b.capacity)
        rows.append({"probe": "layout", "layout": label, "MB": nbytes / 1e6, "ms": 1e3 * s, "GBs": nbytes / s / 1e9})
        print(json.dumps(rows[-1]), flush=True)
        del a, b
    return rows


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="profile_out")
    ap.add_argument("--scene", default="Mushy")
    ap.add_argument("--grid", type=int, default=128)
    ap.add_argument("--ncu", action="store_true", help="one scene's substeps, graphs off (under ncu)")
    ap.add_argument("--lineinfo", action="store_true", help="kernels with line info (ncu's source counters)")
    a = ap.parse_args()
    wp.config.quiet = True
    wp.config.lineinfo = a.lineinfo
    wp.init()
    if a.ncu:
        solver, state, span = build(a.scene, a.grid)
        solver._device_advance.graphs = False
        solver.advance(state, 0.0, span)
        return 0
    rows = layouts()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "layout_probe.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
