"""The animated mesh collider's cost per substep beside the solver step: a block of Mushy snow
of about N particles, and a squashing ball of V vertices (a sphere baked per frame, as a rig
would be) pressed into its top; the same run without the collider for the step alone; and the
collider's own per-substep work (interpolate + refit), timed alone. One table; rows as JSON
under --out.

    python lab/collider_cost.py [--device cpu|cuda] [--grid 32] [--particles 20000 ...] [--subdiv 3] [--frames 3] [--no-graphs]

(On a GPU: --device cuda --grid 256 --particles 2400000 19000000.)
"""

import argparse
import json
import os
import time

import numpy as np
import trimesh
import warp as wp

from mpmfx.bench.report import print_table
from mpmfx.mpm import AnimatedMesh, Particles, Solver, SolverConfig, animated, preset

OUT = os.environ.get("OUT", "renders/bench")
FPS = 24.0


def snow_block(n: int, grid_n: int) -> Particles:
    """About n particles, 8 a cell, in a cube resting on the floor in the middle of the domain."""
    side = (n / 8) ** (1 / 3) / grid_n  # domain units
    side = min(side, 0.8)
    h = 1.0 / (2 * grid_n)
    lo = np.array([0.5 - side / 2, 3.0 / grid_n, 0.5 - side / 2])
    axes = [np.arange(lo[a] + h / 2, lo[a] + side, h) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    k = len(x)
    return Particles(x, np.zeros_like(x), np.full(k, h**3, np.float32), np.zeros(k, np.int32), np.zeros(k, np.int32))


def squashing_ball(top: float, radius: float, subdiv: int, frames: int) -> AnimatedMesh:
    """A ball sinking a radius into the block's top over the frames, squashing as it goes."""
    ball = trimesh.creation.icosphere(subdivisions=subdiv, radius=radius)
    times = np.arange(frames + 1) / FPS
    pts = []
    for t in times:
        a = t / times[-1]
        v = ball.vertices * [1 + 0.2 * a, 1 - 0.3 * a, 1 + 0.2 * a]
        pts.append(v + [0.5, top + radius * (1.05 - a), 0.5])
    return AnimatedMesh(times, np.asarray(pts, np.float32), ball.faces, friction=0.3)


def run(device, grid_n, parts, mesh, frames, graphs=True):
    """(seconds a substep, substeps, solver) of `frames` frames, the kernels compiled and warm;
    graphs: the device stepper's chunks as CUDA graphs (the default), else launched one by one."""
    s = Solver([preset("Mushy")], SolverConfig(grid_n=grid_n), animated=[mesh] if mesh else [], device=device)
    s._device_advance.graphs = graphs
    st = s.init_state(parts)
    s.advance(st, 0.0, 0.25 / FPS)  # compile, capture
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    subs = 0
    for f in range(frames):
        subs += s.advance(st, (f + 0.25) / FPS, (f + 1.25) / FPS).substeps
    wp.synchronize_device(device)
    return (time.perf_counter() - t0) / subs, subs, s


def pose_alone(s, reps=50) -> float:
    """Seconds a substep of the collider's own work: interpolate the points, refit the BVH."""
    m = s._meshes
    m.pose_host(0.01, 0.011, 0.001)
    wp.synchronize_device(s.device)
    t0 = time.perf_counter()
    for i in range(reps):
        m.pose_host(0.01 + i * 1e-4, 0.0101 + i * 1e-4, 1e-4)
    wp.synchronize_device(s.device)
    return (time.perf_counter() - t0) / reps


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--grid", type=int, default=32)
    ap.add_argument("--particles", type=int, nargs="+", default=[20000])
    ap.add_argument("--subdiv", type=int, default=3, help="icosphere subdivisions (3: 642 vertices, 5: 10242)")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--no-graphs", action="store_true", help="launch the substeps' kernels one by one (no CUDA graphs)")
    ap.add_argument(
        "--inside", nargs="+", default=["faces"], choices=animated.INSIDE_TESTS, help="inside tests to time"
    )
    ap.add_argument("--out", default=OUT)
    a = ap.parse_args()
    wp.config.quiet = True
    rows = []
    for n in a.particles:
        parts = snow_block(n, a.grid)
        top = float(parts.x[:, 1].max())
        mesh = squashing_ball(top, 0.15, a.subdiv, a.frames + 1)
        step, subs, _ = run(a.device, a.grid, parts, None, a.frames, not a.no_graphs)
        for inside in a.inside:
            animated.INSIDE_TEST = inside
            step_c, subs_c, s = run(a.device, a.grid, parts, mesh, a.frames, not a.no_graphs)
            pose = pose_alone(s)
            rows.append(
                {
                    "device": a.device,
                    "inside": inside,
                    "grid": a.grid,
                    "particles": len(parts.x),
                    "vertices": mesh.points.shape[1],
                    "step_ms": 1e3 * step,
                    "step_with_collider_ms": 1e3 * step_c,
                    "collider_ms": 1e3 * (step_c - step),
                    "pose_refit_ms": 1e3 * pose,
                    "substeps": [subs, subs_c],
                }
            )
    print_table(
        rows,
        [
            "inside",
            "particles",
            "vertices",
            "step_ms",
            "step_with_collider_ms",
            "collider_ms",
            "pose_refit_ms",
            "substeps",
        ],
    )
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, f"collider_cost_{a.device.replace(':', '')}.json"), "w") as fh:
        json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
