"""`mpmfx bench surface`: the surfacer and its peers on particles sampled in analytic shapes.

Thin wrapper over `mpmfx.bench.surface_cases`: --quick runs 100k particles (CPU-sized) with
splashsurf where it is installed; the full run 1M and 10M (GPU) with every peer that is
installed (splashsurf on the CPU, Newton isotropic and anisotropic on the GPU), each method
timed as the median of 3 calls after a warm-up. All methods see the same particles. Prints one
table; writes surface.csv/json and surface.png (particles per second against mean surface
error, log-log; needs pyvista, skipped with a message without it) under --out. Then the
thin-sheet case (a disc one particle spacing thick, isotropic and anisotropic kernels, and
every installed peer): surface_sheet.csv/json; a real splash frame of water_dam
(mpmfx.bench.surface_splash): surface_splash.csv/json; and the flicker of a slowly moving block
over 10 frames (mpmfx.bench.surface_flicker): surface_flicker.csv/json.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from mpmfx.bench.plot import surface_plot
from mpmfx.bench.report import write_rows
from mpmfx.bench.surface_cases import HEADER, SHEET_COUNTS, bench_sheet, bench_surface
from mpmfx.bench.surface_flicker import FLICKER_COUNT, bench_flicker
from mpmfx.bench.surface_peers import PEERS, peer_missing
from mpmfx.bench.surface_splash import SPLASH_PARTICLES, bench_splash

QUICK_COUNTS = (100_000,)
FULL_COUNTS = (1_000_000, 10_000_000)


def choose_peers(peers: Sequence[str] | None, *, quick: bool) -> list[str]:
    """The peers to run: `peers` as asked (ValueError naming the fix for an unknown or missing
    one), or by default splashsurf for --quick and every peer for the full run, each only where
    its package is installed (the others are named on stdout)."""
    if peers is not None:
        unknown = [p for p in peers if p not in PEERS]
        if unknown:
            raise ValueError(f"--peers {' '.join(unknown)}: unknown; use any of {' '.join(PEERS)}")
        missing = [f"{p} ({peer_missing(p)})" for p in peers if peer_missing(p)]
        if missing:
            raise ValueError(f"--peers: not installed: {'; '.join(missing)}")
        return list(dict.fromkeys(peers))
    chosen = []
    for p in ("splashsurf",) if quick else PEERS:
        why = peer_missing(p)
        if why:
            print(f"peer {p} skipped: {why}")
        else:
            chosen.append(p)
    return chosen


def main(
    *,
    quick: bool = False,
    device: str | None = None,
    out: str = "renders/bench",
    peers: Sequence[str] | None = None,
    counts: Sequence[int] | None = None,
) -> int:
    """Run the sweep; 0 on success, 2 on bad --peers / --counts."""
    try:
        chosen = choose_peers(peers, quick=quick)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    counts = tuple(counts) if counts else (QUICK_COUNTS if quick else FULL_COUNTS)
    if min(counts) < 1000:
        print(f"error: --counts {' '.join(map(str, counts))}: use at least 1000 particles", file=sys.stderr)
        return 2
    print(HEADER)
    rows = bench_surface(
        counts, ("sphere", "torus", "box"), ("lattice", "random"), device, peers=chosen, repeats=1 if quick else 3
    )
    path = write_rows(rows, out, "surface")
    print(f"tables: {path} (+ .json)")
    try:
        print(f"plot: {surface_plot(rows, out)}")
    except ImportError as err:
        print(f"plot skipped: {err} (pip install pyvista to draw surface.png; the CSV/JSON are written)")
    except ValueError as err:  # nothing with a positive speed and error (empty meshes only)
        print(f"plot skipped: {err}")
    # the sheet, splash and flicker cases are small: every installed peer runs on them (Newton
    # too on the CPU) unless --peers chose; none is larger than the largest of --counts
    sheet_peers = chosen if peers is not None else choose_peers(None, quick=False)
    sheet = bench_sheet(min(SHEET_COUNTS["quick" if quick else "full"], max(counts)), device, peers=sheet_peers)
    print(f"thin sheet: {write_rows(sheet, out, 'surface_sheet')} (+ .json)")
    if max(counts) >= SPLASH_PARTICLES:
        print(f"splash frame: {write_rows(bench_splash(device, peers=sheet_peers), out, 'surface_splash')} (+ .json)")
    else:
        print(f"splash frame skipped: --counts below its {SPLASH_PARTICLES} particles")
    flicker = bench_flicker(min(FLICKER_COUNT, max(counts)), device, peers=sheet_peers)
    print(f"flicker: {write_rows(flicker, out, 'surface_flicker')} (+ .json)")
    return 0
