"""Issue 13 measurements on the GPU: the experiments section of `mpmfx bench accuracy` (full),
diagnostics of the sand runout at one aspect ratio, and production (GPU, float32) against
the numpy reference step (CPU, float64) on the same set-ups. Prints tables; writes under $OUT."""
import math
import os
import sys
import time

T0 = time.time()
OUT = os.environ.get("OUT", "/tmp/physics-out")
DEV = "cuda:0" if "--cpu" not in sys.argv else "cpu"


def stamp(msg):
    print(f"[{time.time() - T0:6.1f} s] {msg}", flush=True)


def diagnostics():
    """a = 2 at grid 128, one knob changed at a time from the Granular preset (phi 38)."""
    from mpmfx.bench import experiments as ex
    from mpmfx.mpm import preset
    rows = []
    variants = [
        ("compression (preset)", {}, {}, {}),
        ("plane_strain", {"friction_fit": "plane_strain"}, {}, {}),
        ("compression, no volume correction", {"volume_correction": False}, {}, {}),
        ("compression, Coulomb floor mu=tan(38)", {}, {"floor": "separate", "wall_friction": math.tan(math.radians(38))}, {}),
        ("compression, 2-cell wall band", {}, {}, {"boundary_cells": 2}),
        ("compression, E x4", {"youngs_modulus": 1600.0}, {}, {}),
        ("compression, run 8 sqrt(H/g)", {}, {"t_scale": 8.0}, {}),
        ("compression, phi 30", {"friction_angle": 30.0}, {}, {}),
        ("plane_strain, phi 30", {"friction_fit": "plane_strain", "friction_angle": 30.0}, {}, {}),
        ("plane_strain, phi 34", {"friction_fit": "plane_strain", "friction_angle": 34.0}, {}, {}),
    ]
    for name, mat_kw, run_kw, cfg in variants:
        mat = preset("Granular", **mat_kw)
        r = ex.column_collapse(a=2.0, grid_n=128, material=mat, ppz=1, device=DEV, config=cfg or None, **run_kw)
        e = r.extra
        rows.append({"variant": name, "runout": e["runout"], "runout_q": e["runout_q"], "law": e["law_runout"],
                     "error": e["runout"] / e["law_runout"] - 1, "height": e["height"], "max_speed_end": e["max_speed"],
                     "cells_across": e["cells_across"], "wall_s": r.wall_s, "device": r.device})
        stamp(f"diag {rows[-1]}")
    return rows


def extra_phi(phi):
    from mpmfx.bench import experiments as ex
    rows = []
    for a in (0.5, 1.0, 2.0, 4.0, 8.0):
        for n in (64, 128):
            r = ex.column_collapse(a=a, grid_n=n, fit="plane_strain", friction_angle=phi, ppz=1, device=DEV)
            e = r.extra
            rows.append({"case": f"quasi2d plane_strain phi {phi:g}", "a": a, "grid_n": n, "cells_across": e["cells_across"],
                         "runout": e["runout"], "law": e["law_runout"], "error": e["runout"] / e["law_runout"] - 1,
                         "height": e["height"], "law_height": e["law_height"], "device": r.device, "wall_s": r.wall_s})
            stamp(f"phi {rows[-1]}")
    return rows


def convergence():
    """Finer grids than the lab's for the repose fit: does the runout settle?"""
    from mpmfx.bench import experiments as ex
    rows = []
    for fit, phi, a, n in (("repose", 32.0, 0.5, 192), ("repose", 32.0, 2.0, 192), ("repose", 32.0, 8.0, 192),
                           ("repose", 32.0, 2.0, 256)):
        r = ex.column_collapse(a=a, grid_n=n, fit=fit, friction_angle=phi, ppz=1, device=DEV)
        e = r.extra
        lj = ex.runout_law(a, "lajeunesse2005")[0]
        rows.append({"fit": f"{fit} {phi:g}", "a": a, "grid_n": n, "cells_across": e["cells_across"],
                     "runout": e["runout"], "runout_q": e["runout_q"], "law_lube2005": e["law_runout"],
                     "error_lube2005": e["runout"] / e["law_runout"] - 1, "error_lajeunesse2005": e["runout"] / lj - 1,
                     "height": e["height"], "particles": r.particles, "wall_s": r.wall_s, "device": r.device})
        stamp(f"conv {rows[-1]}")
    return rows


def differential():
    from mpmfx.bench import experiments as ex
    rows = []
    for name, fn, kw in (("dam_break", ex.dam_break, dict(grid_n=24, width=0.25, ppz=1, t_star=(1.0, 2.0, 2.5))),
                         ("collapse a=2 plane_strain", ex.column_collapse, dict(grid_n=24, a=2.0, ppz=1, fit="plane_strain")),
                         ("collapse a=2 compression", ex.column_collapse, dict(grid_n=24, a=2.0, ppz=1))):
        p = fn(engine="warp", device=DEV, **kw)
        r = fn(engine="reference", **kw)
        key = "Zq" if "Zq" in p.extra else "runout_q"
        vp = p.extra[key][-1] if key == "Zq" else 1 + p.extra[key]
        vr = r.extra[key][-1] if key == "Zq" else 1 + r.extra[key]
        rows.append({"case": name, "metric": f"front/{'width' if key == 'Zq' else 'L0'}", "production": vp,
                     "reference": vr, "rel_diff": vp / vr - 1, "particles": p.particles, "steps": p.steps,
                     "device": p.device, "reference_s": r.wall_s})
        stamp(f"diff {rows[-1]}")
    return rows


def main():
    os.makedirs(OUT, exist_ok=True)
    from mpmfx.bench import accuracy
    from mpmfx.bench.report import print_table, write_rows
    parts = sys.argv[1:] or ["lab", "diag", "phi", "diff"]
    if "diff" in parts:
        write_rows(d := differential(), OUT, "differential")
        print_table(d)
    if "lab" in parts:
        accuracy.experiments(quick=False, device=DEV, out=OUT)
        stamp("lab done")
    if "conv" in parts:
        write_rows(d := convergence(), OUT, "sand_convergence")
        print_table(d)
    if "diag" in parts:
        write_rows(d := diagnostics(), OUT, "sand_diagnostics")
        print_table(d)
    if "phi" in parts:
        write_rows(d := extra_phi(30.0), OUT, "sand_phi30")
        print_table(d)
    stamp("all done")


if __name__ == "__main__":
    main()
