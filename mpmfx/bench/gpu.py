"""`mpmfx bench gpu`: the production step's speed through `Solver.advance()`, beside Taichi.

Scenes: a block filling 0.6 x 0.4 x 0.6 of the domain at 8 particles per cell, at rest,
falling under gravity inside walls: Water, Mushy (snow), Granular (sand), Elastic, at grid
64 / 128 / 256 (~0.3M / 2.4M / 19M particles); plus a mixed scene (the four materials side
by side) hit by a moving SDF sphere collider at grid 128. Each is timed through `advance()`
(adaptive dt, every guard, the per-advance report), deterministic mode off and on, over an
interval of about `SUBSTEPS` CFL substeps after four warm-up intervals (compiles, and the
CUDA graphs of the cadence the timed interval keeps; `captures` counts any left in it).

Per row: particle-substeps per second (G/s = 1e9), ms per substep and its split by phase
(device time per kernel from Warp's CUDA timing; "host" = wall minus device time), device
bytes per particle (particle buffers; the grid separately), the bytes one substep moves
(model below) and the bandwidth achieved, against a device-to-device copy measured in the
same run. The peer, Taichi's mpm3d step (`taichi_peer.py`), runs in a child process at the
same sizes and the dt our solver took. --quick: tiny sizes on the CPU, no peer.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import traceback

import numpy as np
import warp as wp

from mpmfx.bench.gpu_plot import throughput_plot
from mpmfx.bench.report import print_table, write_rows
from mpmfx.mpm import Collider, ColliderKind, Particles, Solver, SolverConfig, preset
from mpmfx.mpm.p2g import P2GParams
from mpmfx.mpm.stepper import SubstepDev

MATERIALS = ("Water", "Mushy", "Granular", "Elastic")
MIXED = MATERIALS  # the mixed scene's four columns
SUBSTEPS = 50  # CFL substeps per timed advance() interval
REGION_LO, REGION_SIZE = (0.2, 0.1, 0.2), (0.6, 0.4, 0.6)
COLS = [
    "impl",
    "path",
    "scene",
    "grid_n",
    "particles",
    "det",
    "substeps",
    "G_per_s",
    "ms_substep",
    "ms_clear",
    "ms_p2g",
    "ms_grid",
    "ms_g2p",
    "ms_sort",
    "ms_host",
    "captures",
    "B_per_particle",
    "grid_MB",
    "GBs",
    "copy_GBs",
    "x_taichi",
    "device",
]


def block(grid_n: int, *, seed: int = 0) -> tuple[np.ndarray, float]:
    """Particles of the scene block, 2x2x2 jittered per cell: x (n, 3) float32, rest volume."""
    dx = 1.0 / grid_n
    cells = [round(s * grid_n) for s in REGION_SIZE]
    idx = np.stack(np.meshgrid(*[np.arange(2 * c, dtype=np.int32) for c in cells], indexing="ij"), -1)
    idx = idx.reshape(-1, 3)
    rng = np.random.default_rng(seed)
    x = np.asarray(REGION_LO, np.float32) + (idx + 0.5 + rng.uniform(-0.3, 0.3, idx.shape).astype(np.float32)) * (
        0.5 * dx
    )
    return x.astype(np.float32), dx**3 / 8


def sphere_collider(grid_n: int):
    """An SDF sphere (radius 0.12, 24^3 voxels) sweeping through the block along +x in 0.5 s."""
    r, res = 0.12, 24
    voxel = 2.6 * r / (res - 1)
    g = (np.arange(res) * voxel - 1.3 * r).astype(np.float32)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    sdf = (np.sqrt(X**2 + Y**2 + Z**2) - r).astype(np.float32)
    return Collider(
        kind=ColliderKind.SDF,
        friction=0.2,
        times=np.array([0.0, 0.5]),
        translations=np.array([[0.1, 0.3, 0.5], [0.9, 0.3, 0.5]], np.float32),
        sdf=sdf,
        sdf_origin=(-1.3 * r,) * 3,
        sdf_voxel=voxel,
    )


def scene(name: str, grid_n: int):
    """(materials, Particles, colliders) of a scene: one material name, or "Mixed"."""
    x, vol = block(grid_n)
    n = len(x)
    if name == "Mixed":  # the four materials in four columns of the block, a moving collider
        mats = [preset(m) for m in MIXED]
        col = (x[:, 0] > 0.5).astype(np.int32) * 2 + (x[:, 2] > 0.5).astype(np.int32)
        colliders = [sphere_collider(grid_n)]
    else:
        mats, col, colliders = [preset(name)], np.zeros(n, np.int32), []
    parts = Particles(
        x=x, v=np.zeros_like(x), volume=np.full(n, vol, np.float32), material=col, body=np.zeros(n, np.int32)
    )
    return mats, parts, colliders


def copy_bandwidth(device, mbytes: int = 1024) -> float:
    """Device-to-device copy, GB/s counting read + write (0 on the CPU: not measured)."""
    if not wp.get_device(device).is_cuda:
        return 0.0
    a = wp.zeros(mbytes * 2**18, dtype=float, device=device)
    b = wp.zeros_like(a)
    wp.copy(b, a)
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    for _ in range(10):
        wp.copy(b, a)
    wp.synchronize_device(device)
    return 10 * 2 * a.capacity / (time.perf_counter() - t0) / 1e9


def _bytes(arrs) -> int:
    return int(sum(a.capacity for a in arrs))


def traffic(solver, state) -> tuple[int, int, int]:
    """(particle bytes on the device, grid bytes, bytes one substep moves). Moved: P2G reads
    every particle array once, G2P reads the current buffers and writes the next ones; the
    grid is cleared, read and written by the update, and read once more by G2P."""
    cur = state.cur.arrays()
    const = [state.mass, state.volume, state.material, state.body, state.field_id]
    part = _bytes(cur) + _bytes(state.nxt.arrays()) + _bytes(const) + state.pid.capacity
    da = solver._device_advance
    brick = solver.stepper == "device" and da.p2g == "brick" and da._brick is not None
    if brick:  # the brick P2G's scratch (its sort, once a chunk of up to 32 substeps, is left out)
        part += da._brick.nbytes() + (_bytes(state.spare) if state.spare else 0)
    grid_arrays = [solver._grid_m, solver._grid_mv, solver._grid_fixed, solver._grid_v, solver._grid_normal]
    grid = _bytes(grid_arrays)
    acc = _bytes([solver._grid_fixed] if solver.config.deterministic else [solver._grid_m, solver._grid_mv])
    moved = (
        (_bytes(cur) + _bytes(const) - state.body.capacity) + 2 * _bytes(cur) + 3 * acc + 2 * solver._grid_v.capacity
    )
    return part, grid, moved


def _phase_split(solver, state, t: float, span: float) -> tuple[dict, float]:
    """Device ms per substep of each phase over one more advance() (CUDA only), and t after it."""
    if not solver.device.is_cuda:
        report = solver.advance(state, t, t + span)
        return {}, t + span
    graphs = solver._device_advance.graphs
    solver._device_advance.graphs = False  # a graph is timed as one item: launch the kernels one by one
    wp.timing_begin(cuda_filter=wp.TIMING_KERNEL | wp.TIMING_MEMSET)
    report = solver.advance(state, t, t + span)
    results = wp.timing_end()
    solver._device_advance.graphs = graphs
    ms = {"clear": 0.0, "p2g": 0.0, "grid": 0.0, "g2p": 0.0}
    for r in results:
        name = r.name.lower()
        key = (
            "g2p"
            if "g2p" in name
            else "grid"
            if "grid_update" in name
            else "clear"
            if "memset" in name or "clear" in name
            else None
            if ("begin" in name or "end" in name or "report" in name or "sum_rows" in name)
            else "p2g"
        )  # p2g, and the brick P2G's keys, sort, scan, segments, scatter
        if key:
            ms[key] += r.elapsed
    k = max(1, report.substeps + report.rejected_substeps)
    return {f"ms_{p}": v / k for p, v in ms.items()}, t + span


def sort_ms(solver, state, reps: int = 10, *, whole: bool = False) -> float:
    """Device ms of one brick-P2G sort of `state`, timed alone (CUDA; 0 without the brick P2G):
    its CUB calls (radix sort and scan), which are not Warp launches, so Warp's kernel timing
    (_phase_split) does not see them (its Warp kernels, keys and segments, are in P2G's); whole:
    the whole sort (what bricks.sort_cadence weighs)."""
    brick = solver._device_advance._brick
    if brick is None or not solver.device.is_cuda or solver._device_advance.p2g != "brick":
        return 0.0
    pp = P2GParams()
    pp.inv_dx, pp.nodes = float(solver.config.grid_n), solver.config.grid_n + 1
    sd = SubstepDev()
    sd.active = 1
    sub = wp.array([sd], dtype=SubstepDev, device=solver.device)

    def once():  # (a radix sort's cost does not depend on the keys' order)
        if whole:
            brick.sort(pp, state, state.cur, sub)
        else:
            wp.utils.radix_sort_pairs(brick.keys, brick.idx, brick.n)
            wp.utils.array_scan(brick.flag, brick.pos, inclusive=False)

    once()  # warm
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    for _ in range(reps):
        once()
    wp.synchronize_device(solver.device)
    return 1e3 * (time.perf_counter() - t0) / reps


def run_case(
    name: str,
    grid_n: int,
    deterministic: bool,
    device,
    copy_gbs: float,
    *,
    substeps: int = SUBSTEPS,
    path: str = "device",
) -> dict:
    """One scene through advance(). path: "device" (the default stepper), "device-nograph"
    (same, CUDA graphs off), "device-unbinned" (same, with the reference P2G instead of the
    brick P2G, the default on a GPU), "device-sortK" (the brick P2G re-sorted every K
    substeps, not at the cadence bricks.sort_cadence picks; 32: once a chunk) or "host" (the reference loop and kernels: statistics read every
    substep)."""
    mats, parts, colliders = scene(name, grid_n)
    cfg = SolverConfig(grid_n=grid_n, deterministic=deterministic)
    solver = Solver(mats, cfg, colliders=colliders, device=device, stepper="host" if path == "host" else "device")
    solver._device_advance.graphs = path != "device-nograph"
    da = solver._device_advance
    if path == "device-unbinned":  # (multi-field scenes and the CPU have only the reference P2G)
        da.p2g = "reference"
    da.sort_every = int(path[len("device-sort") :]) if path.startswith("device-sort") else 0
    state = solver.init_state(parts)
    c = max(m.wave_speed() for m in mats)
    span = substeps * cfg.cfl * cfg.dx / c  # ~substeps CFL substeps at rest
    # compile, warm up: two intervals, so the chunk graphs of both buffer parities are captured
    # (a shot captures them in its first frames; capture cost is a one-off per State)
    solver.advance(state, 0.0, span)
    solver.advance(state, span, 2 * span)
    # the block speeds up as it falls, and the brick P2G re-sorts more often as it does
    # (bricks.sort_cadence): a new cadence is a new graph to capture, so the timed interval
    # keeps the one the warm-up ended with (steady state; a shot pays each capture once), after
    # two more warm-up intervals that capture that cadence's graphs (without them they would be
    # captured inside the timing)
    da.sort_every = da.sort_every or state.clock.sort_every or da.last_sort_every
    for i in (2, 3):
        solver.advance(state, i * span, (i + 1) * span)
    captured = len(da._graphs)
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    report = solver.advance(state, 4 * span, 5 * span)
    wp.synchronize_device(solver.device)
    wall = time.perf_counter() - t0
    captured = len(da._graphs) - captured  # graphs captured inside the timing (a one-off cost)
    phases, _ = _phase_split(solver, state, 5 * span, span)
    part, grid, moved = traffic(solver, state)
    k = report.substeps + report.rejected_substeps
    ms = 1e3 * wall / k
    row = {
        "impl": "mpmfx",
        "path": path,
        "scene": name,
        "grid_n": grid_n,
        "particles": state.n,
        "det": int(deterministic),
        "substeps": report.substeps,
        "rejected": report.rejected_substeps,
        "dt_mean": span / max(1, report.substeps),
        "G_per_s": state.n * report.substeps / wall / 1e9,
        "ms_substep": ms,
        **phases,
        "captures": captured,
        "B_per_particle": part / state.n,
        "grid_MB": grid / 2**20,
        "moved_MB": moved / 2**20,
        "GBs": moved / (ms * 1e-3) / 1e9,
        "copy_GBs": copy_gbs,
        "finite": bool(np.isfinite(state.cur.x.numpy()).all()),
        "device": _device_name(solver.device),
    }
    if phases:  # the sorts: one every `sort_every` substeps (the cadence the timed interval kept)
        row["sort_every"] = da.sort_every
        row["ms_sort"] = sort_ms(solver, state) / max(1, da.sort_every)
        row["ms_host"] = ms - sum(phases.values()) - row["ms_sort"]
    return row


def safe_case(*args, **kw) -> dict:
    """run_case, or a row naming the error (one failing case must not lose the whole run)."""
    try:
        return run_case(*args, **kw)
    except Exception as err:  # noqa: BLE001 (reported in the row and the table)
        traceback.print_exc()
        return {
            "impl": "mpmfx",
            "path": kw.get("path", "device"),
            "scene": args[0],
            "grid_n": args[1],
            "det": int(args[2]),
            "error": repr(err)[:200],
            "finite": False,
        }


def _device_name(device) -> str:
    d = wp.get_device(device)
    return d.name if d.is_cuda else "cpu"


def taichi_rows(cases: list[tuple], *, arch: str = "cuda") -> list[dict]:
    """Run the Taichi peer in a child process (its own memory pool); rows it printed."""
    m = preset("Mushy")
    spec = {
        "cases": cases,
        "arch": arch,
        "snow": {
            "mu0": m.mu0,
            "lambda0": m.lambda0,
            "hardening": m.hardening,
            "theta_c": m.theta_c,
            "theta_s": m.theta_s,
        },
    }
    try:
        out = subprocess.run(
            [sys.executable, "-m", "mpmfx.bench.taichi_peer", json.dumps(spec)],
            capture_output=True,
            text=True,
            timeout=900,
            env=dict(os.environ),
        )
    except (OSError, subprocess.TimeoutExpired) as err:
        print(f"taichi peer: did not run ({err})")
        return []
    rows = [json.loads(line[4:]) for line in out.stdout.splitlines() if line.startswith("ROW ")]
    if not rows:
        print(f"taichi peer: no rows (is taichi installed?); stderr tail:\n{out.stderr[-1500:]}")
    return rows


def main(
    *, quick: bool = False, device: str | None = None, out: str = "renders/bench", sizes: tuple[int, ...] | None = None
) -> int:
    """sizes: grid sizes to run (default 64, 128, 256; the mixed scene runs at 128 if listed)."""
    if quick:
        device = device or "cpu"
    sizes = (16,) if quick else tuple(sizes or (64, 128, 256))
    k = 8 if quick else SUBSTEPS
    mixed = 16 if quick else 128
    wp.init()
    copy_gbs = copy_bandwidth(device)
    rows = []
    for g in sizes:
        for name in MATERIALS:
            for det in (False, True):
                rows.append(safe_case(name, g, det, device, copy_gbs, substeps=k))
                print_table(rows[-1:], COLS)
    for det in (False, True) if mixed in sizes else ():  # colliders posed on the device, and the host loop
        for path in ("device", "host"):
            rows.append(safe_case("Mixed", mixed, det, device, copy_gbs, substeps=k, path=path))
    # the levers, back to back in this run: the reference host loop, and no CUDA graphs
    levers = (
        ("Mushy", "host", False),
        ("Water", "host", False),
        ("Mushy", "device-nograph", False),
        ("Mushy", "device-unbinned", False),
        ("Water", "device-unbinned", False),
        ("Mushy", "device-unbinned", True),
        ("Mushy", "device-sort1", False),
        ("Mushy", "device-sort32", False),
        ("Water", "device-sort32", False),
        ("Mushy", "host", True),
    )
    for g in sizes:
        for name, path, det in levers:
            if name in MATERIALS:
                rows.append(safe_case(name, g, det, device, copy_gbs, substeps=k, path=path))
                print_table(rows[-1:], COLS)
    if not quick and os.environ.get("MPMFX_BENCH_PEER", "1") != "0":
        cases = [
            [r["grid_n"], "water" if r["scene"] == "Water" else "snow", r["dt_mean"], r["substeps"]]
            for r in rows
            if r["scene"] in ("Water", "Mushy") and not r["det"] and r["path"] == "device"
        ]
        for t in taichi_rows(cases):
            t.update(scene="Water" if t["material"] == "water" else "Mushy", device=rows[0]["device"])
            ours = [r for r in rows if r["scene"] == t["scene"] and r["grid_n"] == t["grid_n"] and r["impl"] == "mpmfx"]
            t["path"] = "mpm3d step loop"
            for r in ours:
                if t.get("G_per_s"):
                    r["x_taichi"] = r["G_per_s"] / t["G_per_s"]
            rows.append(t)
    write_rows(rows, out, "gpu")
    try:
        print("plot:", throughput_plot(rows, out))
    except ImportError as err:
        print(f"plot skipped ({err}); draw it from {out}/gpu.csv with `python -m mpmfx.bench.gpu_plot {out}`")
    print(f"\nmpmfx bench gpu: {rows[0].get('device')}; G_per_s = 1e9 particle-substeps/s through Solver.advance()")
    print_table(rows, COLS)
    return 0 if all(r.get("finite", True) for r in rows) else 1


if __name__ == "__main__":  # the GPU machine has no pydantic, so not through mpmfx.cli there
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="renders/bench")
    ap.add_argument("--sizes", type=lambda s: tuple(int(g) for g in s.split(",")), help="grid sizes, e.g. 64,128")
    a = ap.parse_args()
    sys.exit(main(quick=a.quick, out=a.out, sizes=a.sizes))
