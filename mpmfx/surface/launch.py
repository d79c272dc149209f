"""Kernel launches of the sparse surfacer, split across CPU threads on the CPU.

Warp's CPU backend runs all threads of a launch one after another on one core. Its launches
call the compiled kernel through ctypes, which releases the GIL, so the same kernel launched
on disjoint index ranges from several Python threads runs on several cores at once. Kernels
that take a trailing `base: int` (their first thread's index) can be split that way: each
thread must write only its own outputs (or, like the flood fills' in-place sweeps, be correct
in any interleaving, as they are on a GPU). On a GPU the launch is one call with base 0.

MPMFX_SURFACE_THREADS sets the CPU thread count (default: the cores this process may use, at
most MAX_THREADS); 1 turns splitting off.
"""

from __future__ import annotations

import os
import queue
from concurrent.futures import ThreadPoolExecutor

MAX_THREADS = 8
CHUNKS_PER_THREAD = 4
MIN_SPLIT = 1 << 14  # threads of a launch below which splitting costs more than it gains

_pool: ThreadPoolExecutor | None = None
_pool_key = (0, 0)  # (threads, pid): a forked child must not reuse its parent's pool (no threads behind it)


def cpu_threads() -> int:
    """Threads a CPU launch is split into (MPMFX_SURFACE_THREADS, else the usable cores, capped)."""
    env = os.environ.get("MPMFX_SURFACE_THREADS")
    if env:
        try:
            n = int(env)
        except ValueError:
            raise ValueError(f"MPMFX_SURFACE_THREADS={env!r}: give a whole number of threads (1 = no splitting)") from None
        if n < 1:
            raise ValueError(f"MPMFX_SURFACE_THREADS={env!r}: give at least 1 thread")
        return n
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(cores, MAX_THREADS))


def _executor(n: int) -> ThreadPoolExecutor:
    global _pool, _pool_key
    key = (n, os.getpid())
    if _pool is None or _pool_key != key:
        if _pool is not None and _pool_key[1] == key[1]:
            _pool.shutdown(wait=True)
        _pool, _pool_key = ThreadPoolExecutor(n, thread_name_prefix="mpmfx-surface"), key
    return _pool


def launch_split(wp, kernel, dim: int, inputs: list, *, device, min_split: int | None = None) -> None:
    """Launch `kernel` over `dim` threads with `inputs` + [base]: on a CPU device as
    CHUNKS_PER_THREAD x cpu_threads() chunks run on cpu_threads() threads, else (or when small)
    as one launch with base 0 (also below min_split threads: a kernel whose threads do much
    work, such as a block each, passes a smaller one)."""
    if dim <= 0:
        return
    n = cpu_threads() if device.is_cpu else 1
    if n == 1 or dim < (MIN_SPLIT if min_split is None else min_split):
        wp.launch(kernel, dim, inputs=[*inputs, 0], device=device)
        return
    # more chunks than threads: a thread that shares its core with another process takes fewer
    # of them instead of holding the whole launch up
    step = -(-dim // (n * CHUNKS_PER_THREAD))
    chunks = [(lo, min(step, dim - lo)) for lo in range(0, dim, step)]
    futures = [_executor(n).submit(wp.launch, kernel, size, inputs=[*inputs, lo], device=device) for lo, size in chunks]
    for f in futures:
        f.result()


def launch_split_scratch(wp, kernel, dim: int, inputs: list, scratch, *, device) -> None:
    """launch_split for a CPU kernel of one block per thread that takes inputs + [scratch, base]
    and uses scratch for one of its threads at a time (a CPU launch runs its threads one after
    another): each CPU thread gets its own scratch() array, reused by the chunks it runs.
    scratch(): a new array."""
    if dim <= 0:
        return
    n = cpu_threads() if device.is_cpu else 1
    if n == 1:
        wp.launch(kernel, dim, inputs=[*inputs, scratch(), 0], device=device)
        return
    step = -(-dim // (n * CHUNKS_PER_THREAD))
    free: queue.SimpleQueue = queue.SimpleQueue()
    for _ in range(n):
        free.put(scratch())

    def run(lo: int, size: int) -> None:
        buf = free.get()
        try:
            wp.launch(kernel, size, inputs=[*inputs, buf, lo], device=device)
        finally:
            free.put(buf)

    futures = [_executor(n).submit(run, lo, min(step, dim - lo)) for lo in range(0, dim, step)]
    for f in futures:
        f.result()
