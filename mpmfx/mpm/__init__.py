"""mpmfx.mpm — explicit MLS-MPM solver on Warp (imports numpy and warp only).

The solver works in the normalised domain [0,1]^3 with grid_n cells per axis; every
input and output here is in domain units and seconds (see the reference guide §2).

    solver = Solver([preset("Soft"), preset("Water")], SolverConfig(grid_n=64, damping=1.0))
    state = solver.init_state(Particles(x, v, volume, material, body))
    for f in range(frames):
        report = solver.advance(state, f / fps, (f + 1) / fps)   # StepReport
        frame = solver.state_to_numpy(state)                      # x, v, F / J, Jp, ...
    ckpt = solver.checkpoint(state, t)                            # exact resume: restore(ckpt)
"""

from .colliders import Collider, ColliderKind
from .config import OutOfDomain, SolverConfig, WallType
from .materials import PRESETS, Material, Mode, preset
from .solver import Particles, SimulationError, Solver, StepReport
from .state import State

__all__ = [
    "Mode", "Material", "PRESETS", "preset", "SolverConfig", "WallType", "OutOfDomain",
    "Collider", "ColliderKind", "Particles", "Solver", "State", "StepReport", "SimulationError",
]
