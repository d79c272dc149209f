"""The solver's slot tables, declared once: statistic slots, counter slots, wall codes.

Kernels use these IntEnums directly (Warp folds an IntEnum member into a constant); the
stepper reads the same names on the host. Plain Python, so the shot schema can import it.
"""

from __future__ import annotations

import enum

__all__ = ["Stat", "Count", "REJECTING", "WallCode", "Clock", "Status"]


class Stat(enum.IntEnum):
    """float32 slots of the per-substep statistics G2P reduces (atomic max / min)."""

    MAX_SPEED = 0  # |v| max, domain/s
    MAX_HARDENING = 1  # largest snow hardening factor exp(xi (1 - Jp))
    WATER_J_MIN = 2  # smallest water J
    J_MIN = 3  # J range over all particles (J_MIN > J_MAX: no particle reported)
    J_MAX = 4

    @classmethod
    def initial(cls) -> list[float]:
        """Value of each slot before a substep: the identity of its reduction."""
        start = {cls.MAX_SPEED: 0.0, cls.MAX_HARDENING: 0.0, cls.WATER_J_MIN: 1e30, cls.J_MIN: 1e30, cls.J_MAX: -1e30}
        return [start[s] for s in cls]


class Count(enum.IntEnum):
    """int32 counter slots written by G2P and the grid update; PER_MATERIAL is the first of
    one slot per material (particles of that material that made the substep invalid)."""

    NONFINITE = 0  # particle state non-finite: substep rejected
    TOO_FAR = 1  # particle moved more than a cell: substep rejected
    LOST = 2  # particles removed at the domain edge (REMOVE mode)
    GRID_NONFINITE = 3  # non-finite grid velocity: substep rejected
    INVERTED = 4  # trial F inverted and mirrored back out (not a rejection)
    PER_MATERIAL = 5

    @classmethod
    def size(cls, n_materials: int) -> int:
        return cls.PER_MATERIAL + n_materials


# the counters whose non-zero value rejects a substep
REJECTING = (Count.NONFINITE, Count.TOO_FAR, Count.GRID_NONFINITE)


class WallCode(enum.IntEnum):
    """Device code of each `config.WallType` (same names; WallType.code maps to these)."""

    STICKY = 0
    SLIP = 1
    SEPARATE = 2


class Clock(enum.IntEnum):
    """float64 slots of the device stepper's clock (`stepper.py`): the host's `advance` loop
    variables, kept on the device so a chunk of substeps runs without a host round trip."""

    DONE = 0  # simulated seconds done in this advance
    TOTAL = 1  # simulated seconds this advance must cover
    DT_SCALE = 2  # StepperClock fields, same meaning
    MAX_SPEED = 3
    MAX_HARDENING = 4
    WATER_J_MIN = 5
    LAST_DT = 6
    SUBSTEPS = 7
    N_SUB = 8  # accepted substeps in this advance
    N_REJ = 9  # rejected substeps in this advance
    DT_MIN = 10  # report: smallest / largest accepted dt
    DT_MAX = 11
    VMAX = 12
    CFL_USED = 13
    J_MIN = 14
    J_MAX = 15
    LOST = 16
    INVERTED = 17
    STATUS = 18  # a Status
    DT = 19  # dt of the substep in flight
    LAST = 20  # 1 when the substep in flight lands on the end of the advance
    DT_CFL = 21  # the CFL dt of the last substep begun (for error messages)
    HAS_BAD = 22  # 1 once a substep of this advance was rejected (last_bad holds its counts)
    T0 = 23  # shot time (s) at the start of this advance: poses the colliders
    T1 = 24  # shot time (s) at its end


class Status(enum.IntEnum):
    """Clock.STATUS: why the device stepper stopped (RUNNING: it did not)."""

    RUNNING = 0
    FINISHED = 1  # landed on the end of the advance
    DT_TOO_SMALL = 2  # the CFL dt fell below dt_min: the host raises
    TOO_MANY = 3  # max_substeps_per_frame reached: the host raises
    REJECTED = 4  # a substep was rejected: the chunk stops, the host starts the next one
