"""Cycles renders from the parent side: the job for the Blender child and the child's run.

Never imports bpy (nor pxr): Blender runs as `python -m mpmfx.render.cycles_job JOB.json`
in its own process (both bundle USD libraries), and reports each finished frame on stdout.
"""

from __future__ import annotations

import json
import math
import os
import queue
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from mpmfx.blender import FRAME_LINE, NOTE_LINE, bpy_available, child_command, child_env

INSTALL_HINT = (
    'render.engine = "cycles" needs Blender as a Python module (bpy 4.5, Python 3.11; '
    "pinned in pyproject.toml): run `bash setup.sh`, or `pip install -e '.[render]'`, or render "
    "the fast preview with --set render.engine=preview"
)


STALL_ENV = "MPMFX_RENDER_STALL"
STALL_S = 3600.0  # a CPU frame of a heavy shot can take many minutes; an hour without one is a hang
EXIT_S = 120.0  # after its last frame a child only has to exit


class CyclesError(RuntimeError):
    """The Blender child failed; the message carries the end of its output."""


def blender_version() -> str | None:
    """The installed bpy's version, read from its metadata (importing bpy costs a second)."""
    try:
        return version("bpy")
    except PackageNotFoundError:
        return None


def write_job(
    path: Path,
    *,
    usd: Path,
    frames: list[int],
    outputs: list[Path],
    blend: Path | None,
    width: int,
    height: int,
    samples: int,
    denoise: bool,
    shutter: float,
    fps: float,
    mode: str,
    looks: dict[str, str],
    floor_y: float,
    domain_origin,
    domain_size: float,
    camera: dict,
    sun_elevation: float,
    sun_rotation: float,
    walls: tuple | None = None,
    basin: float | None = None,
    label: str = "",
    blend_usd_root: str | None = None,
    device: str = "cpu",
    collider_looks: dict[str, str] | None = None,
    threads: int = 0,
) -> Path:
    """Write the JSON job the child reads. Units: metres and degrees, in the USD stage's frame
    (Y up). looks: USD prim name (surface group or object) -> `mpmfx.render.looks.LOOKS` key;
    camera: `mpmfx.render.camera.render_camera`'s (the exported USD's camera); outputs: one PNG
    path per frame; blend: where the lit scene is saved;
    walls: (lo, hi) of the box the solver's walls hold, basin: height of the basin drawn there;
    label: text burned into every frame (empty: none); device: "cpu", or "gpu" for Cycles' GPU
    devices where Blender has one; blend_usd_root: what the saved .blend calls the export
    entry's folder (a Blender path such as `//../../published/<name>`, relative to where the
    .blend is published), None: its own absolute path; collider_looks: collider prim name ->
    look (default "collider"); threads: Cycles' CPU threads (0: every core)."""
    job = {
        "usd": str(usd),
        "frames": [int(f) for f in frames],
        "outputs": [str(p) for p in outputs],
        "blend": str(blend) if blend else None,
        "width": width,
        "height": height,
        "samples": samples,
        "denoise": denoise,
        "shutter": shutter,
        "fps": fps,
        "mode": mode,
        "looks": looks,
        "floor_y": floor_y,
        "domain_origin": list(domain_origin),
        "domain_size": domain_size,
        "camera": camera,
        "sun_elevation": sun_elevation,
        "sun_rotation": sun_rotation,
        "walls": walls,
        "basin": basin,
        "label": label,
        "blend_usd_root": blend_usd_root,
        "device": device,
        "collider_looks": collider_looks or {},
        "threads": int(threads),
    }
    path.write_text(json.dumps(job, indent=1))
    return path


def stall_limit() -> float:
    """Seconds a Cycles child may go without finishing a frame: $MPMFX_RENDER_STALL, else STALL_S."""
    raw = os.environ.get(STALL_ENV)
    try:
        limit = float(raw) if raw is not None else STALL_S
        assert math.isfinite(limit) and limit > 0
    except (ValueError, AssertionError):
        raise CyclesError(f"${STALL_ENV} = {raw!r}: give seconds above 0, e.g. {STALL_S:g}, or unset it") from None
    return limit


