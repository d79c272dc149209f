"""Independent work as dask.distributed tasks: a stage's frames, a wedge's variants.

A stage whose frames are independent (surface, export, render) does its work in calls
`frame(job, f)`; `Frames` runs them either here, one after another (`workers=1`: the serial
path, the byte-for-byte reference), or as Dask tasks: on a `LocalCluster` of worker processes
with one task thread each (VTK and Python hold the GIL; the surfacer's Warp kernels split
across the worker's share of the cores, `_worker_env`), or on a farm's scheduler (`scheduler="tcp://host:8786"`, or $MPMFX_SCHEDULER).

The cache contract with many writers:
- a task writes its own frame file through `mpmfx.cache.atomic_path`, so a frame file is
  complete or absent, whichever worker (or two) wrote it;
- the client writes the manifest, after every task has finished;
- a task's key is the entry key plus the frame number, so two clients asking one scheduler for
  the same frame share one task, and a worker that dies mid-task has its task re-run on another
  worker by the scheduler (`distributed.scheduler.allowed-failures`, 3 by default);
- temp files a killed worker left behind are swept by the client (`mpmfx.cache.remove_temps`),
  under the shot's lock before a run starts and after a stage's tasks have finished, so an entry
  never holds a partial file when done.

Paths in a task are absolute: a farm worker's working directory is not the client's (the cache
root must then be a folder every host mounts at the same path).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import socket
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

from tqdm import tqdm

from mpmfx.cache import DamagedError, Entry
from mpmfx.config import ShotError
from mpmfx.publish import publish_name
from mpmfx.threads import THREADS_ENV, cpu_threads, usable_cores

if TYPE_CHECKING:
    from mpmfx.config import Shot

SCHEDULER_ENV = "MPMFX_SCHEDULER"  # a farm scheduler's address, e.g. tcp://farm-head:8786
WORKERS_ENV = "MPMFX_WORKERS"  # worker processes of the LocalCluster; 1 = serial
CORES_ENV = "MPMFX_WORKER_CORES"  # a LocalCluster worker's share of the cores (a Blender child's threads)
# Below this many frames to make, `workers=None` (auto) stays serial: a two-worker LocalCluster
# costs ~20 CPU seconds (start, Warp kernels loaded in each worker; docs/scale-out.md).
AUTO_MIN_TASKS = 10
# From AUTO_MIN_TASKS frames on, auto runs PROBE_CALLS frames here first and starts workers for
# the rest only if the probe says they would finish sooner (worth_a_cluster). CLUSTER_COST_S: the
# wall seconds a LocalCluster costs before it gains any, as the default shot's 24 frames measure
# it on a 2-core CPU (lab/bench_frames.py): two workers are slower than serial there for surface and export, and
# Cycles already uses every core.
PROBE_CALLS = 2
CLUSTER_COST_S = 4.0


def worth_a_cluster(remaining: int, wall: float, cpu: float, cores: int) -> bool:
    """Whether `remaining` more calls like the probe's (`wall` seconds, `cpu` seconds of this
    process's threads) would finish sooner on `cores` one-thread workers, CLUSTER_COST_S
    included. Serial: remaining x wall. On workers each call needs its CPU seconds and no call
    gets shorter than it ran alone, so at best remaining x max(wall, cpu) / cores: a call that
    already kept every core busy (a Cycles frame) gains nothing from more processes."""
    if remaining <= 0 or cores < 2:
        return False
    return remaining * (wall - max(wall, cpu) / cores) > CLUSTER_COST_S


@dataclass(frozen=True)
class FrameJob:
    """What a per-frame task reads: the shot, its stage entry and the upstream entries (paths
    absolute), and the Warp device. Small and picklable: it travels with every task."""

    shot: Shot
    entry: Entry
    upstream: dict[str, Entry]
    device: str | None = None

    @classmethod
    def of(cls, shot: Shot, entry: Entry, upstream: dict[str, Entry], device: str | None) -> FrameJob:
        absolute = lambda e: dataclasses.replace(e, root=e.root.resolve())  # noqa: E731
        return cls(shot, absolute(entry), {k: absolute(e) for k, e in upstream.items()}, device)


def task_key(entry: Entry, frame: int | None = None) -> str:
    """The Dask key of an entry's frame (or of the whole entry): equal work has an equal key."""
    return f"{entry.stage}-{entry.key[:20]}" + ("" if frame is None else f"-{frame:04d}")


