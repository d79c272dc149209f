"""`mpmfx bench shot SHOT`: one shot through voxelise, simulate, surface and export, as `mpmfx run`
runs it (the stages overlapped unless --no-overlap), and where each stage's time goes.

Prints one table: each stage's wall time and time a frame, split into
- simulate: the substeps (the device's work and the host waiting for it), the frames' host
  copies, and the wait for the frame writer (host deflate, checksums, disk);
- surface: reading and checking the particle frame, surfacing it (the GPU's kernels and the
  mesh's copy to the host), writing its file (deflate, checksums, disk, on threads), and the
  surfacer's wait for those writers; the part made while simulate ran and the tail after it;
- export: each frame's reading of the upstream frames, VDB grids, USD layer built, and written;
then the whole run against simulate alone, the share of simulate the GPU spent waiting on the
host, the cache bytes a frame, the device's peak memory and the host's (voxelise's, then the
stages' after it), each beside the run's estimate. Writes shot.json under
--out. Kernel compiles of a fresh machine land in the first frames: run it twice, or after
`mpmfx run` of any shot, for the figures docs/benchmarks.md shows.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import warp as wp

from mpmfx.bench.shots import device_name
from mpmfx.meminfo import host_available, peak_rss, reset_peak_rss
from mpmfx.stages import memory
from mpmfx.stages.runner import load_shot

STAGES = ("voxelise", "simulate", "surface", "export")
# the host peak after voxelise is one figure: the stages at once, or the largest of them in turn
AFTER_VOXELISE = {True: "simulate + surface", False: "simulate, surface, export"}


def measure(shot: str | Path, *, overrides=(), cache: Path, device: str | None, overlap: bool = True) -> dict:
    """Run `shot` up to export in `cache`; its times, bytes and memory (the module docstring)."""
    run = load_shot(shot, overrides=list(overrides), cache_root=cache, device=device, quiet=True, overlap=overlap)
    peaks = {}  # host bytes at the peak of voxelise, then of the stages after it (together when overlapped)
    t0 = time.perf_counter()
    reset_peak_rss()
    results = {r.stage: r for r in run.run(until="voxelise")}
    peaks["voxelise"] = peak_rss()
    reset_peak_rss()
    results |= {r.stage: r for r in run.run(until="export") if r.stage != "voxelise"}
    peaks[AFTER_VOXELISE[overlap]] = peak_rss()
    wall = time.perf_counter() - t0
    entries = run.entries()
    man = {s: entries[s].manifest() or {} for s in STAGES}
    frames = len(man["simulate"].get("frames", []))
    qa = man["simulate"].get("qa", {})
    dev = wp.get_device(device)
    n = int(man["simulate"].get("particles", 0))
    counted = memory.counts(run.shot)
    est = memory.need(run.shot, memory.Counts(n, counted.candidates, counted.raster), cuda=dev.is_cuda, overlap=overlap)
    most, per = memory.largest(
        run.shot,
        cuda=dev.is_cuda,
        overlap=overlap,
        host_free=host_available() or 0,
        device_free=int(dev.total_memory) if dev.is_cuda else None,
    )
    return {
        "shot": run.shot.shot.name,
        "overrides": list(overrides),
        "device": device_name(device),
        "overlap": overlap,
        "particles": int(man["simulate"].get("particles", 0)),
        "grid_n": run.shot.domain.grid_n,
        "frames": frames,
        "substeps": sum(int(q.get("substeps", 0)) for q in qa.values()),
        "wall_s": round(wall, 2),
        "stages_s": {s: round(results[s].seconds, 2) for s in STAGES},
        "simulate_split_s": man["simulate"].get("seconds_split", {}),
        "followed_s": {s: man[s].get("followed_s", {}) for s in ("surface", "export")},
        "split_s": {s: man[s].get("seconds_split", {}) for s in ("surface", "export")},  # frames made after simulate
        "faces": man["surface"].get("this_run", {}).get("faces", 0),
        "bytes_per_frame": {s: _frame_bytes(entries[s], frames) for s in ("simulate", "surface", "export")},
        "device_peak_bytes": wp.get_mempool_used_mem_high(dev) if dev.is_cuda and dev.is_mempool_enabled else None,
        "host_peak_bytes": peaks,
        "estimate_bytes": {"host": est.host, "device": est.device},
        "bytes_per_particle": per,
        "largest_particles": most,  # this shot's set-up, at this machine's memory (the GPU's whole)
    }


def _frame_bytes(entry, frames: int) -> int:
    """The entry's per-frame files (frames/, vdb/), bytes a frame on average."""
    total = sum(size for rel, size in entry.files().items() if rel.split("/")[0] in ("frames", "vdb"))
    return round(total / max(frames, 1))


