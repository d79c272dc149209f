"""Surface and export each frame while simulate makes the next ones (the stages overlapped).

Without it a shot's wall time is simulate + surface + export one after another. The frames of
those stages do not depend on each other, only on their upstream frame, so while simulate runs,
`Follower` watches its entry and takes every frame the moment its file lands (a frame file is
complete or absent: `mpmfx.cache.atomic_path`): one thread surfaces it (on a GPU, in turns with the
solver's frames) and writes its file behind on threads, and
one thread exports every frame whose surface has landed. When simulate ends, the runner waits
for each followed stage in turn, then runs that stage as usual: it finds its frames made (those
the follower did not get to, it makes itself) and writes the manifest, as for a resumed stage.

What this keeps:
- every file is the one the stage alone would write: the same functions make it;
- a killed run leaves complete frame files in entries without manifests: the next run resumes
  each stage from them (`mpmfx.stages.runner`);
- a follower's error (a surface that cannot be made, a damaged upstream file) stops the
  following and is raised by the stage it belongs to, when the runner reaches it; a failed
  simulate stops the follower after the frame in hand;
- on a GPU the solver and the surfacer take turns (`mpmfx.stages.base.device_turn`): Warp's
  current stream is the device's, not the thread's, so two threads must not launch at once.
"""

from __future__ import annotations

import threading
import time
from functools import partial

from mpmfx.io.frames import ParticleFrame, SurfaceFrame
from mpmfx.stages import export, surface
from mpmfx.stages.base import Context, device_turn
from mpmfx.stages.writer import FrameWriter

POLL_S = 0.05  # how often the follower looks for a new upstream frame file
FOLLOWED = ("surface", "export")


class Follower:
    """Follows a running simulate stage with the surface (and export) stages' frames.

    contexts: the followed stages' contexts ("surface", optionally "export"), made by the runner
    as it would make them; kernels: the run's ahead-of-time compile (kernels.ShotKernels),
    waited for before the first frame, or None."""

    def __init__(self, contexts: dict[str, Context], *, kernels=None):
        self.contexts = contexts
        self.kernels = kernels
        self.results: dict[str, list[dict]] = {name: [] for name in contexts}
        self.seconds: dict[str, dict[str, float]] = {name: {} for name in contexts}
        self._errors: dict[str, BaseException] = {}
        self._upstream_done = threading.Event()  # simulate has written every frame it will
        self._stop = threading.Event()  # the run failed: finish the frame in hand, take no more
        self._threads: dict[str, threading.Thread] = {}

    def start(self) -> Follower:
        self._threads["surface"] = threading.Thread(target=self._surface, name="mpmfx-follow-surface", daemon=True)
        if "export" in self.contexts:
            self._threads["export"] = threading.Thread(target=self._export, name="mpmfx-follow-export", daemon=True)
        for t in self._threads.values():
            t.start()
        return self

    def upstream_done(self) -> None:
        """Simulate has finished: the frames it did not write will not come."""
        self._upstream_done.set()

    def stop(self) -> None:
        """Stop after the frames in hand, and wait for that (a failed or interrupted run)."""
        self._stop.set()
        self._upstream_done.set()
        for t in self._threads.values():
            t.join()

    def finish(self, name: str) -> Context:
        """Wait until the follower has made every frame of stage `name` it can; its context,
        with the frames' results in `ctx.followed`. Raises the follower's error in that stage."""
        self._threads[name].join()
        if name in self._errors:
            raise self._errors[name]
        ctx = self.contexts[name]
        ctx.followed = self.results[name]
        return ctx

    # -- the threads ----------------------------------------------------------------------
    def _wait_for(self, path, upstream_finished) -> bool:
        """Until `path` exists (True), or it never will (False): the upstream is finished
        without it, or the run stopped."""
        while not path.exists():
            if self._stop.is_set() or upstream_finished():
                return path.exists() and not self._stop.is_set()
            time.sleep(POLL_S)
        return not self._stop.is_set()

    def _surface(self) -> None:
        ctx = self.contexts["surface"]
        job, sim = ctx.job(), ctx.upstream["simulate"]
        split = self.seconds["surface"]
        try:
            with FrameWriter(surface.write_threads(ctx.device)) as writer:
                for f in surface.todo(ctx):
                    if not self._wait_for(sim.frame_path(f, ParticleFrame.EXT), self._upstream_done.is_set):
                        break
                    if self.kernels is not None:
                        self.kernels.wait("surface")
                        self.kernels = None
                    t0 = time.perf_counter()
                    particles = surface.read_particles(job, f)
                    t1 = time.perf_counter()
                    turn = partial(device_turn, ctx.device)
                    surfaces, stats = surface.make_surfaces(job, particles, f, turn=turn)
                    del particles
                    t2 = time.perf_counter()
                    writer.submit(self._write_surface, surfaces, ctx.entry.frame_path(f, surface.FRAME_EXT))
                    _add(split, read=t1 - t0, surface=t2 - t1, writer_wait=time.perf_counter() - t2)
                    self.results["surface"].append(stats)
        except BaseException as exc:
            self._errors["surface"] = exc

    def _write_surface(self, surfaces: SurfaceFrame, path) -> None:
        t0 = time.perf_counter()
        surfaces.write(path)
        _add(self.seconds["surface"], write=time.perf_counter() - t0)  # (one key per thread: += under the GIL)

    def _export(self) -> None:
        ctx = self.contexts["export"]
        job, surf = ctx.job(), ctx.upstream["surface"]
        surfacing = self._threads["surface"]
        try:
            for f in export.todo(ctx):
                if not self._wait_for(surf.frame_path(f, SurfaceFrame.EXT), lambda: not surfacing.is_alive()):
                    break
                _add(self.seconds["export"], **export.frame(job, f))  # read, vdb, usd, write
        except BaseException as exc:
            self._errors["export"] = exc


def _add(split: dict[str, float], **seconds: float) -> None:
    for k, s in seconds.items():
        split[k] = split.get(k, 0.0) + s
