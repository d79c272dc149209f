"""Page-locked host buffers for the surfacer's downloads from a GPU (and the surface stage's
reads of the particles it uploads), and the copy to the host."""

from __future__ import annotations

import logging
import os
import threading
import weakref

import numpy as np

log = logging.getLogger(__name__)


class PinnedPool:
    """Page-locked host buffers lent to the numpy arrays of one download and taken back when
    the last of those arrays (or a view of them) is gone, for the next call's copies.

    A device-to-host copy into pageable memory goes through the driver's staging and faults
    the destination's pages in: a large part of a 10M-particle call on a GPU. Into
    page-locked memory it is one DMA. Allocating page-locked memory costs more than it saves,
    so the buffers are kept: a frame's download reuses the last frame's buffers once that frame's
    arrays are gone. At most `limit` bytes are held; past that a download falls back to
    pageable arrays (a caller keeping many frames' results does not pin them all)."""

    def __init__(self, limit: int):
        self.limit = limit
        self._free: list = []  # page-locked wp.arrays of uint8 not lent
        self._held = 0  # bytes of page-locked buffers, free or lent
        self._lock = threading.RLock()  # a lent array's finalizer may run inside take(), on the same thread

    def take(self, wp, nbytes: int):
        """A page-locked uint8 wp.array of at least nbytes, or None past the limit."""
        with self._lock:
            # the smallest free buffer that holds it, however big: a cap at twice the size sent the
            # 10M bench's first calls after a bigger case to new page-locked allocations (+20-40 ms)
            fits = [b for b in self._free if nbytes <= b.size]
            if fits:
                buf = min(fits, key=lambda b: b.size)
                self._free.remove(buf)
                return buf
            size = -(-nbytes * 5 // 4 // (1 << 20)) * (1 << 20)  # room to grow: frames' sizes move
            while self._free and self._held + size > self.limit:  # free buffers too small or too big
                self._held -= self._free.pop(0).size
            if self._held + size > self.limit:
                return None
            self._held += size
        try:
            return self._allocate(wp, size)
        except RuntimeError as exc:  # page-locked memory refused (a container's memlock limit): pageable from now on
            log.warning("surface download: no page-locked host memory (%s); copying to pageable memory", exc)
            with self._lock:
                self._held -= size
                self.limit = 0
            return None

    def _allocate(self, wp, size: int):
        return wp.empty(size, dtype=wp.uint8, device="cpu", pinned=True)

    def lend(self, wp, buf, shape: tuple, dtype) -> np.ndarray:
        """A numpy array of `shape` and numpy `dtype` over buf's first bytes; buf comes back to
        the pool when that array and every view of it are gone."""
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        alias = wp.array(ptr=buf.ptr, dtype=wp.uint8, shape=(max(nbytes, 1),), device="cpu")  # owns nothing
        weakref.finalize(alias, self._give_back, buf)
        return alias.numpy()[:nbytes].view(dtype).reshape(shape)

    def _give_back(self, buf) -> None:
        with self._lock:
            self._free.append(buf)


def pinned_limit() -> int:
    """Bytes the pool may hold page-locked: an eighth of the host's memory, at most 4 GiB (a 10M
    torus at "fine" lends 174 MB a frame, and the stage's 4 writers may hold 4 frames; at 10M
    particles the surface stage reads 283 MB a frame into it, a frame ahead)."""
    try:
        ram = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        ram = 8 << 30
    return min(4 << 30, ram // 8)


PINNED = PinnedPool(limit=pinned_limit())

"""The downloads' and reads' page-locked buffers (a 10M-particle frame's mesh and leaves are
~120 MB, with velocities ~300 MB)."""


def host_buffer(wp, nbytes: int) -> np.ndarray:
    """A uint8 array of nbytes in a page-locked buffer of the PINNED pool (numpy's memory past its
    limit), for host data a GPU call will upload: from page-locked memory the copy is one DMA,
    from pageable memory it goes through the driver's staging (mpmfx.io.npz.read_npz's alloc).
    The buffer goes back to the pool when the array and its views are gone."""
    buf = PINNED.take(wp, nbytes) if nbytes else None
    return np.empty(nbytes, np.uint8) if buf is None else PINNED.lend(wp, buf, (nbytes,), np.uint8)


def to_host(wp, arrays: list, *, pinned: bool) -> list:
    """numpy copies of device arrays (None stays None; arrays already on the CPU are returned as
    numpy views), every copy queued before one wait. pinned (CUDA only): into page-locked buffers
    of the PINNED pool. Else each array is copied into a buffer numpy allocated: numpy asks Linux
    for transparent huge pages on large arrays (madvise), so the copy faults in a few hundred pages
    where Warp's own host allocation (`wp.array.numpy()`) faults tens of thousands."""
    if all(a is None or a.device.is_cpu for a in arrays):
        return [None if a is None else a.numpy() for a in arrays]
    out = []
    for a in arrays:
        if a is None:
            out.append(None)
            continue
        scalar = wp.dtype_to_numpy(getattr(a.dtype, "_wp_scalar_type_", a.dtype))
        shape = tuple(a.shape) + tuple(getattr(a.dtype, "_shape_", ()))
        nbytes = int(np.prod(shape)) * np.dtype(scalar).itemsize
        host = host_buffer(wp, nbytes).view(scalar).reshape(shape) if pinned else np.empty(shape, dtype=scalar)
        wp.copy(wp.array(host, dtype=a.dtype, device="cpu", copy=False), a)
        out.append(host)
    wp.synchronize()
    return out
