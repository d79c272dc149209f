"""Host copies through reused buffers (readback.HostStaging): the same arrays as fresh copies,
and a frame's buffers are not overwritten until two frames later (the writer thread's margin)."""

import numpy as np

from mpmfx.mpm import Solver, SolverConfig
from mpmfx.mpm.materials import preset
from mpmfx.mpm.readback import HostStaging

from .mpm_helpers import block


def test_staged_copies_equal_fresh_ones_and_alternate_between_two_sets():
    s = Solver([preset("Mushy")], SolverConfig(grid_n=16), device="cpu")
    st = s.init_state(block((0.3, 0.2, 0.3), (0.6, 0.5, 0.6), grid_n=16))
    s.advance(st, 0.0, 1 / 24)
    staging = HostStaging(s.device)
    fresh = s.checkpoint(st, 0.0)
    first = s.checkpoint(st, 0.0, staging)
    assert fresh.keys() == first.keys()
    for k in fresh:
        assert np.array_equal(fresh[k], first[k]) and fresh[k].dtype == first[k].dtype, k
    kept = {k: first[k].copy() for k in ("x", "F")}
    s.advance(st, 1 / 24, 2 / 24)
    second = s.checkpoint(st, 1 / 24, staging)
    assert not np.shares_memory(first["x"], second["x"])
    assert np.array_equal(first["x"], kept["x"]) and np.array_equal(first["F"], kept["F"])  # still being written
    third = s.checkpoint(st, 1 / 24, staging)
    assert np.shares_memory(first["x"], third["x"])  # two frames later: the first set again
