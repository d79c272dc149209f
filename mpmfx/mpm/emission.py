"""Particles that enter during the run (emitters, late objects), and the device memory a run needs.

A particle with a birth time is in the state from the start, dormant: alive = 0, so P2G skips
it and G2P leaves its position and velocity as they are (the emitted ones). At the start of
each substep, before P2G, `activate` wakes every dormant particle whose birth has come (birth
<= the substep's start on the shot clock) and marks it born (birth = +inf), so a particle
removed at the domain edge later (also alive = 0) never comes back. A rejected substep redoes
the same start time, so waking again there changes nothing.

`State.birth` is indexed by particle (State.pid), not by storage slot: the brick P2G's sorts move
the slots, never the births. The brick P2G (a GPU's) sorts a dormant particle last, outside every
segment, and a woken one gets a segment only at the next sort: so an advance in which particles
wake sorts at every substep (chunked.py; every chunk's first substep sorts anyway). Only a state made from Particles with births has the array, and
only then is the kernel launched: other scenes compile and run nothing of this.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .slots import Clock, Status
from .state import SceneFlags

__all__ = ["activate", "device_bytes", "pending_between"]


@wp.kernel(enable_backward=False, module="mpmfx_mpm_emission")
def activate(
    t_host: wp.float64,
    device_clock: int,
    time_scale: wp.float64,
    clk: wp.array(dtype=wp.float64),
    pid: wp.array(dtype=wp.int32),
    birth: wp.array(dtype=wp.float32),
    alive: wp.array(dtype=wp.int32),
):
    """Wake the slots whose particle's birth (s, shot clock) is at or before the substep's start:
    t_host (the host loop), or the device stepper's T0 + DONE / time_scale (stepper.py)."""
    slot = wp.tid()
    t = t_host
    if device_clock != 0:
        if int(clk[Clock.STATUS]) != Status.RUNNING:
            return
        t = clk[Clock.T0] + clk[Clock.DONE] / time_scale
    p = pid[slot]
    b = birth[p]
    if alive[slot] == 0 and wp.float64(b) <= t:
        alive[slot] = 1
        birth[p] = wp.inf


def pending_between(birth_host: np.ndarray | None, t0: float, t1: float) -> bool:
    """Whether any birth (s, sorted) falls in [t0, t1]: an advance over it wakes particles."""
    if birth_host is None or len(birth_host) == 0:
        return False
    i = np.searchsorted(birth_host, t0, side="left")
    return bool(i < len(birth_host) and birth_host[i] <= t1)


def device_bytes(n: int, flags: SceneFlags, grid_n: int, *, deterministic: bool, births: bool, gpu: bool = True) -> int:
    """Estimated device memory (bytes) of a run of n particles: the particle buffers (two
    copies: current and next substep), the constants (two copies on a GPU: the brick P2G's
    sorts), variation factors, births, the brick P2G's scratch, and the dense grid. An estimate for the budget
    line before a run, not an allocator's count (Warp's own pools and the kernels come on top)."""
    per = 12 + 12 + 36 + 4 + 4  # x, v, C, Jp, alive
    per += (36 + 24) if flags.solid else 0  # F, tau
    per += 4 if flags.water else 0  # J
    consts = 6 * 4 * (2 if gpu else 1)  # mass, volume, material, body, field_id, pid
    consts += 20 if flags.varied else 0  # the variation factors (one copy: read by particle)
    brick = 28 if gpu else 0
    nodes = (grid_n + 1) ** 3
    grid = nodes * (12 + (4 * 8 if deterministic else 16))  # grid_v, and fixed-point or float mass+momentum
    return int(n * (2 * per + consts + brick + (4 if births else 0)) + grid)
