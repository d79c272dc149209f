"""Kernel launches of the sparse surfacer, split across CPU threads on the CPU.

Warp's CPU backend runs all threads of a launch one after another on one core. Its launches
call the compiled kernel through ctypes, which releases the GIL, so the same kernel launched
on disjoint index ranges from several Python threads runs on several cores at once. Kernels
that take a trailing `base: int` (their first thread's index) can be split that way: each
thread must write only its own outputs (or, like the flood fills' in-place sweeps, be correct
in any interleaving, as they are on a GPU). On a GPU the launch is one call with base 0.

A split launch costs Python time that a surfacing call (70-100 split launches, 500-800 chunks)
feels: the calling thread runs chunks itself and n - 1 pool workers take the rest from the same
list (one wake-up and one hand-back per worker, where a future per chunk would pay both for
every chunk: a round trip to a pool thread takes tens of microseconds), and the kernel's
arguments are packed once (`wp.launch(record_cmd=True)`), each chunk setting only its size and
base (a `wp.launch` would pack every argument again).

MPMFX_SURFACE_THREADS sets the CPU thread count (default: the cores this process may use, at
most MAX_THREADS); 1 turns splitting off.
"""

from __future__ import annotations

import copy
import os
import queue
import threading
from concurrent.futures import ThreadPoolExecutor

from mpmfx.threads import MAX_THREADS, THREADS_ENV, cpu_threads, usable_cores  # noqa: F401 - shared with io

CHUNKS_PER_THREAD = 4
MIN_SPLIT = 1 << 14  # threads of a launch below which splitting costs more than it gains
# blocks below which a light block kernel (a few hundred ns a block: the blurs, a flood round) runs
# unsplit: on 2800 blocks a blur pass took 0.62 ms on one thread and 0.84-0.86 ms split in two
# (the two vCPUs slow each other's vector code ~1.4x, and the hand-offs cost ~0.1-0.2 ms)
LIGHT_MIN_SPLIT = 1 << 13

_pool: ThreadPoolExecutor | None = None
_pool_key = (0, 0)  # (workers, pid): a forked child must not reuse its parent's pool (no threads behind it)


def _executor(n: int) -> ThreadPoolExecutor:
    global _pool, _pool_key
    key = (n, os.getpid())
    if _pool is None or _pool_key != key:
        if _pool is not None and _pool_key[1] == key[1]:
            _pool.shutdown(wait=True)
        _pool, _pool_key = ThreadPoolExecutor(n, thread_name_prefix="mpmfx-surface"), key
    return _pool


