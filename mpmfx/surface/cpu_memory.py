"""Keep freed memory in the process for the CPU surfacer's next arrays (glibc only).

A surfacing call on the CPU allocates and frees some 40-120 MB of Warp arrays (a few MB each
at 100k particles: the field, its weights and offsets, the sweeps' buffers). By default glibc
serves blocks above a (dynamic) threshold with fresh mmaps and hands a heap's free top back to
the kernel above 128 KB, so every call would fault its pages in again: thousands of page
faults a call at 100k particles (the faults and the kernel's zeroing of each page). With
blocks up to 32 MB (glibc's largest mmap threshold) served from the heap and up to
MAX_KEPT_FREE of free heap kept, the faults drop to ~10 a call: the process keeps up to that
much more resident memory than it uses (arrays above 32 MB, at millions of particles, are still
mmapped and returned when freed).

Process-wide (mallopt): done once, by the first CPU surfacing call; not where the user set
glibc's malloc tunables themselves (GLIBC_TUNABLES, MALLOC_*_ environment variables), nor
with MPMFX_SURFACE_KEEP_MEMORY=0.
"""

from __future__ import annotations

import ctypes
import os
import platform

MMAP_THRESHOLD = 32 << 20  # bytes: glibc's largest (HEAP_MAX_SIZE / 2 on 64-bit)
MAX_KEPT_FREE = 256 << 20  # bytes of free heap top kept for the next call (M_TRIM_THRESHOLD)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's malloc.h
_done = False


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds once (see the module docstring); whether they were
    set by this call."""
    global _done
    if _done:
        return False
    _done = True
    env = os.environ
    if (
        env.get("MPMFX_SURFACE_KEEP_MEMORY", "1") == "0"
        or "GLIBC_TUNABLES" in env
        or any(k.startswith("MALLOC_") for k in env)
    ):
        return False
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(None)
        ok = libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
        return bool(libc.mallopt(_M_TRIM_THRESHOLD, MAX_KEPT_FREE) == 1 and ok)
    except (OSError, AttributeError):
        return False
