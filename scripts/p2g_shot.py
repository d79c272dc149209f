"""Why the brick P2G is slower per particle in a shot than in the bench block: the shot's
segments (particles a brick, runs, window fallbacks) and the scatter's time per substep, as the
particles lie in memory and physically re-ordered into brick order, both modes.

    python3 scripts/p2g_shot.py hero_dam --frames 3 --out $OUT     # on the GPU
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parent)]
from shot_profile import build, kernel_split  # noqa: E402


def segments(solver, state) -> dict:
    """Statistics of the brick P2G's last sort, with the window test redone on the current x."""
    br = solver._device_advance._brick
    n = state.n
    nseg = int(br.n_seg.numpy()[0])
    start = br.start.numpy()[: nseg + 1]
    keys = br.keys.numpy()[:n]
    idx = br.idx.numpy()[:n]
    sizes = np.diff(start)
    valid = keys[: start[-1]]
    runs = 1 + int(np.count_nonzero(np.diff(valid) != 0)) if len(valid) else 0
    inv_dx = float(solver.config.grid_n)
    nb = -(-(solver.config.grid_n + 1) // 4)
    brick = valid // 64
    origin = np.stack([(brick // (nb * nb)) * 4 - 1, ((brick // nb) % nb) * 4 - 1, (brick % nb) * 4 - 1], 1)
    x = state.cur.x.numpy()[idx[: start[-1]]]
    b = np.floor(x * inv_dx - 0.5).astype(np.int64)
    loc = b - origin
    out = (loc.min(1) < 0) | (loc.max(1) > 5)
    return {"segments": nseg, "sorted": int(start[-1]), "mean_per_seg": float(sizes.mean()),
            "p10_p50_p90": [int(v) for v in np.percentile(sizes, [10, 50, 90])], "max_per_seg": int(sizes.max()),
            "segs_under_64": int((sizes < 64).sum()), "mean_run": float(len(valid) / max(1, runs)),
            "fallback_now": int(out.sum()),
            "marked_bricks": int(br.marks.numpy().sum()), "bricks": int(br.nb**3),
            "memory_coherence": float(np.mean(np.abs(np.diff(idx[: start[-1]].astype(np.int64))) == 1))}


def reorder(solver, state, t: float):
    """A new State with every particle array permuted into the brick P2G's current order."""
    data = solver.checkpoint(state, t)
    n = state.n
    idx = solver._device_advance._brick.idx.numpy()[:n]
    perm = np.concatenate([idx, np.setdiff1d(np.arange(n), idx)])[:n]
    for k, a in data.items():
        if isinstance(a, np.ndarray) and a.ndim >= 1 and a.shape[0] == n:
            data[k] = a[perm]
    st, _ = solver.restore(data)
    solver._device_advance._brick = None  # fresh order for the new state
    return st


def p2g_ms(solver, state, t0: float, t1: float) -> float:
    if not solver.device.is_cuda:  # (no kernel timing on the CPU: the smoke test checks the path)
        solver.advance(state, t0, t1)
        return float("nan")
    ms, rep = kernel_split(solver, state, t0, t1)
    k = max(1, rep.substeps + rep.rejected_substeps)
    return sum(v for n, v in ms.items() if "scatter" in n) / k


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("shots", nargs="*", default=["hero_dam"])
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--out", default=os.environ.get("OUT", "profile_out"))
    args = ap.parse_args(argv)
    import warp as wp
    wp.config.quiet = True
    from hero_gpu import smoke_overrides
    rows = []
    for name in args.shots:
        for det in (True, False):
            ov = (smoke_overrides(32, args.frames + 3) if args.smoke else []) + [f"solver.deterministic={str(det).lower()}"]
            if name.startswith("bench:"):  # the bench block (mpmfx bench gpu), e.g. bench:Water@256
                from mpmfx.bench.gpu import scene
                from mpmfx.mpm import Solver, SolverConfig
                mat, grid_n = name[6:].split("@")
                mats, parts, cols = scene(mat, int(grid_n))
                solver = Solver(mats, SolverConfig(grid_n=int(grid_n), deterministic=det), colliders=cols,
                                device=args.device)
                state, fps = solver.init_state(parts), 24
            else:
                solver, state, shot = build(name, ov, Path("/tmp/p2g_shot_cache"), args.device)
                fps = shot.shot.fps
            solver._device_advance.p2g = "brick"  # (already so on a GPU)
            for f in range(args.frames):
                solver.advance(state, f / fps, (f + 1) / fps)
            t = args.frames / fps
            span = 1.0 / (4 * fps)
            row = {"shot": name, "det": det, "n": state.n}
            row["p2g_ms_as_is"] = p2g_ms(solver, state, t, t + span)
            row.update(segments(solver, state))
            st2 = reorder(solver, state, t + span)
            solver.advance(st2, t + span, t + 2 * span)  # compiles nothing new; sorts afresh
            row["p2g_ms_reordered"] = p2g_ms(solver, st2, t + 2 * span, t + 3 * span)
            row["reordered"] = segments(solver, st2)
            print(json.dumps(row), flush=True)
            rows.append(row)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "p2g_shot.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