def run_job(job_path: Path, *, log: Path) -> Iterator[tuple[int, float, float]]:
    """Run the Blender child on `job_path`; yield (frame, wall s, CPU s of all its threads) as
    each frame lands.

    The child's full output goes to `log`; a failure raises CyclesError with its last lines. A
    child that finishes no frame for `stall_limit()` seconds (from its start, or its last frame)
    is killed and CyclesError names the frame it was on; one that hangs after its last frame is
    killed after EXIT_S with a warning (its frames are complete). A child that fails, is killed,
    or is left early (Ctrl-C, another task's failure) leaves no temp file."""
    if not bpy_available():
        raise CyclesError(INSTALL_HINT)
    limit = stall_limit()
    job = json.loads(job_path.read_text())
    cmd = child_command("mpmfx.render.cycles_job", str(job_path))
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=child_env())
        lines = _lines(proc)
        done, deadline = 0, time.monotonic() + limit
        try:
            while (line := _next(lines, deadline)) is not None:
                out.write(line)
                if line.startswith(FRAME_LINE):
                    _, frame, wall, cpu = line.split()
                    done += 1
                    yield int(frame), float(wall), float(cpu)
                    left = limit if done < len(job["frames"]) else min(limit, EXIT_S)
                    deadline = time.monotonic() + left
                elif line.startswith(NOTE_LINE):
                    print(f"[render] {line.removeprefix(NOTE_LINE).strip()}", file=sys.stderr, flush=True)
        except _Stalled:
            proc.kill()
            proc.wait()
            out.flush()
            if done < len(job["frames"]):
                raise CyclesError(_stalled(job, done, limit, log)) from None
            print(
                f"warning: Blender (Cycles) rendered every frame but did not exit within "
                f"{min(limit, EXIT_S):g} s and was stopped (a scripted driver in the scene?); full log: {log}",
                file=sys.stderr,
            )
            return
        finally:
            if proc.poll() is None:  # the consumer stopped early (Ctrl-C): do not leave Blender running
                proc.kill()
            proc.wait()
            _remove_child_temps(job, proc.pid)
    if proc.returncode != 0:
        tail = "".join(log.read_text().splitlines(keepends=True)[-15:])
        raise CyclesError(f"Blender (Cycles) exited with code {proc.returncode}; full log: {log}\n{tail}")


class _Stalled(Exception):
    """No line from the child before the deadline."""


def _lines(proc: subprocess.Popen) -> queue.Queue:
    """The child's output lines, read on a thread (a read blocks, the watchdog must not); None at
    the end of its output."""
    lines: queue.Queue = queue.Queue()

    def read() -> None:
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True, name="cycles-output").start()
    return lines


def _next(lines: queue.Queue, deadline: float) -> str | None:
    try:
        return lines.get(timeout=max(deadline - time.monotonic(), 0.0))
    except queue.Empty:
        raise _Stalled from None


def _stalled(job: dict, done: int, limit: float, log: Path) -> str:
    frame, output = job["frames"][done], job["outputs"][done]
    doing = "loading the scene" if done == 0 else f"frame {frame}"
    return (
        f"Blender (Cycles) finished no frame in {limit:g} s, {doing} (frame {frame} -> {output}), "
        f"and was stopped. A scripted (Python) driver in the scene, a stage too heavy for this "
        f"machine, or a frame that really takes this long: check the log {log}; "
        f"${STALL_ENV} sets the limit in seconds (default {STALL_S:g}); complete frames are kept"
    )


def _remove_child_temps(job: dict, pid: int) -> None:
    """The temp files child `pid` left (`mpmfx.blender.temp_name`'s, its pid in the name: never
    another child's, e.g. another worker's render of the same frame)."""
    for p in [Path(o) for o in job["outputs"]] + ([Path(job["blend"])] if job.get("blend") else []):
        for tmp in p.parent.glob(f".{p.stem}.{pid}-*.tmp{p.suffix}"):
            tmp.unlink(missing_ok=True)