class Frames:
    """Runs independent calls serially or as Dask tasks; the cluster starts at the first call
    that is worth one, and stops at `close()` (a `with` block does that).

    workers: LocalCluster worker processes; 1 = serial in this process; None = auto (all cores
    when there are at least AUTO_MIN_TASKS calls, else serial), or $MPMFX_WORKERS.
    scheduler: a running scheduler's address (a farm); overrides workers. Default $MPMFX_SCHEDULER.
    """

    def __init__(self, *, workers: int | None = None, scheduler: str | None = None):
        self.scheduler = scheduler or os.environ.get(SCHEDULER_ENV) or None
        if workers is None and os.environ.get(WORKERS_ENV):
            try:
                workers = int(os.environ[WORKERS_ENV])
            except ValueError:
                raise ShotError(
                    f"${WORKERS_ENV} = {os.environ[WORKERS_ENV]!r}: give a whole number of worker "
                    f"processes (1 = serial), or unset it"
                ) from None
        if workers is not None and workers < 1:
            raise ShotError(f"--workers / ${WORKERS_ENV} = {workers}: give at least 1 (1 = serial)")
        # the surfacer's thread setting, checked before any stage runs
        try:
            cpu_threads()
        except ValueError as exc:
            raise ShotError(f"${exc}, or unset it") from None
        self.workers = workers
        self._client = self._cluster = None

    def __enter__(self) -> Frames:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def size(self) -> int:
        """Worker processes of a LocalCluster started here: the workers asked for, else all cores."""
        return self.workers or os.cpu_count() or 1

    def spread(self) -> int:
        """How many workers were asked for: the farm's workers now connected (at least 1) with a
        scheduler, the LocalCluster's size with --workers, else 1 (auto and serial: work that
        already keeps every core busy, such as a Cycles render, stays in one process)."""
        if self.scheduler:
            return max(1, len(self.client().scheduler_info()["workers"]))
        return self.workers or 1

    def parallel(self, n_calls: int, *, auto_min: int = AUTO_MIN_TASKS) -> bool:
        """Whether `n_calls` calls go to Dask (auto: only `auto_min` calls or more)."""
        if self._client is not None or self.scheduler:
            return True
        n = self.size
        if n < 2 or n_calls < 2:
            return False
        return self.workers is not None or n_calls >= auto_min

    def client(self):
        """The Dask client: connected to the scheduler, or to a LocalCluster started now."""
        if self._client is None:
            from distributed import Client, LocalCluster  # backend: distributed

            if self.scheduler:
                try:
                    self._client = Client(self.scheduler, timeout="20s")
                except (OSError, TimeoutError, ValueError) as exc:  # ValueError: not an address
                    raise ShotError(
                        f"--scheduler / ${SCHEDULER_ENV} = {self.scheduler!r}: no Dask scheduler "
                        f"answers there ({exc}); start one (dask scheduler) or check the address, "
                        f"or run without it"
                    ) from None
            else:
                n = self.size
                self._cluster = LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    env=_worker_env(n),
                    dashboard_address=":0",
                    silence_logs=logging.ERROR,
                )
                self._client = Client(self._cluster)
        return self._client

    def close(self) -> None:
        """Disconnect, and stop the LocalCluster if this started one. A worker slow to exit (a
        loaded machine) is killed by its nanny; that is no error of the run, so it is not raised."""
        try:
            if self._client is not None:
                self._client.close()
            if self._cluster is not None:
                self._cluster.close(timeout=30)
        except (TimeoutError, OSError) as exc:
            print(
                f"note: the Dask cluster did not stop cleanly ({type(exc).__name__}); its workers were killed",
                file=sys.stderr,
            )
        finally:
            self._client = self._cluster = None

    def map(
        self,
        fn: Callable[[FrameJob, int], Any],
        calls: list[tuple[FrameJob, int]],
        *,
        desc: str = "",
        quiet: bool = False,
        auto: bool = True,
        serial: Callable[[list[tuple[FrameJob, int]], Any], list[Any]] | None = None,
    ) -> list[Any]:
        """fn(job, frame) for each call; results in call order. The first failure is raised
        (the other tasks are cancelled; frames already written stay, a re-run resumes).
        auto=False: stay serial unless workers or a scheduler were asked for (work that a GPU
        does in a fraction of a second a frame, where starting workers costs more).
        serial(calls, bar): how the calls run here when they stay serial (default: fn on each,
        in order); it returns the results in call order and updates the progress bar.
        Auto (no workers, no scheduler asked for, no cluster running): from AUTO_MIN_TASKS calls
        on, the first PROBE_CALLS run here, timed, and the rest go to a LocalCluster only if
        worth_a_cluster says it would finish them sooner."""
        if not calls:
            return []
        bar = _bar(len(calls), desc, quiet)

        def here(part: list[tuple[FrameJob, int]]) -> list[Any]:
            if serial is not None:
                return serial(part, bar) if part else []
            out = []
            for job, f in part:
                out.append(fn(job, f))
                bar.update()
            return out

        try:
            if not self.parallel(len(calls), auto_min=AUTO_MIN_TASKS if auto else sys.maxsize):
                return here(calls)
            done: list[Any] = []
            if self.workers is None and self._client is None and not self.scheduler:  # auto: probe first
                done = here(calls[: PROBE_CALLS - 1])  # the first call loads (or compiles) the kernels: not timed
                t0, c0 = time.perf_counter(), time.process_time()
                done += here(calls[PROBE_CALLS - 1 : PROBE_CALLS])
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                calls = calls[PROBE_CALLS:]
                if not worth_a_cluster(len(calls), wall, cpu, self.size):
                    return done + here(calls)
            client = self.client()
            futures = [
                client.submit(_task, fn, job, f, desc, key=task_key(job.entry, f), pure=False) for job, f in calls
            ]
            return done + _gather(client, futures, bar)
        finally:
            bar.close()

    def call(self, fn: Callable[..., Any], *args, key: str, desc: str = "", quiet: bool = False) -> Any:
        """One call, e.g. one shot's whole simulation: a single task, or run here when serial."""
        return self.calls(fn, [args], keys=[key], desc=desc, quiet=quiet)[0]

    def calls(
        self,
        fn: Callable[..., Any],
        args: list[tuple],
        *,
        keys: list[str],
        desc: str = "",
        quiet: bool = False,
        labels: list[str] | None = None,
    ) -> list[Any]:
        """fn(*a) for each a in `args` (e.g. a wedge's simulations): tasks, or here when serial.
        labels: what each call is, for its failure line (default: desc and its key)."""
        if not args:
            return []
        bar = _bar(len(args), desc, quiet)
        try:
            if not self.parallel(len(args), auto_min=2):
                out = []
                for a in args:
                    out.append(fn(*a))
                    bar.update()
                return out
            client = self.client()
            labels = labels or [f"{desc} {k}" for k in keys]
            futures = [client.submit(_call, fn, w, *a, key=k, pure=False) for a, k, w in zip(args, keys, labels)]
            return _gather(client, futures, bar)
        finally:
            bar.close()