def table(r: dict) -> str:
    n, sim = max(r["frames"] - 1, 1), r["stages_s"]["simulate"]  # frames made by simulate (the first is given)
    split, fol = r["simulate_split_s"], r["followed_s"]
    host = split.get("host_copy", 0.0) + split.get("writer_wait", 0.0)
    ms = lambda s, k=n: f"{1000 * s / k:.0f} ms"  # noqa: E731
    sf, ex = fol["surface"], fol["export"]
    lines = [
        f"{r['shot']} {' '.join(r['overrides'])}".rstrip(),
        f"  {r['particles']:,} particles, grid {r['grid_n']}, {r['frames']} frames, {r['substeps']:,} substeps, "
        f"{r['faces']:,} faces surfaced; {r['device']}; stages {'overlapped' if r['overlap'] else 'in turn'}",
        "  stage     wall s   a frame   where it goes (s, summed over the frames)",
        f"  voxelise  {r['stages_s']['voxelise']:7.1f}",
        f"  simulate  {sim:7.1f}  {ms(sim):>8}   "
        + ", ".join(f"{k} {v:.1f}" for k, v in split.items())
        + (f"; the device waiting on the host {100 * host / sim:.1f} %" if sim else ""),
    ]
    for name, part in (("surface", sf), ("export", ex)):
        busy = sum(v for k, v in part.items() if k != "writer_wait")
        lines.append(
            f"  {name:<8}  {r['stages_s'][name]:7.1f}  {ms(busy + r['stages_s'][name], r['frames']):>8}   "
            + ", ".join(f"{k} {v:.1f}" for k, v in part.items())
            + f"{'; ' if part else ''}after simulate {r['stages_s'][name]:.1f}"
            + _parts(r.get("split_s", {}).get(name))
        )
    lines.append(f"  total     {r['wall_s']:7.1f}            {r['wall_s'] / sim:.2f} x simulate" if sim else "")
    b = r["bytes_per_frame"]
    per = f" ({b['simulate'] / max(r['particles'], 1):.1f} B a particle)"
    lines.append(
        "  cache a frame: "
        + ", ".join(f"{s} {b[s] / 1e6:.1f} MB" + (per if s == "simulate" else "") for s in b)
        + f"; peak memory: device {_gb(r['device_peak_bytes'])}"
    )
    est, per = r["estimate_bytes"], r["bytes_per_particle"]
    lines.append(
        "  host peak against the estimate: "
        + ", ".join(
            f"{k} {_gb(b)} (estimated {_gb(_estimate(est['host'], k))})" for k, b in r["host_peak_bytes"].items()
        )
    )
    lines.append(
        "  estimated peak: "
        + "; ".join(
            f"{w} {_gb(max(est[w].values()))} ({', '.join(f'{k} {b:.0f} B' for k, b in per[w].items())} a particle)"
            for w in ("device", "host")
            if est[w]
        )
        + f"; this machine holds such a shot up to ~{r['largest_particles'] / 1e6:.0f}M particles"
    )
    return "\n".join(lines)


def _estimate(host: dict[str, int], measured: str) -> int | None:
    """The estimate beside a measured peak: that stage's, or the largest of the stages it covers."""
    if measured in host:
        return host[measured]
    return max((b for k, b in host.items() if k != "voxelise"), default=None)


def _parts(split: dict | None) -> str:
    """' (read 0.1, vdb 0.2, ...)': where the stage's own time went, when it says."""
    return f" ({', '.join(f'{k} {v:.1f}' for k, v in split.items())})" if split else ""


def _gb(b) -> str:
    return "-" if b is None else f"{b / 1e9:.2f} GB"


def main(
    *,
    shot: str | None = None,
    overrides=(),
    quick: bool = False,
    device: str | None = None,
    out: str = "renders/bench",
    cache: str | None = None,
    overlap: bool = True,
) -> int:
    """`shot`: a shot file; --quick: the default shot at a CPU size. `cache`: a cache root to
    keep (default: a temporary one, removed after)."""
    if shot is None:
        shot = Path(__file__).parents[2] / "pipeline" / "shots" / "jelly_splash.toml"
        overrides = (*overrides, "shot.frame_end=4") if quick else overrides
    with tempfile.TemporaryDirectory(prefix="mpmfx-bench-shot-") as tmp:
        row = measure(shot, overrides=overrides, cache=Path(cache or tmp), device=device, overlap=overlap)
    print(table(row), flush=True)
    Path(out).mkdir(parents=True, exist_ok=True)
    (Path(out) / "shot.json").write_text(json.dumps(row, indent=1))
    print(f"table: {Path(out) / 'shot.json'}")
    return 0
