"""The CPU thread policy shared by the surfacer's split launches and the frame writer.

MPMFX_SURFACE_THREADS sets the CPU thread count (default: the cores this process may use, at
most MAX_THREADS); 1 turns splitting off. `mpmfx.stages.parallel` sets it for each Dask worker
to that worker's share of the cores. Plain Python: no Warp, no numpy.
"""

from __future__ import annotations

import os

MAX_THREADS = 8
THREADS_ENV = "MPMFX_SURFACE_THREADS"  # the CPU thread count, where set (a Dask worker's share: mpmfx.stages.parallel)


def usable_cores() -> int:
    """The cores this process may run on (its affinity mask where the OS has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def cpu_threads() -> int:
    """Threads a CPU launch is split into (MPMFX_SURFACE_THREADS, else the usable cores, capped)."""
    env = os.environ.get(THREADS_ENV)
    if env:
        try:
            n = int(env)
        except ValueError:
            raise ValueError(f"{THREADS_ENV}={env!r}: give a whole number of threads (1 = no splitting)") from None
        if n < 1:
            raise ValueError(f"{THREADS_ENV}={env!r}: give at least 1 thread")
        return n
    return max(1, min(usable_cores(), MAX_THREADS))
