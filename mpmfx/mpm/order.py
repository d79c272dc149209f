"""The particles' storage order (State.pid).

On a GPU the brick P2G keeps the particle arrays themselves in its sort order: a sorting
substep's G2P writes them there (p2g_brick.py), so the scatter reads consecutive slots as
consecutive memory and G2P gathers neighbouring grid nodes. Everything the host sees (frames,
checkpoints) is in particle order: these put it back.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

__all__ = ["in_particle_order", "to_slots"]


@wp.kernel(enable_backward=False)
def _to_particle_order(src: wp.array(dtype=Any), pid: wp.array(dtype=wp.int32), dst: wp.array(dtype=Any)):
    s = wp.tid()
    dst[pid[s]] = src[s]


def in_particle_order(a: wp.array, pid: wp.array) -> wp.array:
    """A device copy of the per-particle array `a` ((n,), or (3, n) row planes) in particle
    order; pid: (n,) int32, the particle each slot holds. Arrays of another length (a field
    no material needs, (1,)) are returned as they are."""
    n = pid.shape[0]
    if a.shape[-1] != n:
        return a
    out = wp.empty_like(a)
    for src, dst in ((a[r], out[r]) for r in range(a.shape[0])) if a.ndim == 2 else ((a, out),):
        wp.launch(_to_particle_order, dim=n, device=a.device, inputs=[src, pid, dst])
    return out


def to_slots(values: np.ndarray, pid: np.ndarray, n: int) -> np.ndarray:
    """Host array in particle order -> slot order (slot s holds particle pid[s]); arrays of
    another length than n are returned as they are."""
    return values[pid] if np.shape(values)[0] == n else values
