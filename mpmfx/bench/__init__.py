"""`mpmfx bench ...`: speed and accuracy benchmarks. Run the full sweeps on the GPU.

Each benchmark prints one table, and writes CSV/JSON (and a PNG plot where it has one) under
`--out` (default renders/bench/). Every row names the device it ran on.
"""

from __future__ import annotations

import importlib
import sys


def main(
    what: str,
    *,
    quick: bool = False,
    device: str | None = None,
    out: str = "renders/bench",
    peers: list[str] | None = None,
    counts: list[int] | None = None,
) -> int:
    """Run benchmark `what`; `peers` and `counts` are the options of `surface` and `surface-times`
    (None: their defaults)."""
    module = {
        "accuracy": "mpmfx.bench.accuracy",
        "oscillation": "mpmfx.bench.oscillation",
        "surface": "mpmfx.bench.surface",
        "solver": "mpmfx.bench.solver",
        "gpu": "mpmfx.bench.gpu",
        "voxelise": "mpmfx.bench.voxelise",
        "shots": "mpmfx.bench.shots",
        "surface-times": "mpmfx.bench.surface_times",
    }[what]
    own = {"peers": peers, "counts": counts} if what in ("surface", "surface-times") else {}
    if not own and (peers is not None or counts is not None):
        print(
            f"error: --peers / --counts belong to `mpmfx bench surface` and `surface-times`, not `{what}`",
            file=sys.stderr,
        )
        return 2
    return importlib.import_module(module).main(quick=quick, device=device, out=out, **own)
