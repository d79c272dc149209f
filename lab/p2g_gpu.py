"""The brick P2G on a GPU: (1) it against the reference, deterministic and fast, over a
few hundred substeps; (1b) G2P compiled with CUDA fast math (the default, g2p.G2P_FAST_MATH)
against IEEE G2P; (2) their kernels one by one beside the reference P2G; (3) the paths through
advance() back to back. One table each; rows also under --out ($OUT or renders/bench).

    python lab/p2g_gpu.py [grid ...] [--skip agreement|fastmath|kernels|paths ...]   (grids: 128 256)
"""

import argparse
import json
import os
import time

import numpy as np
import warp as wp

from mpmfx.bench.gpu import COLS, copy_bandwidth, safe_case, scene
from mpmfx.bench.report import print_table
from mpmfx.mpm import Solver, SolverConfig, preset

OUT = os.environ.get("OUT", "renders/bench")


def stirred_run(name, grid_n, det, frames, p2g=None, restart=False):
    """(state as numpy, substeps) of the `name` block, its particles stirred (random velocities:
    runs keep changing make-up), after `frames` frames through the device stepper. p2g: the P2G
    path to force (None: the default); restart: a fresh solver resumes from a checkpoint taken at
    frame frames // 2."""
    mats, parts, _ = scene(name, grid_n)
    parts.v[:] = np.random.default_rng(1).normal(0.0, 0.5, parts.v.shape)
    cfg = SolverConfig(grid_n=grid_n, deterministic=det)

    def solver():
        s = Solver(mats, cfg, device="cuda", stepper="device")
        if p2g is not None:
            s._device_advance.p2g = p2g
        return s

    s = solver()
    st = s.init_state(parts)
    subs, ckpt = 0, None
    for f in range(frames):
        if restart and f == frames // 2:
            s = solver()
            st, _ = s.restore(ckpt)
        subs += s.advance(st, f / 24, (f + 1) / 24).substeps
        if f + 1 == frames // 2:
            ckpt = s.checkpoint(st, (f + 1) / 24)
    return s.state_to_numpy(st), subs


def agreement(grid_n=32, frames=6):
    """Max |brick P2G - reference| over x, v, F after `frames` stirred frames, Mushy and Water,
    both modes; and whether the brick path replays, and resumes from a checkpoint at frame
    frames // 2, bit for bit."""
    rows = []
    for name in ("Mushy", "Water"):
        for det in (True, False):

            def run(p2g, restart=False):
                return stirred_run(name, grid_n, det, frames, p2g, restart)

            (a, na), (b, nb) = run("reference"), run("brick")
            same = lambda o: all(np.array_equal(o[0][k], b[k]) for k in b)  # noqa: E731
            rows.append(
                {
                    "scene": name,
                    "det": int(det),
                    "p2g": "brick",
                    "substeps_ref": na,
                    "substeps": nb,
                    "max_dx": float(np.abs(a["x"] - b["x"]).max()),
                    "max_dv": float(np.abs(a["v"] - b["v"]).max()),
                    "max_dF": float(np.abs(a["F"] - b["F"]).max()) if "F" in a else 0.0,
                    "replay_identical": int(same(run("brick"))),
                    "resume_identical": int(same(run("brick", True))),
                }
            )
    print_table(rows, list(rows[0]))
    return rows


