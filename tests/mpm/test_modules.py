"""The Warp modules a scene's solver launches are known before it exists (mpm/modules.py), so a
run compiles them ahead: every module a run loads is listed, and none it never loads."""

from __future__ import annotations

import numpy as np
import pytest
from warp._src.context import Module

from mpmfx.mpm import Solver
from mpmfx.mpm.config import SolverConfig
from mpmfx.mpm.materials import preset
from mpmfx.mpm.modules import solver_modules
from mpmfx.mpm.readback import HostStaging
from tests.mpm.mpm_helpers import block, concat

FPS = 24.0


@pytest.mark.parametrize("emission", [False, True])
def test_listed_modules_are_those_a_run_loads(monkeypatch, emission):
    mats = [preset("Soft"), preset("Water")] if emission else [preset("Soft")]
    cfg = SolverConfig(grid_n=16)
    listed = {m.name for m, _ in solver_modules(mats, cfg, device="cpu", emission=emission)}

    loaded = set()
    real = Module.load

    def load(self, *args, **kw):
        loaded.add(self.name)
        return real(self, *args, **kw)

    monkeypatch.setattr(Module, "load", load)
    parts = block((0.2, 0.1, 0.2), (0.5, 0.3, 0.5), grid_n=16)
    if emission:
        late = block((0.6, 0.5, 0.3), (0.8, 0.7, 0.7), grid_n=16, material=1, v=(0.0, -1.0, 0.0))
        parts = concat(parts, late)
        parts.birth = np.r_[np.zeros(len(parts.x) - len(late.x)), np.full(len(late.x), 0.5 / FPS)].astype(np.float32)
    solver = Solver(mats, cfg, device="cpu")
    state = solver.init_state(parts)
    solver.advance(state, 0.0, 1.0 / FPS)
    solver.host_arrays(state, staging=HostStaging(solver.device))  # (as the simulate stage reads a frame back)
    solver.report_sums(state)
    assert {n for n in loaded if "mpm" in n} == listed