class TaskError(RuntimeError):
    """A task failed on a worker: one line naming the worker, the stage, the frame, the variant
    and the cause (the full output of a Blender child stays in the log the cause names)."""


def one_line(exc: BaseException) -> str:
    """An exception as one line: its first line, and its last where it has more (the error a
    child's log tail ends with), e.g. 'Blender (Cycles) exited with code 1; full log: L ... Error: X'."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = lines[0] if len(lines) < 2 else f"{lines[0]} ... {lines[-1]}"
    return text if type(exc).__name__ in ("StageError", "TaskError") else f"{type(exc).__name__}: {text}"


def worker_name() -> str:
    """The Dask worker this runs on (its address), or this host and process outside one."""
    try:
        from distributed import get_worker  # backend: distributed

        return get_worker().address
    except (ImportError, ValueError):
        return f"{socket.gethostname()} pid {os.getpid()}"


def _task(fn: Callable[[FrameJob, int], Any], job: FrameJob, f: int, desc: str) -> Any:
    """fn(job, f) on a worker; a failure comes back as one TaskError line (not the task's
    traceback, which Dask would carry to the client escaped into one long string). A damaged
    upstream file comes back as a value, raised in the client (which has the frame redone), so
    the worker does not log it as a failed task with its traceback."""
    try:
        return fn(job, f)
    except DamagedError as exc:
        return exc
    except ShotError:  # bad input: its own message, exit 2
        raise
    except Exception as exc:  # noqa: BLE001 - every failure is reported as one line
        raise TaskError(
            f"{desc or job.entry.stage} frame {f} of {publish_name(job.shot)} failed on worker "
            f"{worker_name()}: {one_line(exc)}"
        ) from None


def _call(fn: Callable[..., Any], what: str, *args) -> Any:
    """fn(*args) on a worker (a wedge's whole-shot stage); a failure as one TaskError line."""
    try:
        return fn(*args)
    except ShotError:
        raise
    except Exception as exc:  # noqa: BLE001 - every failure is reported as one line
        raise TaskError(f"{what} failed on worker {worker_name()}: {one_line(exc)}") from None


def _worker_env(workers: int) -> dict[str, str]:
    """The LocalCluster workers' share of the cores, for the surfacer's CPU threads
    (mpmfx.threads) and a Cycles child's threads ($MPMFX_WORKER_CORES): without it each of n
    workers splits its kernels across every core, and two workers on two cores surfaced the
    default shot 10 % slower (44.0-46.1 s against 40.4-41.2 s with one thread each). A surfacer
    thread count the user set is inherited as it is."""
    share = str(max(1, usable_cores() // max(1, workers)))
    return {CORES_ENV: share} | ({} if THREADS_ENV in os.environ else {THREADS_ENV: share})


def _gather(client, futures: list, bar) -> list[Any]:
    from distributed import as_completed  # backend: distributed

    try:
        for fut in as_completed(futures):
            result = fut.result()  # raises the task's exception here, in the client
            if isinstance(result, DamagedError):  # (returned by _task)
                raise result
            bar.update()
        return [f.result() for f in futures]
    except BaseException:
        client.cancel(futures)
        raise


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _bar(total: int, desc: str, quiet: bool):
    """A progress bar over tasks as they complete (in any order), on stderr."""
    if quiet:
        return _NoBar()
    return tqdm(total=total, desc=f"{desc:>9}", unit="frame", file=sys.stderr, leave=False, dynamic_ncols=True)