def fast_math_agreement(grid_n=48, frames=6):
    """Max |fast-math G2P - IEEE G2P| over x, v, F after `frames` stirred frames, Mushy, Granular
    and Water in both modes; beside it the IEEE run's own run-to-run difference (0 in
    deterministic mode, the float atomics' order in fast mode)."""
    from mpmfx.mpm.g2p import G2P_FAST_MATH, make_g2p
    from mpmfx.mpm.state import SceneFlags

    def g2p_modules(on):
        for mats in ([preset("Mushy")], [preset("Granular")], [preset("Water")]):
            for clock in (False, True):
                for sorting in (False, True):  # made first: making one sets its module's default
                    kernel = make_g2p(SceneFlags.of(mats), device_clock=clock, sorting=sorting)
                    wp.set_module_options({"fast_math": on}, module=kernel.module)

    rows = []
    for name in ("Mushy", "Granular", "Water"):
        for det in (True, False):
            g2p_modules(False)
            (a, na), (a2, _) = (stirred_run(name, grid_n, det, frames) for _ in range(2))
            g2p_modules(True)
            b, nb = stirred_run(name, grid_n, det, frames)
            row = {"scene": name, "det": int(det), "substeps_ieee": na, "substeps_fast": nb}
            for k in ("x", "v", "F"):
                if k in a:
                    row[f"max_d{k}"] = float(np.abs(a[k] - b[k]).max())
                    row[f"ieee_replay_d{k}"] = float(np.abs(a[k] - a2[k]).max())
            rows.append(row)
    g2p_modules(G2P_FAST_MATH)  # back to the shipped setting
    print_table(rows, list(rows[2]))
    return rows


def kernels(name, grid_n, det, p2g, sort1=False):
    """Device ms per substep of each P2G kernel over one advance (graphs off)."""
    mats, parts, _ = scene(name, grid_n)
    s = Solver(mats, SolverConfig(grid_n=grid_n, deterministic=det), device="cuda", stepper="device")
    da = s._device_advance
    da.p2g, da.sort_every, da.graphs = p2g, int(sort1), False
    st = s.init_state(parts)
    span = 32 * s.config.cfl * s.config.dx / max(m.wave_speed() for m in mats)
    s.advance(st, 0.0, span)
    wp.synchronize()
    wp.timing_begin(cuda_filter=wp.TIMING_ALL)
    rep = s.advance(st, span, 2 * span)
    res = wp.timing_end()
    k = rep.substeps + rep.rejected_substeps
    ms = {}
    for r in res:
        nm = r.name.split("(")[0].split(" ")[-1][:40]
        ms[nm] = ms.get(nm, 0.0) + r.elapsed / k
    row = {"scene": name, "grid_n": grid_n, "det": int(det), "p2g": p2g, "sort1": int(sort1), "substeps": k, "n": st.n}
    row.update({kk: round(v, 3) for kk, v in sorted(ms.items(), key=lambda kv: -kv[1])[:12]})
    print(json.dumps(row), flush=True)
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("grids", type=int, nargs="*", default=[128, 256], help="grid sizes of kernels and paths")
    ap.add_argument("--skip", nargs="+", default=[], choices=("agreement", "fastmath", "kernels", "paths"))
    ap.add_argument("--out", default=OUT, help="folder for p2g_gpu.json (default $OUT or renders/bench)")
    a = ap.parse_args()
    skip, grids = set(a.skip), a.grids
    os.makedirs(a.out, exist_ok=True)
    wp.init()
    print(wp.get_device("cuda").name)
    t0 = time.time()
    ag = agreement() if "agreement" not in skip else []
    print(f"agreement {time.time() - t0:.0f} s", flush=True)
    fm = fast_math_agreement() if "fastmath" not in skip else []
    ks = []
    for g in grids if "kernels" not in skip else ():
        for name in ("Mushy", "Water"):
            for p2g in ("reference", "brick"):
                ks.append(kernels(name, g, False, p2g))
    print(f"kernels {time.time() - t0:.0f} s", flush=True)
    bw = copy_bandwidth(None)
    rows = []
    for g in grids if "paths" not in skip else ():
        for name in ("Mushy", "Water"):
            for det, path in (
                (False, "device-unbinned"),
                (False, "device"),
                (False, "device-sort1"),
                (True, "device-unbinned"),
                (True, "device"),
            ):
                rows.append(safe_case(name, g, det, None, bw, substeps=50, path=path))
                print_table(rows[-1:], COLS)
    if rows:
        print_table(rows, COLS)
    print(f"total {time.time() - t0:.0f} s", flush=True)
    with open(os.path.join(a.out, "p2g_gpu.json"), "w") as f:
        json.dump({"agreement": ag, "fast_math": fm, "kernels": ks, "paths": rows}, f, indent=1, default=str)


if __name__ == "__main__":
    main()
