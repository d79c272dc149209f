"""`mpmfx bench ...`: speed and accuracy benchmarks. Run the full sweeps on the GPU.

Each benchmark prints one table, and writes CSV/JSON (and a PNG plot where it has one) under
`--out` (default renders/bench/). Every row names the device it ran on.
"""

from __future__ import annotations

import importlib
import sys

MODULES = {
    "accuracy": "mpmfx.bench.accuracy",
    "oscillation": "mpmfx.bench.oscillation",
    "surface": "mpmfx.bench.surface",
    "solver": "mpmfx.bench.solver",
    "gpu": "mpmfx.bench.gpu",
    "voxelise": "mpmfx.bench.voxelise",
    "shots": "mpmfx.bench.shots",
    "shot": "mpmfx.bench.shot",
    "surface-times": "mpmfx.bench.surface_times",
    "collapse": "mpmfx.bench.collapse",
}
# The options only some benchmarks take (the CLI's flags), and which take them.
OWN = {
    "peers": ("surface", "surface-times"),
    "counts": ("surface", "surface-times"),
    "shot": ("shot",),
    "overrides": ("shot",),
    "cache": ("shot",),
    "overlap": ("shot",),
    "sizes": ("collapse",),
}
UNSET = {"overrides": [], "overlap": True}  # what a flag holds when it is not given


def main(what: str, *, quick: bool = False, device: str | None = None, out: str = "renders/bench", **options) -> int:
    """Run benchmark `what`; `options` are the ones of OWN (None or unset: the benchmark's defaults)."""
    given = {k: v for k, v in options.items() if v is not None and v != UNSET.get(k)}
    if wrong := [k for k in given if what not in OWN[k]]:
        flag = "--" + wrong[0].replace("overrides", "set").replace("overlap", "no-overlap")
        print(f"error: {flag} belongs to `mpmfx bench {' / '.join(OWN[wrong[0]])}`, not `{what}`", file=sys.stderr)
        return 2
    own = {k: options.get(k) for k in OWN if what in OWN[k] and k in options}
    return importlib.import_module(MODULES[what]).main(quick=quick, device=device, out=out, **own)
