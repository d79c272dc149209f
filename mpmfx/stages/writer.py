"""Frames' files written on background threads while the stage makes the next frame: on a GPU
the host's compression and disk writes take longer than the device's work on a frame."""

from __future__ import annotations

from collections import deque
from concurrent.futures import ThreadPoolExecutor


class FrameWriter:
    """Runs write jobs on `threads` background threads, at most `threads` pending at a time
    (a submit waits for the oldest first), so at most threads + 1 frames' host arrays are held:
    those being written and the one being made. threads = 1 (the simulate stage: a frame and
    its checkpoint) runs the jobs in order, one at a time. A job's error is raised when that
    job is waited for (a later submit, or leaving the block); leaving the block always finishes
    every pending job first (frames made before an error are still written)."""

    def __init__(self, threads: int = 1):
        self._threads = max(1, threads)
        self._pool = ThreadPoolExecutor(max_workers=self._threads, thread_name_prefix="mpmfx-frames")
        self._pending: deque = deque()

    def submit(self, fn, *args) -> None:
        while len(self._pending) >= self._threads:
            self._pending.popleft().result()
        self._pending.append(self._pool.submit(fn, *args))

    def wait(self) -> None:
        """Every pending job finished; the first failure raised (the rest still finish)."""
        try:
            while self._pending:
                self._pending.popleft().result()
        finally:
            self._finish_rest()

    def _finish_rest(self) -> None:
        """Let every pending job finish, its error (if any) left unraised."""
        for p in self._pending:
            p.exception()

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                self.wait()
            else:
                self._finish_rest()  # the error already raised is the one to report
        finally:
            self._pool.shutdown(wait=True)
