"""`mpmfx bench ...`: speed and accuracy benchmarks. Run the full sweeps on the GPU.

Each benchmark prints one table, and writes CSV/JSON (and a PNG plot where it has one) under
`--out` (default renders/bench/). Every row names the device it ran on.
"""
from __future__ import annotations

import importlib


def main(what: str, *, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    module = {"accuracy": "mpmfx.bench.accuracy", "surface": "mpmfx.bench.surface",
              "solver": "mpmfx.bench.solver"}[what]
    return importlib.import_module(module).main(quick=quick, device=device, out=out)
