"""mpmfx.mpm — explicit MLS-MPM solver on Warp (imports numpy and warp only).

The solver works in the normalised domain [0,1]^3 with grid_n cells per axis; every
input and output here is in domain units and seconds (docs/physics.md, "The method").

    solver = Solver([preset("Soft"), preset("Water")], SolverConfig(grid_n=64, damping=1.0))
    state = solver.init_state(Particles(x, v, volume, material, body))
    for f in range(frames):
        report = solver.advance(state, f / fps, (f + 1) / fps)   # StepReport
        frame = solver.state_to_numpy(state)                      # x, v, F / J, Jp, ...
    ckpt = solver.checkpoint(state, t)                            # exact resume: restore(ckpt)

Names load lazily (PEP 562): `mpmfx.mpm.config` and `mpmfx.mpm.materials` are plain Python,
so the shot schema reads the solver's defaults from them without starting Warp.
"""

import importlib

_WHERE = {
    "AnimatedMesh": "animated",
    "Collider": "colliders",
    "ColliderKind": "colliders",
    "OutOfDomain": "config",
    "SolverConfig": "config",
    "WallType": "config",
    "PRESETS": "materials",
    "Material": "materials",
    "Mode": "materials",
    "preset": "materials",
    "Particles": "particles",
    "SimulationError": "errors",
    "Solver": "solver",
    "StepReport": "report",
    "State": "state",
}
__all__ = list(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'mpmfx.mpm' has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
