"""The download's pool of page-locked buffers (pinned.PinnedPool) lends a buffer to one
result's arrays and reuses it only once they and every view of them are gone: a frame's mesh
must never change under a caller still holding it. Page-locked memory needs CUDA; here the
pool allocates ordinary host memory, the bookkeeping is the same."""

import gc

import numpy as np
import warp as wp

from mpmfx.surface.pinned import PinnedPool


class HostPool(PinnedPool):
    def _allocate(self, wp, size):
        return wp.empty(size, dtype=wp.uint8, device="cpu")


def test_a_buffer_comes_back_only_when_every_view_is_gone():
    pool = HostPool(limit=64 << 20)
    buf = pool.take(wp, 4000)
    a = pool.lend(wp, buf, (100, 3), np.float32)
    a[:] = 7.0
    view = a[10:20]
    del a
    gc.collect()
    other = pool.take(wp, 4000)  # the first buffer is still lent (view): a new one
    assert other.ptr != buf.ptr
    b = pool.lend(wp, other, (1000,), np.float32)
    b[:] = -1.0
    assert np.all(view == 7.0)  # untouched by the second lend
    del view
    gc.collect()
    again = pool.take(wp, 4000)
    assert again.ptr == buf.ptr  # back, and reused


def test_the_limit_falls_back_to_no_buffer():
    pool = HostPool(limit=3 << 20)
    first = pool.take(wp, 2 << 20)  # rounded up with room to grow: 3 MiB
    held = pool.lend(wp, first, (2 << 20,), np.uint8)
    assert pool.take(wp, 1 << 20) is None  # lent buffers count against the limit
    del held
    gc.collect()
    assert pool.take(wp, 1 << 20).ptr == first.ptr  # free again: lent out once more
    assert pool.take(wp, 2 << 20) is None


def test_a_refused_allocation_falls_back_to_pageable_copies():
    class Refused(PinnedPool):
        def _allocate(self, wp, size):
            raise RuntimeError(f"Failed to allocate {size} bytes on device 'cpu'")

    pool = Refused(limit=64 << 20)
    assert pool.take(wp, 4000) is None
    assert pool.limit == 0 and pool.take(wp, 10) is None  # not asked again


def test_a_free_buffer_serves_a_smaller_array_before_a_new_one_is_pinned():
    # pinning memory costs more than the copy it speeds up: a smaller array takes the smallest
    # free buffer that holds it, however much bigger (a cap at twice its size pinned new memory
    # in the 10M bench whenever a case followed a bigger one)
    pool = HostPool(limit=64 << 20)
    big = pool.take(wp, 16 << 20)
    lent = pool.lend(wp, big, (16 << 20,), np.uint8)
    del lent
    gc.collect()
    held = pool._held
    assert pool.take(wp, 1 << 20).ptr == big.ptr
    assert pool._held == held  # nothing new pinned


def test_host_buffer_lends_from_the_pool_and_takes_it_back(monkeypatch):
    """host_buffer (the surface stage's reads, the downloads' copies) hands out the pool's memory
    and gets it back when the array made of it is gone; past the limit, numpy's memory."""
    from mpmfx.surface import pinned

    pool = HostPool(limit=8 << 20)
    monkeypatch.setattr(pinned, "PINNED", pool)
    first = pinned.host_buffer(wp, 4 << 20)
    x = first[128:].view(np.float32)  # as read_npz's arrays: a view past the .npy header
    x[:] = 1.0
    del first
    gc.collect()
    assert pool.take(wp, 1 << 20) is not None and pool._held > 4 << 20  # still lent (x): a second buffer
    assert pinned.host_buffer(wp, 8 << 20).size == 8 << 20  # past the limit: numpy's
    ptr = x.__array_interface__["data"][0] - 128
    del x
    gc.collect()
    assert pool.take(wp, 4 << 20).ptr == ptr  # back once the view is gone
