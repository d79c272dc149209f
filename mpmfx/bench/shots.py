"""`mpmfx bench shots`: what each stage of the GPU hero shots costs, run as `mpmfx run` runs them.

Each hero shot (pipeline/shots/hero_*.toml) goes through voxelise, simulate and surface with the
product's own stage runner (`mpmfx.load_shot(...).run(until="surface", frames=...)`, the path of
`mpmfx run SHOT --until surface --frames ...`), surfacing its still frames only. A small first run
of the same stages compiles Warp's kernels, timed on its own, so compiles stay out of the stage
times. --quick: CPU size (grid 32, frames up to the second still, no warm-up): tests the path.
Prints one table; writes shots.json (per shot: particles, grid, frames, substeps, seconds per
stage, the simulate stage's own split, mesh sizes, the device) under --out.
"""

from __future__ import annotations

import json
import os
import platform
import tempfile
import time
from pathlib import Path

import warp as wp

from mpmfx.stages.runner import load_shot

SHOT_DIR = Path(__file__).parents[2] / "pipeline" / "shots"
SHOTS = {"hero_dam": [8, 6], "hero_castle": [7, 12]}
"""Shot -> the frames to surface (its stills, best first)."""
SMOKE_GRID = 32


def smoke_overrides(grid_n: int, last: int) -> list[str]:
    """CPU size: a coarse grid (domain origin kept 3 cells below y = 0, the solver's floor) and a
    short shot; everything else is the shot's own."""
    dx = 2.0 / grid_n
    return [f"domain.grid_n={grid_n}", f"domain.origin=[-1.0, {-3 * dx}, -1.0]", f"shot.frame_end={last}"]


def run_shot(name: str, frames: list[int], *, overrides: list[str], cache: Path, device: str | None) -> dict:
    """Run shot `name` up to the surface stage, surfacing `frames`; its times and sizes. Keys
    starting with "_" (the surface cache entry, the shot) are for the caller, not the report."""
    run = load_shot(
        SHOT_DIR / f"{name}.toml", overrides=overrides, cache_root=cache, device=device, quiet=True, workers=1
    )
    t0 = time.perf_counter()
    results = run.run(until="surface", frames=frames)
    wall = time.perf_counter() - t0
    entries = run.entries()
    man = {s: entries[s].manifest() or {} for s in ("voxelise", "simulate", "surface")}
    qa = man["simulate"].get("qa", {})
    substeps = [
        int(q.get("substeps", 0))
        for f, q in sorted(qa.items(), key=lambda kv: int(kv[0]))
        if int(f) > run.shot.shot.frame_start
    ]
    return {
        "shot": name,
        "overrides": overrides,
        "grid_n": run.shot.domain.grid_n,
        "domain_m": run.shot.domain.size,
        "frames_simulated": len(man["simulate"].get("frames", [])),
        "seconds_of_shot": (len(man["simulate"].get("frames", [1])) - 1) / run.shot.shot.fps,
        "frames_surfaced": frames,
        "particles": man["voxelise"].get("particles"),
        "substeps_total": sum(substeps),
        "substeps_per_frame": [min(substeps or [0]), max(substeps or [0])],
        "stages": {r.stage: {"seconds": round(r.seconds, 2), "state": r.state, "frames": r.frames} for r in results},
        "simulate_split": man["simulate"].get("seconds_split"),
        "run_wall_s": round(wall, 2),
        "surface_vertices": man["surface"].get("this_run", {}).get("vertices"),
        "surface_faces": man["surface"].get("this_run", {}).get("faces"),
        "voxel_m": None,
        "_surface_entry": str(entries["surface"].root),
        "_shot": run.shot,
    }


def device_name(device: str | None) -> str:
    """The device's name; the CPU with its core count."""
    d = wp.get_device(device)
    return (
        getattr(d, "name", str(d))
        if d.is_cuda
        else f"CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)"
    )


def warm_up(shots: list[str], cache: Path, device: str | None) -> dict:
    """A tiny run of every shot's stages (each material's and collider's kernels), timed alone:
    compiling Warp's kernels on a fresh machine would otherwise land in the first shot's times."""
    t0 = time.perf_counter()
    warm = {}
    for name in shots:
        warm = run_shot(name, [3], overrides=smoke_overrides(SMOKE_GRID, 3), cache=cache, device=device)
    warm["run_wall_s"] = round(time.perf_counter() - t0, 2)
    warm["shot"] = ", ".join(shots)
    return warm


def table(rows: list[dict], warm: dict | None, dev: str) -> str:
    """The printed table: one line per shot, then its simulate stage's split."""
    lines = [f"device: {dev}"]
    if warm:
        lines.append(f"warm-up (Warp kernel compiles, {warm['shot']} at grid {warm['grid_n']}): {warm['run_wall_s']} s")
    head = (
        "shot",
        "particles",
        "grid",
        "frames",
        "substeps",
        "voxelise s",
        "simulate s",
        "surface s",
        "surf frames",
        "vertices",
    )
    lines.append(" | ".join(head))
    for r in rows:
        st = r["stages"]
        lines.append(
            " | ".join(
                str(x)
                for x in (
                    r["shot"],
                    r["particles"],
                    r["grid_n"],
                    r["frames_simulated"],
                    r["substeps_total"],
                    st.get("voxelise", {}).get("seconds"),
                    st.get("simulate", {}).get("seconds"),
                    st.get("surface", {}).get("seconds"),
                    len(r["frames_surfaced"]),
                    r["surface_vertices"],
                )
            )
        )
        if r.get("simulate_split"):
            lines.append(f"  {r['shot']} simulate, s: " + ", ".join(f"{k} {v}" for k, v in r["simulate_split"].items()))
    return "\n".join(lines)


def public(row: dict) -> dict:
    """A row without its caller-only keys."""
    return {k: v for k, v in row.items() if not k.startswith("_")}


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    """Both hero shots from a fresh cache; --quick: CPU size."""
    dev = device_name(device)
    with tempfile.TemporaryDirectory(prefix="mpmfx-bench-shots-") as tmp:
        cache = Path(tmp)
        warm = None if quick else warm_up(list(SHOTS), cache / "warmup", device)
        rows = []
        for name, frames in SHOTS.items():
            over = smoke_overrides(SMOKE_GRID, max(frames)) if quick else []
            rows.append(run_shot(name, frames, overrides=over, cache=cache, device=device))
            print(f"{name}: {rows[-1]['stages']}", flush=True)
    print(table(rows, warm, dev), flush=True)
    Path(out).mkdir(parents=True, exist_ok=True)
    report = {
        "device": dev,
        "warp": wp.config.version,
        "python": platform.python_version(),
        "quick": quick,
        "warmup": public(warm) if warm else None,
        "shots": [public(r) for r in rows],
    }
    (Path(out) / "shots.json").write_text(json.dumps(report, indent=1))
    print(f"table: {Path(out) / 'shots.json'}")
    return 0
