"""Cycles renders from the parent side: the job for the Blender child and the child's run.

Never imports bpy (nor pxr): Blender runs as `python -m mpmfx.render.cycles_job JOB.json`
in its own process (both bundle USD libraries), and reports each finished frame on stdout.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from mpmfx.blender import FRAME_LINE, NOTE_LINE, bpy_available, child_command, child_env

INSTALL_HINT = (
    'render.engine = "cycles" needs Blender as a Python module (bpy 4.5, Python 3.11; '
    "pinned in pyproject.toml): run `bash setup.sh`, or `pip install -e '.[render]'`, or render "
    "the fast preview with --set render.engine=preview"
)


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
    camera: dict | None,
    view_direction,
    sun_elevation: float,
    sun_rotation: float,
    walls: tuple | None = None,
    basin: float | None = None,
    label: str = "",
    device: str = "cpu",
) -> Path:
    """Write the JSON job the child reads. Units: metres and degrees, in the USD stage's frame
    (Y up). looks: USD prim name (surface group or object) -> `mpmfx.render.looks.LOOKS` key;
    camera: {"position", "look_at"} or None to frame the simulated bounds, seen along
    -view_direction; outputs: one PNG path per frame; blend: where the lit scene is saved;
    walls: (lo, hi) of the box the solver's walls hold, basin: height of the basin drawn there;
    label: text burned into every frame (empty: none); device: "cpu", or "gpu" for Cycles' GPU
    devices where Blender has one."""
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
        "view_direction": list(view_direction),
        "sun_elevation": sun_elevation,
        "sun_rotation": sun_rotation,
        "walls": walls,
        "basin": basin,
        "label": label,
        "device": device,
    }
    path.write_text(json.dumps(job, indent=1))
    return path


def run_job(job_path: Path, *, log: Path) -> Iterator[tuple[int, float, float]]:
    """Run the Blender child on `job_path`; yield (frame, wall s, CPU s of all its threads) as
    each frame lands.

    The child's full output goes to `log`; a failure raises CyclesError with its last lines."""
    if not bpy_available():
        raise CyclesError(INSTALL_HINT)
    cmd = child_command("mpmfx.render.cycles_job", str(job_path))
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=child_env())
        try:
            for line in proc.stdout:
                out.write(line)
                if line.startswith(FRAME_LINE):
                    _, frame, wall, cpu = line.split()
                    yield int(frame), float(wall), float(cpu)
                elif line.startswith(NOTE_LINE):
                    print(f"[render] {line.removeprefix(NOTE_LINE).strip()}", file=sys.stderr, flush=True)
        finally:
            if proc.poll() is None:  # the consumer stopped early (Ctrl-C): do not leave Blender running
                proc.kill()
            proc.wait()
    if proc.returncode != 0:
        tail = "".join(log.read_text().splitlines(keepends=True)[-15:])
        raise CyclesError(f"Blender (Cycles) exited with code {proc.returncode}; full log: {log}\n{tail}")
