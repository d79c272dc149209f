"""Timing probe for issue 14 (not a product path), on the GPU: how much the particles' storage
order costs the brick P2G, which reads every particle through its sorted order `idx`.

The bench's blocks are stored in lattice order, so a brick's particles sit in a few runs of
consecutive ids. This runs the same scenes with the particles stored (a) as built, (b) already
in brick order (what a P2G that keeps the particle arrays themselves sorted would read) and
(c) shuffled (a shot after its particles have mixed), ms a substep by phase.

    python3 scripts/order_probe.py --out $OUT [--cases Mushy:128,Water:256]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import mpmfx.bench.gpu as bench


def brick_order(x: np.ndarray, grid_n: int) -> np.ndarray:
    """Permutation putting particles in the brick P2G's sort order (brick, then corner node)."""
    b = np.maximum(np.floor(x * grid_n - 0.5).astype(np.int64), 0)
    nb = -(-(grid_n + 1) // 4)
    brick = ((b[:, 0] // 4) * nb + b[:, 1] // 4) * nb + b[:, 2] // 4
    corner = ((b[:, 0] % 4) * 4 + b[:, 1] % 4) * 4 + b[:, 2] % 4
    return np.argsort(brick * 64 + corner, kind="stable")


BUILT = bench.scene


def ordered_scene(order: str):
    def scene(name, grid_n):
        mats, parts, colliders = BUILT(name, grid_n)
        if order == "built":
            return mats, parts, colliders
        perm = (brick_order(parts.x, grid_n) if order == "bricks"
                else np.random.default_rng(0).permutation(len(parts.x)))
        fields = {k: getattr(parts, k)[perm] for k in ("x", "v", "volume", "material", "body")}
        return mats, type(parts)(**fields), colliders

    return scene


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="profile_out")
    ap.add_argument("--cases", default="Mushy:128,Water:128,Mushy:256,Water:256")
    a = ap.parse_args()
    gbs = bench.copy_bandwidth("cuda:0")
    rows = []
    keys = ("G_per_s", "ms_substep", "ms_p2g", "ms_g2p", "ms_sort", "sort_every")
    for case in a.cases.split(","):
        name, g = case.split(":")
        for order in ("built", "bricks", "shuffled"):
            bench.scene = ordered_scene(order)
            r = bench.safe_case(name, int(g), False, "cuda:0", gbs)
            r["order"] = order
            rows.append(r)
            print(name, g, order, " ".join(f"{k}={r.get(k, float('nan')):.3f}" for k in keys), flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "order_probe.json").write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
