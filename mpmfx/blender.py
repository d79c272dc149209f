"""Blender (bpy) in a child process, for the layers that need it: mesh loading
(`mpmfx.geometry.blender_export`) and Cycles renders (`mpmfx.render.cycles_job`).

Never imports bpy: Blender bundles its own USD libraries, so it runs as
`python -m mpmfx.<module> ...` in its own process, never beside pxr. The modules run there
(blender_export, cycles_job, blender_scene) import bpy at their top and no other module imports
them; what parent and child share (the lines the child prints) is here.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
import signal
import subprocess
import sys
import uuid
from pathlib import Path

TIMEOUT_ENV = "MPMFX_BLENDER_TIMEOUT"  # seconds a Blender child that reads a file may take
TIMEOUT_S = 600.0
FRAME_LINE = "MPMFX_FRAME"  # a Cycles child's line per finished frame: FRAME_LINE frame wall_s cpu_s
NOTE_LINE = "MPMFX_NOTE"  # a Cycles child's line for the user: NOTE_LINE text (the parent prints the text)
PARENT_ENV = "MPMFX_PARENT_PID"  # the process that started a Blender child (die_with_parent)
ERROR = "mpmfx-blender-error: "  # a child's line the parent reads the reason of a failure from


def temp_name(path: str | Path) -> Path:
    """A temp path beside `path` (same suffix), unique to this process and call, what a Blender
    child writes before its rename: two children (a wedge's frames on two workers) never share
    one. It matches `mpmfx.cache.TEMP_GLOB`, so a killed child's is swept."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp{path.suffix}")


def bpy_available() -> bool:
    """Whether Blender as a Python module (bpy) is installed (found without importing it)."""
    return importlib.util.find_spec("bpy") is not None


def child_env() -> dict:
    """The environment of a Blender child process (`python -m mpmfx....`): it runs this very
    mpmfx (a worktree or an editable install alike): the folder that holds this package."""
    env = dict(os.environ)
    env[PARENT_ENV] = str(os.getpid())
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parents[1]), env.get("PYTHONPATH", "")])
    return env


def die_with_parent() -> None:
    """In a Blender child, first thing: the kernel kills it (SIGKILL) when the thread that
    started it ends, so a killed worker or client leaves no Blender rendering on for hours. That
    thread (`mpmfx.render.cycles.run_job`'s caller) waits on the child for its whole life. A
    parent already gone by now ($MPMFX_PARENT_PID no longer ours): exit at once. Linux only
    (prctl); elsewhere nothing changes."""
    if not sys.platform.startswith("linux"):
        return
    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    parent = os.environ.get(PARENT_ENV)
    if parent and parent.isdigit() and os.getppid() != int(parent):
        os._exit(1)


def child_command(module: str, *args: str) -> list[str]:
    """The command line that runs `module` (`python -m`) in a child process with this Python."""
    return [sys.executable, "-m", module, *args]


class ChildTimeout(RuntimeError):
    """A Blender child that did not finish in time (it was killed)."""


def run_child(cmd: list[str], *, what: str) -> subprocess.CompletedProcess:
    """Run a Blender child that reads a file, output captured, killed after $MPMFX_BLENDER_TIMEOUT
    seconds (default TIMEOUT_S): a rig with a scripted driver makes Blender refuse the script
    (auto-run is off) and then wait at exit forever, and a run must never hang on an asset."""
    try:
        timeout = float(os.environ.get(TIMEOUT_ENV, TIMEOUT_S))
    except ValueError:
        raise ChildTimeout(f"${TIMEOUT_ENV} = {os.environ[TIMEOUT_ENV]!r}: give seconds, e.g. 600") from None
    try:
        return subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=timeout)
    except subprocess.TimeoutExpired:  # subprocess.run has killed the child and reaped it
        raise ChildTimeout(
            f"{what}: Blender did not finish within {timeout:g} s and was stopped. A rig with a "
            f"scripted (Python) driver can make it wait forever: remove the driver or bake the "
            f"animation, or export the asset as USD; ${TIMEOUT_ENV} sets the limit"
        ) from None
