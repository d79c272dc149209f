"""The stages write frames on background threads (`FrameWriter`): with one thread in order, one at
a time, a failed write reported (not lost), and a frame simulated before an error still
written."""

import threading
import time

import pytest

from mpmfx.stages.writer import FrameWriter


def test_jobs_run_in_order_off_the_main_thread():
    done, threads = [], set()

    def job(i):
        time.sleep(0.02 * (3 - i))  # a later job would overtake an earlier one if they overlapped
        done.append(i)
        threads.add(threading.current_thread().name)

    with FrameWriter() as w:
        for i in range(3):
            w.submit(job, i)
    assert done == [0, 1, 2]
    assert threading.current_thread().name not in threads


def test_a_failed_write_is_raised_at_the_next_frame():
    def fail():
        raise OSError("No space left on device: frames/0003.npz")

    with pytest.raises(OSError, match="0003.npz"):
        with FrameWriter() as w:
            w.submit(fail)
            w.submit(lambda: None)  # the next frame's files: the failure surfaces here


def test_a_failed_write_is_raised_on_leaving():
    with pytest.raises(OSError, match="0005.npz"):
        with FrameWriter() as w:
            w.submit(lambda: (_ for _ in ()).throw(OSError("frames/0005.npz")))


def test_the_pending_frame_is_written_when_the_simulation_fails():
    written = []
    with pytest.raises(RuntimeError, match="frame 4 blew up"):
        with FrameWriter() as w:
            w.submit(lambda: (time.sleep(0.1), written.append(3)))
            raise RuntimeError("frame 4 blew up")
    assert written == [3]


def test_a_non_finite_frame_writes_nothing(tmp_path):
    import numpy as np

    from mpmfx.stages.base import StageError
    from mpmfx.stages.simulate import _write_frame

    class Entry:
        root = tmp_path

        @staticmethod
        def frame_path(frame, ext):
            return tmp_path / "frames" / f"{frame:04d}.{ext}"

    n = 4
    state = {
        "x": np.full((n, 3), 0.5, np.float32),
        "v": np.zeros((n, 3), np.float32),
        "alive": np.ones(n, np.int32),
        "material": np.zeros(n, np.int32),
        "body": np.zeros(n, np.int32),
        "J": np.ones(n, np.float32),
    }
    state["v"][2, 1] = np.nan
    with pytest.raises(StageError, match="frame 7: the solver returned non-finite values"):
        _write_frame(Entry, 7, {"substeps": 3}, {"x": state["x"]}, state, np.zeros(3), 2.0)
    assert not any(tmp_path.rglob("*.*"))  # no QA, no checkpoint (a NaN resume point), no frame
    state["v"][2, 1] = 0.0
    _write_frame(Entry, 7, {"substeps": 3}, {"x": state["x"]}, state, np.zeros(3), 2.0)
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.*")) == [
        "checkpoints/.0007.npz.b2",  # each with its checksum (mpmfx.checksum)
        "checkpoints/0007.npz",
        "frames/.0007.npz.b2",
        "frames/0007.npz",
        "qa/0007.json",
    ]


def test_several_threads_write_at_once_and_hold_at_most_that_many():
    running, peak, lock = [0], [0], threading.Lock()

    def job():
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        time.sleep(0.05)
        with lock:
            running[0] -= 1

    with FrameWriter(threads=3) as w:
        for _ in range(7):
            w.submit(job)
            assert len(w._pending) <= 3  # the frames held for writing
    assert peak[0] == 3


def test_with_several_threads_every_pending_frame_is_written_before_a_failure_is_raised():
    written = []
    with pytest.raises(OSError, match="0002.npz"):
        with FrameWriter(threads=3) as w:
            w.submit(lambda: (_ for _ in ()).throw(OSError("frames/0002.npz")))
            w.submit(lambda: (time.sleep(0.1), written.append(3)))
            w.submit(lambda: (time.sleep(0.1), written.append(4)))
    assert sorted(written) == [3, 4]
