"""Halo volume of a domain-decomposed simulation, measured from a shot's cached particle frames.

    python lab/halo_volume.py pipeline/shots/jelly_splash.toml [--cache cache] [--out halo.csv]

For K = 2, 4, 8 subdomains (particle-balanced slabs along the axis the material spans most, and
for 8 also 2x2x2 median splits), per frame: each particle belongs to the subdomain holding it;
its quadratic B-spline stencil (3x3x3 nodes from floor(x/dx - 0.5)) writes grid nodes; a node
written by a particle of another subdomain is a halo node of that pair. Per substep a
Claymore-style step sends every halo node twice: the P2G partial sums to the owner (the
deterministic solver's int64 fixed-point channels: 4, or 7 with multi_field normals), and the
updated grid velocity back for G2P (vec3 float32). Halo blocks count whole 4^3 blocks, the unit
Claymore exchanges. Migrants: particles whose subdomain changed since the last frame, per
substep. Substeps per frame come from the simulation's QA files. Prints one table; writes CSV.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys

import numpy as np

from mpmfx.io.frames import ParticleFrame
from mpmfx.stages.runner import load_shot

BLOCK = 4  # Claymore's grid block edge (nodes)
PARTICLE_BYTES = 128  # x, v, C, F, Jp, J, material, body, volume, ids: ~32 floats


def owners(x: np.ndarray, layout: str, k: int) -> np.ndarray:
    """Subdomain per particle: balanced slabs (k parts) along the widest axis, or 2x2x2 medians."""
    if layout == "slabs":
        axis = int(np.argmax(np.ptp(x, axis=0)))
        cuts = np.quantile(x[:, axis], np.arange(1, k) / k)
        return np.searchsorted(cuts, x[:, axis]), ([axis], [cuts])
    own = np.zeros(len(x), np.int64)
    cut_list = []
    for axis in range(3):
        c = np.median(x[:, axis])
        own = own * 2 + (x[:, axis] >= c)
        cut_list.append(np.array([c]))
    return own, (list(range(3)), cut_list)


def node_owner(nodes: np.ndarray, dx: float, layout: str, geometry) -> np.ndarray:
    """Subdomain of grid nodes (integer index, (m,3)) under the same cuts as the particles."""
    axes, cuts = geometry
    pos = nodes * dx
    if layout == "slabs":
        return np.searchsorted(cuts[0], pos[:, axes[0]])
    own = np.zeros(len(nodes), np.int64)
    for axis, c in zip(axes, cuts):
        own = own * 2 + (pos[:, axis] >= c[0])
    return own


def halo(xg: np.ndarray, dx: float, layout: str, k: int):
    """xg: particle positions in grid units from the domain corner. Returns (halo nodes, halo
    blocks, busiest subdomain's halo nodes, active nodes, owner per particle)."""
    own, geometry = owners(xg * dx, layout, k)
    base = np.floor(xg - 0.5).astype(np.int64)
    offs = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    n_grid = int(base.max()) + 4
    touched = (base[:, None, :] + offs[None]).reshape(-1, 3)
    p_own = np.repeat(own, 27)
    lin = (touched[:, 0] * n_grid + touched[:, 1]) * n_grid + touched[:, 2]
    active = np.unique(lin)
    n_own = node_owner(touched, dx, layout, geometry)
    foreign = p_own != n_own
    pairs = np.unique(np.stack([p_own[foreign], lin[foreign]], 1), axis=0)
    blocks = np.unique(np.stack([p_own[foreign], *(touched[foreign] // BLOCK).T], 1), axis=0)
    per_sender = np.bincount(pairs[:, 0], minlength=k)
    return len(pairs), len(blocks), int(per_sender.max()), len(active), own


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shot")
    ap.add_argument("--cache", default=None)
    ap.add_argument("--out", default=None, help="CSV path (default: print only)")
    args = ap.parse_args()
    run = load_shot(args.shot, cache_root=args.cache, quiet=True, workers=1)
    entry = run.entries()["simulate"]
    frames = entry.done_frames(ParticleFrame.EXT)
    if not frames:
        print(f"no cached simulation at {entry.root}: run `mpmfx run {args.shot} --until simulate` first")
        return 1
    shot = run.shot
    dx = shot.domain.size / shot.domain.grid_n
    origin = np.asarray(shot.domain.origin)
    det, multi = shot.solver.deterministic, shot.solver.multi_field
    node_bytes = (8 * (7 if multi else 4) if det else 4 * (7 if multi else 4)) + 12
    rows = []
    for layout, k in (("slabs", 2), ("slabs", 4), ("slabs", 8), ("2x2x2", 8)):
        prev = None
        for f in frames:
            p = ParticleFrame.read(entry.frame_path(f, ParticleFrame.EXT))
            xg = (p.x - origin) / dx
            nodes, blocks, busiest, active, own = halo(xg, dx, layout, k)
            qa = entry.root / "qa" / f"{f:04d}.json"
            substeps = json.loads(qa.read_text())["substeps"] if qa.is_file() else 0
            migrants = 0 if prev is None else int(np.sum(prev[p.id] != own)) if len(prev) > p.id.max() else 0
            full = np.full(int(p.id.max()) + 1, -1)
            full[p.id] = own
            prev = full
            rows.append(
                {
                    "layout": layout,
                    "k": k,
                    "frame": f,
                    "particles": len(p.x),
                    "active_nodes": active,
                    "halo_nodes": nodes,
                    "halo_blocks": blocks,
                    "busiest_sender_nodes": busiest,
                    "bytes_per_substep": nodes * node_bytes,
                    "block_bytes_per_substep": blocks * BLOCK**3 * node_bytes,
                    "substeps": substeps,
                    "migrants_per_substep": migrants / substeps if substeps else 0.0,
                }
            )
    if args.out:
        with open(args.out, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    print(
        f"{shot.shot.name}: grid {shot.domain.grid_n}, {rows[0]['particles']} particles, {len(frames)} frames, "
        f"{node_bytes} B per halo node and substep (deterministic={det}, multi_field={multi})"
    )
    print(
        "| layout | K | halo nodes (mean / max) | % of active nodes | 4^3 halo blocks (mean) | "
        "KB per substep, nodes / blocks (max) | migrants per substep (mean) |"
    )
    print("|---|---|---|---|---|---|---|")
    for layout, k in (("slabs", 2), ("slabs", 4), ("slabs", 8), ("2x2x2", 8)):
        sel = [r for r in rows if r["layout"] == layout and r["k"] == k]
        h = np.array([r["halo_nodes"] for r in sel])
        frac = np.array([r["halo_nodes"] / r["active_nodes"] for r in sel])
        print(
            f"| {layout} | {k} | {h.mean():.0f} / {h.max()} | {100 * frac.mean():.1f} | "
            f"{np.mean([r['halo_blocks'] for r in sel]):.0f} | "
            f"{max(r['bytes_per_substep'] for r in sel) / 1e3:.0f} / "
            f"{max(r['block_bytes_per_substep'] for r in sel) / 1e3:.0f} | "
            f"{np.mean([r['migrants_per_substep'] for r in sel[1:]]):.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
