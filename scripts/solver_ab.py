"""Before/after of a solver change on the GPU: selected `bench gpu` scenes through
Solver.advance(), one table. Run once per tree, back to back on the same machine:

    PYTHONPATH=/opt/wp/site:.base python3 scripts/solver_ab.py --label before
    PYTHONPATH=/opt/wp/site:$PWD python3 scripts/solver_ab.py --label after

(.base: a copy of the earlier commit's mpmfx package, e.g. `git archive HEAD~1 mpmfx | tar -x -C .base`.)
Rows also go to $OUT/ab_<label>.csv when OUT is set.
"""
import argparse
import csv
import os

import mpmfx
from mpmfx.bench.gpu import copy_bandwidth, safe_case

CASES = [("Mushy", 128, False), ("Mushy", 128, True), ("Water", 128, False), ("Mushy", 256, False),
         ("Mushy", 256, True), ("Granular", 256, False), ("Elastic", 256, False), ("Water", 256, False),
         ("Water", 256, True)]
COLS = ["scene", "grid_n", "det", "substeps", "G_per_s", "ms_substep", "ms_p2g", "ms_grid", "ms_g2p", "ms_clear",
        "ms_sort", "sort_every", "captures", "B_per_particle"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--label", required=True)
    ap.add_argument("--cases", help="scene:grid:det,... (default: the list above)")
    a = ap.parse_args()
    cases = CASES if not a.cases else [(s, int(g), d == "1") for s, g, d in (c.split(":") for c in a.cases.split(","))]
    print(a.label, "mpmfx from", os.path.dirname(mpmfx.__file__), flush=True)
    gbs = copy_bandwidth("cuda:0")
    rows = []
    for scene, g, det in cases:
        r = safe_case(scene, g, det, "cuda:0", gbs)
        rows.append(r)
        print(a.label, " ".join(f"{k}={r.get(k):.3f}" if isinstance(r.get(k), float) else f"{k}={r.get(k)}"
                                for k in COLS + ["device", "error"] if k in r), flush=True)
    if os.environ.get("OUT"):
        with open(os.path.join(os.environ["OUT"], f"ab_{a.label}.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=["label"] + COLS + ["device"], extrasaction="ignore")
            w.writeheader()
            for r in rows:
                w.writerow({"label": a.label, **r})


if __name__ == "__main__":
    main()
