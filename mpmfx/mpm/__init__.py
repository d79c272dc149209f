"""mpmfx.mpm — explicit MLS-MPM solver on Warp (imports numpy and warp only).

The solver works in the normalised domain [0,1]^3 with grid_n cells per axis; every
input and output here is in domain units and seconds (see the reference guide §2).
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