def _run_chunks(n: int, dim: int, run) -> None:
    """run(lo, size) over CHUNKS_PER_THREAD x n chunks of range(dim), on this thread and n - 1
    pool workers, each taking the next chunk when done with one: a thread that shares its core
    with another process takes fewer of them instead of holding the whole launch up."""
    step = -(-dim // (n * CHUNKS_PER_THREAD))
    todo = iter(range(0, dim, step))  # next() on it is atomic under the GIL: each chunk runs once

    def work() -> None:
        for lo in todo:
            run(lo, min(step, dim - lo))

    futures = [_executor(n - 1).submit(work) for _ in range(n - 1)]
    try:
        work()
    finally:
        for f in futures:
            f.result()


def _chunk_launcher(wp, kernel, inputs: list, device):
    """run(lo, size) launching `kernel` on threads lo .. lo + size - 1 (base = lo) from one
    packing of `inputs` (the trailing base excluded). Each call packs only the size and base,
    into its own copy of the recorded launch (chunks run on several threads at once). Relies on
    warp 1.19's Launch (params, set_dim, set_param_at_index; pinned in pyproject.toml)."""
    cmd = wp.launch(kernel, 1, inputs=[*inputs, 0], device=device, record_cmd=True)
    cmd.fwd_args = None  # the copies must not write into a shared list (it only serves graph capture)
    last = len(inputs)

    def run(lo: int, size: int) -> None:
        c = copy.copy(cmd)
        c.params = list(cmd.params)
        c.set_dim(size)
        c.set_param_at_index(last, lo)
        c.launch()

    return run


def launch_split(wp, kernel, dim: int, inputs: list, *, device, min_split: int | None = None, light: int = 0) -> None:
    """Launch `kernel` over `dim` threads with `inputs` + [base]: on a CPU device as
    CHUNKS_PER_THREAD x cpu_threads() chunks run on cpu_threads() threads, else (or when small)
    as one launch with base 0 (also below min_split threads: a kernel whose threads do much
    work, such as a block each, passes a smaller one). light: the kernel's threads per block
    where its work is light (a few hundred ns a block): it then runs unsplit below
    LIGHT_MIN_SPLIT blocks."""
    if dim <= 0:
        return
    n = cpu_threads() if device.is_cpu else 1
    least = MIN_SPLIT if min_split is None else min_split
    if light:
        least = max(least, LIGHT_MIN_SPLIT * light)
    if n == 1 or dim < least:
        wp.launch(kernel, dim, inputs=[*inputs, 0], device=device)
        return
    _run_chunks(n, dim, _chunk_launcher(wp, kernel, inputs, device))


def launch_split_scratch(wp, kernel, dim: int, inputs: list, scratch, *, device) -> None:
    """launch_split for a CPU kernel of one block per thread that takes inputs + [scratch, base]
    and uses scratch for one of its threads at a time (a CPU launch runs its threads one after
    another): each CPU thread gets its own scratch() array, reused by the chunks it runs.
    scratch(): a new array."""
    if dim <= 0:
        return
    if not device.is_cpu:  # a GPU runs the launch's threads at once: they would share one scratch
        raise ValueError(f"launch_split_scratch: {kernel.key} is a CPU kernel (one scratch for all its threads)")
    n = cpu_threads()
    if n == 1:
        wp.launch(kernel, dim, inputs=[*inputs, scratch(), 0], device=device)
        return
    free: queue.SimpleQueue = queue.SimpleQueue()
    for _ in range(n):
        free.put(scratch())

    def run(lo: int, size: int) -> None:
        buf = free.get()
        try:
            wp.launch(kernel, size, inputs=[*inputs, buf, lo], device=device)
        finally:
            free.put(buf)

    _run_chunks(n, dim, run)


def launch_sequence(wp, steps: list, dim: int, *, device, min_split: int = MIN_SPLIT) -> None:
    """Launch each (kernel, inputs) of `steps` over `dim` threads in turn, inputs + [base] as in
    launch_split, each step reading what the one before wrote. On a CPU device (from min_split
    threads) each of cpu_threads() threads takes an equal range of every step, and all finish a
    step before any starts the next (a barrier): one hand-off to the pool for the sequence,
    where launching each step split paid one a step, more than a light step gains (the weight
    blur's 21 passes). The same values as launching the steps one after another."""
    if dim <= 0:
        return
    n = cpu_threads() if device.is_cpu else 1
    if n == 1 or dim < min_split:
        for kernel, inputs in steps:
            wp.launch(kernel, dim, inputs=[*inputs, 0], device=device)
        return
    runs = [_chunk_launcher(wp, kernel, inputs, device) for kernel, inputs in steps]
    step = -(-dim // n)
    barrier = threading.Barrier(n)

    def work(t: int) -> None:
        lo = t * step
        size = max(0, min(step, dim - lo))
        try:
            for run in runs:
                if size:
                    run(lo, size)
                barrier.wait()
        except BaseException:
            barrier.abort()  # the other threads leave their wait (BrokenBarrierError) instead of hanging
            raise

    futures = [_executor(n - 1).submit(work, t) for t in range(1, n)]
    try:
        work(0)
    finally:
        for f in futures:
            try:
                f.result()
            except threading.BrokenBarrierError:
                pass  # the thread that broke it raises its own error


def split(wp, kernel, dim: int, inputs: list) -> None:
    """launch_split on the device of inputs[0], with the default threshold."""
    launch_split(wp, kernel, dim, inputs, device=inputs[0].device)


def launch_blocks(wp, kernel, inputs: list, *, light: bool = False) -> None:
    """Launch a CPU kernel that takes a block per thread (inputs[0]: bcoord, the active blocks),
    split across CPU threads however few the blocks, or (light: a few hundred ns a block) from
    LIGHT_MIN_SPLIT blocks on."""
    launch_split(wp, kernel, inputs[0].shape[0], inputs, device=inputs[0].device, min_split=1, light=int(light))


def launch_nonempty(wp, kernel, dim: int, inputs: list) -> None:
    """wp.launch, nothing for dim 0."""
    if dim:
        wp.launch(kernel, dim, inputs=inputs)


def scan(wp, a, *, inclusive: bool):
    """The prefix sum of a (a new array)."""
    out = wp.empty_like(a)
    wp.utils.array_scan(a, out, inclusive=inclusive)
    return out
