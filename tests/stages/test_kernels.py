"""A run's Warp modules compiled ahead (mpmfx.stages.kernels): the wait for them is announced once,
with its progress, and nothing is said when they are ready before a stage needs them."""

from __future__ import annotations

import threading

import warp as wp

import mpmfx.stages.kernels as kernels_mod
from mpmfx.stages.kernels import ShotKernels


@wp.kernel(enable_backward=False, module="mpmfx_test_ahead")
def _twice(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = 2.0 * a[i]


def _groups():
    return {"simulate": [(_twice.module, None)], "surface": []}


def test_a_wait_is_announced_once_with_its_progress(capsys, monkeypatch):
    go = threading.Event()  # the compile finishes only once wait() has begun waiting
    real = ShotKernels._load
    monkeypatch.setattr(ShotKernels, "_load", lambda self, *a: (go.wait(), real(self, *a)))
    monkeypatch.setattr(kernels_mod.time, "sleep", lambda s: go.set())
    kernels = ShotKernels("cpu", _groups()).start(ahead=True)
    kernels.wait("simulate")
    kernels.wait("surface")  # (nothing of its own to wait for)
    out = capsys.readouterr().out
    assert out.count("compiling 1 GPU kernel modules (first use; cached after) ...") == 1
    assert "1/1" in out


def test_nothing_is_said_when_the_modules_are_ready(capsys):
    kernels = ShotKernels("cpu", _groups()).start(ahead=True)
    kernels._pool.shutdown(wait=True)  # (every module loaded before the stage asks)
    kernels.wait("simulate")
    assert capsys.readouterr().out == ""


def test_a_cpu_run_compiles_as_it_launches(capsys):
    kernels = ShotKernels("cpu", _groups()).start()
    assert kernels._pool is None
    kernels.wait("simulate")
    assert capsys.readouterr().out == ""
