"""The export stage's VDB grids, each surface group's file made in a child process.

pyopenvdb holds Python's lock while it builds and writes a grid: a 10M-face frame's leaves take
~8 s on one core. In the run's own process that would stall every other thread for as long (the
solver's launches, the surfacing that follows it, the USD layers), and the groups of a frame
would wait for each other. A child process reads its group's leaves from the surface frame's
file itself (the export read its mesh from that file, so its bytes were checked against their
digest already), so only the job and a path cross; several groups, and the frame's USD layer,
are made at once. A Dask worker (a daemonic process, which may not start children) spreads
frames over processes already: there the grids are made in turn.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from mpmfx.io.frames import SurfaceFrame
from mpmfx.io.vdb import LeafGrid, write_vdb
from mpmfx.stages.parallel import FrameJob
from mpmfx.threads import usable_cores

LEAVES = ("block_ijk", "blocks", "inside_ijk", "vel_blocks", "density_blocks", "voxel_size", "background")
IN_PROCESS_ENV = "MPMFX_VDB_IN_PROCESS"  # set (to 1): grids made in the calling process (tests that patch it)
_pool: ProcessPoolExecutor | None = None
_lock = threading.Lock()


def submit(job: FrameJob, f: int, groups: list[str]) -> dict[str, Future]:
    """{group: a Future of group_grids(job, f, group)} for each of `groups`; a child process
    makes each where this process may start children. Call it once the surface frame was read
    through its entry (`Entry.read`: the digest checked)."""
    pool = _children()
    out = {}
    for g in groups:
        if pool is None:
            done: Future = Future()
            try:
                done.set_result(group_grids(job, f, g))
            except Exception as exc:  # raised by result(), as a child's error is
                done.set_exception(exc)
            out[g] = done
        else:
            out[g] = pool.submit(group_grids, job, f, g)
    return out


def results(pending: dict[str, Future]) -> dict[str, dict[str, str]]:
    """{group: its grids' paths} once every one of `pending` is written; the first error raised
    after all have finished (a frame's files are complete or absent either way). A child that
    died (killed, out of memory) takes the pool with it: the next frame starts a new one."""
    global _pool
    out, error = {}, None
    for g, fut in pending.items():
        try:
            out[g] = fut.result()
        except BrokenProcessPool as exc:
            with _lock:
                _pool = None
            error = error or exc
        except Exception as exc:
            error = error or exc
    if error is not None:
        raise error
    return out


def group_grids(job: FrameJob, f: int, group: str) -> dict[str, str]:
    """Surface group `group`'s grids of frame f written to vdb/<group>/NNNN.vdb in the export
    entry: {grid name: that path, relative to the entry}; {} where the group has no leaves (no
    surface this frame). Runs in a child process or in the caller."""
    shot, surf = job.shot, job.upstream["surface"]
    d = SurfaceFrame.read(surf.frame_path(f, SurfaceFrame.EXT), fields=LEAVES).groups[group]  # (verified: submit)
    if d.block_ijk is None or len(d.block_ijk) == 0:  # (no leaves: a frame surfaced for no VDB)
        return {}
    vs, band = float(d.voxel_size), float(d.background)
    # straight from the stored leaves: a dense block over their bounding box grows with the
    # cube of the resolution (tens of GB at 10M faces). Half floats on disk: 27 % smaller
    # files (jelly_splash), ~5e-4 relative, invisible in a render
    grids = [LeafGrid("surface", d.block_ijk, d.blocks, vs, "level_set", band, half=True)]
    if d.vel_blocks is not None:  # 0 outside the stored leaves, inside ones too
        grids.append(LeafGrid("vel", d.block_ijk, d.vel_blocks, vs, "unknown", 0.0, half=True))
    if d.density_blocks is not None:  # 1 on the leaves wholly inside, 0 (inactive) outside the stored ones
        grids.append(LeafGrid("density", d.block_ijk, d.density_blocks, vs, "fog_volume", 0.0, True, d.inside_ijk, 1.0))
    rel = f"vdb/{group}/{f:04d}.vdb"
    meta = {"shot": shot.shot.name, "frame": f, "units": "m", "group": group}
    write_vdb(job.entry.root / rel, grids, metadata=meta)
    return {grid.name: rel for grid in grids}


def _children() -> ProcessPoolExecutor | None:
    """The pool of child processes, started at the first call; None where grids are made here."""
    global _pool
    if os.environ.get(IN_PROCESS_ENV) or multiprocessing.current_process().daemon:
        return None
    with _lock:
        if _pool is None:
            # forkserver: a child forked from a clean server, not from this process's threads and
            # GPU context; half the cores at most (the run's own threads have the rest)
            _pool = ProcessPoolExecutor(
                max_workers=max(1, min(4, usable_cores() // 2)),
                mp_context=multiprocessing.get_context("forkserver"),
            )
        return _pool
