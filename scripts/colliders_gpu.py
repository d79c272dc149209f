"""The mixed scene with a moving collider (`mpmfx bench gpu`'s Mixed rows): colliders posed
on the device (device stepper) against the host loop, back to back. Prints one table."""
import sys

import warp as wp

from mpmfx.bench.gpu import COLS, copy_bandwidth, safe_case
from mpmfx.bench.report import print_table

grid = int(sys.argv[1]) if len(sys.argv) > 1 else 128
wp.init()
bw = copy_bandwidth(None)
rows = [safe_case("Mixed", grid, det, None, bw, substeps=64, path=path)
        for det in (False, True) for path in ("device", "host")]
print_table(rows, COLS)
