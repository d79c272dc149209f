"""The Cycles child is watched: one that stops finishing frames is killed, its temp files go, and
the error names the frame, its file and what to do. A stand-in child (plain Python) plays
Blender, so this runs without bpy in about a second."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

import mpmfx.render.cycles as cycles
from mpmfx.blender import FRAME_LINE


def _job(tmp_path: Path, frames=(1, 2, 3)) -> Path:
    out = tmp_path / "frames"
    out.mkdir()
    return cycles.write_job(
        tmp_path / "job.json",
        usd=tmp_path / "shot.usda",
        frames=list(frames),
        outputs=[out / f"{f:04d}.png" for f in frames],
        blend=tmp_path / "tiny.blend",
        width=8,
        height=8,
        samples=1,
        denoise=False,
        shutter=0.0,
        fps=24,
        mode="surface",
        looks={},
        floor_y=0.0,
        domain_origin=(0, 0, 0),
        domain_size=1.0,
        camera={"position": (0, 0, 3), "look_at": (0, 0, 0), "focal_length": 35.0, "horizontal_aperture": 36.0},
        sun_elevation=45.0,
        sun_rotation=0.0,
    )


def _stand_in(monkeypatch, script: str) -> None:
    """Blender replaced by `script`, run with the job's path as argv[1]."""
    monkeypatch.setattr(cycles, "bpy_available", lambda: True)
    monkeypatch.setattr(cycles, "child_command", lambda module, *args: [sys.executable, "-c", script, *args])


HANGS_ON_FRAME_2 = f"""
import json, os, sys, time
from pathlib import Path
job = json.loads(Path(sys.argv[1]).read_text())
Path(job["outputs"][0]).write_bytes(b"png")
print("{FRAME_LINE} 1 0.1 0.1", flush=True)
Path(job["outputs"][1]).with_name(f".0002.{{os.getpid()}}-0badcafe.tmp.png").write_bytes(b"half")  # Cycles at work
print("Fra:2 Sample 1/64", flush=True)  # chatter is no progress
time.sleep(60)
"""


def test_a_child_that_stops_finishing_frames_is_stopped_naming_the_frame(tmp_path, monkeypatch):
    job = _job(tmp_path)
    _stand_in(monkeypatch, HANGS_ON_FRAME_2)
    monkeypatch.setenv(cycles.STALL_ENV, "1")
    got, t0 = [], time.monotonic()
    with pytest.raises(cycles.CyclesError) as caught:
        for frame, _, _ in cycles.run_job(job, log=tmp_path / "cycles.log"):
            got.append(frame)
    said = str(caught.value)
    assert got == [1] and time.monotonic() - t0 < 15
    assert "frame 2" in said and "0002.png" in said and cycles.STALL_ENV in said and "driver" in said
    assert not list((tmp_path / "frames").glob(".*"))  # the child's temp file is gone
    assert (tmp_path / "frames" / "0001.png").read_bytes() == b"png"  # the finished frame stays
    assert "Sample 1/64" in (tmp_path / "cycles.log").read_text()


def test_a_child_that_hangs_after_its_last_frame_is_stopped_and_its_frames_kept(tmp_path, monkeypatch, capsys):
    job = _job(tmp_path, frames=(1,))
    _stand_in(monkeypatch, f"import time; print('{FRAME_LINE} 1 0.1 0.1', flush=True); time.sleep(60)")
    monkeypatch.setenv(cycles.STALL_ENV, "1")
    t0 = time.monotonic()
    assert [f for f, _, _ in cycles.run_job(job, log=tmp_path / "cycles.log")] == [1]
    assert time.monotonic() - t0 < 15
    assert "did not exit" in capsys.readouterr().err


def test_a_slow_child_that_keeps_finishing_frames_is_left_alone(tmp_path, monkeypatch):
    job = _job(tmp_path)
    script = (
        f"import time\nfor f in (1, 2, 3):\n    time.sleep(0.4)\n    print('{FRAME_LINE}', f, 0.4, 0.4, flush=True)"
    )
    _stand_in(monkeypatch, script)
    monkeypatch.setenv(cycles.STALL_ENV, "0.8")  # each frame within it, the whole job over it
    assert [f for f, _, _ in cycles.run_job(job, log=tmp_path / "cycles.log")] == [1, 2, 3]


@pytest.mark.parametrize("value", ["soon", "0", "-5", "nan"])
def test_a_bad_stall_limit_names_the_variable(tmp_path, monkeypatch, value):
    _stand_in(monkeypatch, "pass")
    monkeypatch.setenv(cycles.STALL_ENV, value)
    with pytest.raises(cycles.CyclesError, match=cycles.STALL_ENV):
        list(cycles.run_job(_job(tmp_path), log=tmp_path / "cycles.log"))


def test_a_failed_child_leaves_no_temp_file(tmp_path, monkeypatch):
    job = _job(tmp_path)
    script = (
        "import json, os, sys\nfrom pathlib import Path\njob = json.loads(Path(sys.argv[1]).read_text())\n"
        "Path(job['outputs'][0]).with_name(f'.0001.{os.getpid()}-0badcafe.tmp.png').write_bytes(b'half')\n"
        "sys.exit('out of memory')"
    )
    _stand_in(monkeypatch, script)
    with pytest.raises(cycles.CyclesError, match="exited with code 1"):
        list(cycles.run_job(job, log=tmp_path / "cycles.log"))
    assert not list((tmp_path / "frames").glob(".*"))


ORPHAN_PARENT = """
import sys
from pathlib import Path
import mpmfx.render.cycles as cycles
CHILD = '''
import os, sys, time
from pathlib import Path
from mpmfx.blender import die_with_parent
die_with_parent()
Path(sys.argv[1]).with_name("child.pid").write_text(str(os.getpid()))
time.sleep(120)
'''
cycles.bpy_available = lambda: True
cycles.child_command = lambda module, *args: [sys.executable, "-c", CHILD, *args]
list(cycles.run_job(Path(sys.argv[1]), log=Path(sys.argv[2])))
"""


def _running(pid: int) -> bool:
    """Whether `pid` is a live process (a zombie that no one has reaped yet is not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the kernel's parent-death signal is Linux's")
def test_a_blender_child_exits_when_its_parent_is_killed(tmp_path):
    import os
    import signal
    import subprocess

    import mpmfx

    job = _job(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(Path(mpmfx.__file__).parents[1])}
    parent = subprocess.Popen([sys.executable, "-c", ORPHAN_PARENT, str(job), str(tmp_path / "cycles.log")], env=env)
    marker, t0 = tmp_path / "child.pid", time.monotonic()
    while not marker.exists() and time.monotonic() - t0 < 60:
        time.sleep(0.1)
    child = int(marker.read_text())
    assert _running(child)
    parent.send_signal(signal.SIGKILL)  # a Dask worker killed mid-render, say
    parent.wait()
    t0 = time.monotonic()
    while _running(child) and time.monotonic() - t0 < 10:
        time.sleep(0.1)
    assert not _running(child)
