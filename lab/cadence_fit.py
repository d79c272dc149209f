"""Calibrate the brick P2G's re-sort cadence (bricks.sort_cadence): how much a worn particle
order costs the scatter, against what a sort costs. Per scene and forced cadence (sort every
1 ... 32 substeps): ms a substep through advance() (CUDA graphs, as shots run), the scatter's
device ms a substep, and the order's wear the scatter counts (BrickP2G.frag: runs scattered,
fallback particles). Then a least-squares fit over every row

    scatter ms a substep = a * particles + b * pieces + f * fallbacks

and the constants sort_cadence uses: a sort's cost per particle in pieces ((sort ms + e) / b / n,
e: what the sorting substep's G2P costs over a plain one, as it moves every particle to its new
slot: the fit of G2P ms a substep = g + e / cadence, per scene) and a fallback particle's cost in
pieces (f / b). On the GPU:

    python lab/cadence_fit.py --out DIR        # bench blocks and both hero shots
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

CADENCES = (32, 16, 8, 4, 2, 1)


def measure(label, solver, state, t, span, cadence, rows, restore=None):
    import warp as wp
    from shot_profile import kernel_split

    from mpmfx.bench.gpu import sort_ms

    da = solver._device_advance
    da.p2g = "brick"  # (the CPU's default is the reference P2G: --smoke runs the brick one there too)
    da.sort_every = cadence
    if restore is not None:
        state, t = restore()
    solver.advance(state, t, t + span)  # captures this cadence's graphs
    t += span
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    rep = solver.advance(state, t, t + span)
    wp.synchronize_device(solver.device)
    wall = time.perf_counter() - t0
    t += span
    ms, rep2 = kernel_split(solver, state, t, t + span)
    t += span
    k = rep2.substeps + rep2.rejected_substeps
    frag = np.asarray(da.frag_total, np.float64)  # (advance zeroes the scatter's own counts each chunk)
    row = {
        "scene": label,
        "det": int(solver.config.deterministic),
        "particles": state.n,
        "sort_every": cadence,
        "ms_substep": 1e3 * wall / max(1, rep.substeps + rep.rejected_substeps),
        "ms_scatter": sum(v for n, v in ms.items() if "scatter" in n) / k,
        "ms_g2p": sum(v for n, v in ms.items() if "g2p" in n) / k,
        "pieces": (frag[0] + frag[1]) / k,
        "fallbacks": frag[2] / k,
        "ms_sort": sort_ms(solver, state, whole=True),
        "substeps": k,
    }
    rows.append(row)
    print(json.dumps(row), flush=True)
    return state, t


def blocks(rows, device):
    from mpmfx.bench.gpu import scene
    from mpmfx.mpm import Solver, SolverConfig

    for name, g in (("Mushy", 256), ("Water", 256), ("Water", 128)):
        mats, parts, colliders = scene(name, g)
        cfg = SolverConfig(grid_n=g, deterministic=False)
        solver = Solver(mats, cfg, colliders=colliders, device=device)
        state = solver.init_state(parts)
        span = 50 * cfg.cfl * cfg.dx / max(m.wave_speed() for m in mats)
        t = 0.0
        for _ in range(2):
            solver.advance(state, t, t + span)
            t += span
        for c in CADENCES:
            state, t = measure(f"{name} {g}", solver, state, t, span, c, rows)


def shots(rows, device, names, cache, smoke=False):
    from shot_profile import build

    from mpmfx.bench.shots import smoke_overrides

    for name in names:
        extra = smoke_overrides(24, 10) if smoke else []
        solver, state, shot = build(name, ["solver.deterministic=true", *extra], cache, device)
        fps = shot.shot.fps
        for f in range(1, 4):
            solver.advance(state, (f - 1) / fps, f / fps)
        ck = solver.checkpoint(state, 3 / fps)
        for c in CADENCES:
            measure(name, solver, None, None, 1 / fps, c, rows, restore=lambda: solver.restore(ck))


def fit(rows):
    rows = [r for r in rows if r["ms_scatter"] > 0]  # (CPU: no kernel timing)
    if len(rows) < 3:
        return {}
    A = np.array([[r["particles"], r["pieces"], r["fallbacks"]] for r in rows], np.float64)
    y = np.array([r["ms_scatter"] for r in rows], np.float64)
    scale = A.max(axis=0)
    coef, *_ = np.linalg.lstsq(A / scale, y, rcond=None)
    a, b, f = coef / scale
    moves = {}  # per scene: ms a sorting substep's G2P adds (slope of G2P ms against 1 / cadence)
    for scene in {r["scene"] for r in rows}:
        rs = [r for r in rows if r["scene"] == scene]
        slope, _ = np.polyfit([1.0 / r["sort_every"] for r in rs], [r["ms_g2p"] for r in rs], 1)
        moves[scene] = max(0.0, float(slope))
    sort_per_particle = np.median([(r["ms_sort"] + moves[r["scene"]]) / r["particles"] for r in rows])
    out = {
        "ms_per_particle": a,
        "ms_per_piece": b,
        "ms_per_fallback": f,
        "sort_ms_per_particle": sort_per_particle,
        "move_ms": moves,
        "SORT_PIECES": sort_per_particle / b if b > 0 else None,
        "FALLBACK_PIECES": f / b if b > 0 else None,
        "residual_ms": float(np.abs(A @ (coef / scale) - y).max()),
    }
    print("FIT", json.dumps(out), flush=True)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.environ.get("OUT", "profile_out"))
    ap.add_argument("--shots", nargs="*", default=["hero_dam", "hero_castle"])
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--no-blocks", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="CPU size shots (tests the script)")
    a = ap.parse_args()
    rows = []
    if not a.no_blocks:
        blocks(rows, a.device)
    shots(rows, a.device, a.shots, Path("/tmp/mpmfx-cadence-cache"), smoke=a.smoke)
    out = fit(rows)
    Path(a.out).mkdir(parents=True, exist_ok=True)
    (Path(a.out) / "cadence_fit.json").write_text(json.dumps({"rows": rows, "fit": out}, indent=1))


if __name__ == "__main__":
    main()
