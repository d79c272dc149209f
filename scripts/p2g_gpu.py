"""P2G levers on the GPU, back to back (Mushy and Water, fast mode, through Solver.advance):
the reference P2G ("device") against the tiled one ("device-tiled", p2g_tiled.py), at the
given grids; and their agreement after a few frames of a falling block. Prints one table."""
import sys

import numpy as np
import warp as wp

from mpmfx.bench.gpu import COLS, copy_bandwidth, safe_case
from mpmfx.bench.report import print_table

grids = [int(g) for g in sys.argv[1:]] or [128, 256]
wp.init()
bw = copy_bandwidth(None)
rows = []
for g in grids:
    for name in ("Mushy", "Water"):
        for path in ("device", "device-tiled", "device"):  # the reference twice: the run's noise
            rows.append(safe_case(name, g, False, None, bw, substeps=64, path=path))
            print_table(rows[-1:], COLS)
print_table(rows, COLS)

from mpmfx.mpm import Solver, SolverConfig  # noqa: E402
from mpmfx.bench.gpu import scene  # noqa: E402
for name in ("Mushy", "Water"):
    out = {}
    for tiled in (False, True):
        mats, parts, _ = scene(name, 64)
        s = Solver(mats, SolverConfig(grid_n=64, deterministic=False))
        s._device_advance.tiled = tiled
        st = s.init_state(parts)
        reps = [s.advance(st, f / 24, (f + 1) / 24) for f in range(6)]
        out[tiled] = (s.state_to_numpy(st), [r.substeps for r in reps])
    (a, sa), (b, sb) = out[False], out[True]
    print(f"{name} grid 64, 6 frames: substeps {sa} vs {sb}; max |dx| {np.abs(a['x'] - b['x']).max():.3g} "
          f"max |dv| {np.abs(a['v'] - b['v']).max():.3g} (domain units)")
