"""`mpmfx bench surface`: the surfacer on particles sampled in analytic shapes (validation.md 6).

Thin wrapper over `mpmfx.surface.bench`: --quick runs 100k particles (CPU-sized); the full run
1M and 10M (GPU). Writes surface.csv/json under --out.
"""
from __future__ import annotations


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    from mpmfx.bench.report import write_rows
    from mpmfx.surface.bench import HEADER, bench_surface
    counts = (100_000,) if quick else (1_000_000, 10_000_000)
    print(HEADER)
    rows = bench_surface(counts, ("sphere", "torus", "box"), ("lattice", "random"), device)
    write_rows(rows, out, "surface")
    return 0
