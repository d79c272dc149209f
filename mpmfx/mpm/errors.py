"""Why the solver stopped: SimulationError and its messages, each naming the knob to change
(the reference loop, solver.py, and the device stepper, chunked.py, raise the same ones)."""

from __future__ import annotations

import math

from .materials import Mode
from .slots import Count
from .state import State

__all__ = ["SimulationError"]

_SYMPTOM = "Everything explodes / NaNs"  # the symptom row of the tutorial's tuning table the errors point at


class SimulationError(RuntimeError):
    """The solver cannot continue without a knob change; the message says which. `field`: the
    SolverConfig knob whose limit was hit ("dt_min", "max_substeps_per_frame") or None;
    `needed`: what would have passed it (the substep dt in s, or the substeps the frame needs),
    so a caller can phrase the advice in its own keys; `speed_bound`: the particles' speed, not
    the materials' wave speed, set the step (an initial velocity or a force, not a stiffness)."""

    def __init__(
        self, message: str, *, field: str | None = None, needed: float | None = None, speed_bound: bool = False
    ):
        super().__init__(message)
        self.field, self.needed, self.speed_bound = field, needed, speed_bound


def too_many(
    solver, state: State, t: float, t1: float, substeps: int, dt_cfl: float, remaining: float
) -> SimulationError:
    """`remaining`: simulated seconds still to go (sets `needed`, the substeps that would do)."""
    return SimulationError(
        f"t={t:.4f}s: {substeps} substeps did not reach t1={t1:.4f}s "
        f"(dt ~ {dt_cfl:.3g}s, c_max {solver.wave_speed(state.clock):.3g} domain/s). Raise "
        f"SolverConfig.max_substeps_per_frame, or lower youngs_modulus / bulk_modulus / grid_n",
        field="max_substeps_per_frame",
        needed=substeps + math.ceil(remaining / dt_cfl),
    )


def raise_too_small(solver, state: State, t: float, dt: float) -> None:
    bad = getattr(solver, "_last_bad", None)
    per_mat = [] if bad is None else bad[Count.PER_MATERIAL :]
    names = [describe_material(solver, i) for i, k in enumerate(per_mat) if k > 0] or [
        describe_material(solver, i) for i in range(len(solver.materials))
    ]
    n_bad = 0 if bad is None else int(bad[Count.NONFINITE] + bad[Count.TOO_FAR])
    what = (
        f"the last rejected substep had {n_bad} particle(s) non-finite or moving more than one cell"
        if bad is not None
        else "no substep was rejected; the CFL step is this small"
    )
    raise SimulationError(
        f"t={t:.4f}s: the substep fell to dt={dt:.3g}s < dt_min={solver.config.dt_min:g}s "
        f"({state.n} particles, max speed {state.clock.max_speed:.3g} domain/s, c_max "
        f"{solver.wave_speed(state.clock):.3g} domain/s); {what}, in {', '.join(names)} "
        f"('{_SYMPTOM}'). Lower youngs_modulus / bulk_modulus or raise damping; "
        f"or lower SolverConfig.dt_min if this dt is intended (a lower cfl only shrinks dt further)",
        field="dt_min",
        needed=dt,
        speed_bound=state.clock.max_speed > solver.wave_speed(state.clock),
    )


def describe_material(solver, i: int) -> str:
    m = solver.materials[i]
    if m.mode == Mode.WATER:
        return f"material {i} (WATER, bulk_modulus={m.bulk_modulus:g})"
    return f"material {i} ({m.mode.name}, youngs_modulus={m.youngs_modulus:g})"
