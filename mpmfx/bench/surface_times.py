"""`mpmfx bench surface-times`: how long one surfacer call takes as the surface stage makes it, with
its accuracy, in one short run.

Per shape (sphere, torus, box) and sampling (lattice, random) of `mpmfx bench surface` at one
count: each setting of ours (mpmfx.bench.surface_cases.OURS) as the surface stage asks (sparse
leaves, no dense level set), and splashsurf where it runs, called in turn call by call (so a slow
spell of the machine hits every method alike), the median of the calls after a warm-up. Ours:
the time on the device and the time with the copy of mesh and leaves to the host (end to end,
M particles/s), the mean / max vertex error and the area-weighted surface error
(surface_cases.surface_error), in particle spacings h. On a GPU the particles are on the device
before the clock starts. Full run: 10M particles, 11 calls, no peer unless --peers asks;
--quick: 100k, 9 calls, with splashsurf where it is installed. Prints one table; writes
surface_times.csv/json under --out.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence

import numpy as np
import warp as wp

from mpmfx.bench.report import print_table, write_rows
from mpmfx.bench.surface_cases import OURS, PARTICLE_RADIUS_PER_SPACING, sample_shape, shape_sdf, surface_error
from mpmfx.bench.surface_peers import SPLASHSURF_SETTINGS, peer_missing, splashsurf_call
from mpmfx.surface import SurfaceParams, surface_particles

QUICK = (100_000, 9)
FULL = (10_000_000, 11)
PEERS = ("splashsurf",)


def time_case(shape: str, sampling: str, count: int, calls: int, device, peers: Sequence[str]) -> list[dict]:
    """The rows of one shape and sampling: each of our settings, then each peer."""
    dev = wp.get_device(device)
    x, h = sample_shape(shape, count, sampling)
    sdf, _, _ = shape_sdf(shape)
    xd = wp.array(x, dtype=wp.vec3, device=dev) if dev.is_cuda else x
    calls_of = {}
    for label in OURS:
        kw = dict(OURS[label])
        params = SurfaceParams(
            PARTICLE_RADIUS_PER_SPACING * h, voxel_size=kw.pop("voxel_h") * h, dense_output=False, **kw
        )
        calls_of[f"mpmfx {label}"] = lambda params=params: surface_particles(xd, None, params, device=dev.alias)
    for peer in peers:
        kernel, cube = SPLASHSURF_SETTINGS[sampling]
        calls_of[peer] = splashsurf_call(x, h, kernel=kernel, cube=cube)
    last = {name: call() for name, call in calls_of.items()}  # warm-up (a first call compiles)
    total = {name: [] for name in calls_of}
    on_device = {name: [] for name in calls_of}
    for _ in range(calls):
        for name, call in calls_of.items():
            wp.synchronize_device(dev)
            t0 = time.perf_counter()
            last[name] = call()
            total[name].append(time.perf_counter() - t0)
            if name.startswith("mpmfx"):
                on_device[name].append(last[name].stats["device"])
    rows = []
    for name in calls_of:
        t = float(np.median(total[name]))
        row = {
            "shape": shape,
            "sampling": sampling,
            "particles": len(x),
            "method": name,
            "calls": calls,
            "ms_end_to_end": 1e3 * t,
            "Mps_end_to_end": len(x) / t / 1e6,
        }
        if on_device[name]:
            d = float(np.median(on_device[name]))
            mesh = last[name].mesh
            err = np.abs(sdf(mesh.vertices.astype(np.float64))) / h
            row.update(
                {
                    "ms_device": 1e3 * d,
                    "Mps_device": len(x) / d / 1e6,
                    "err_mean_h": float(err.mean()),
                    "err_surface_h": surface_error(mesh.vertices, mesh.faces, sdf) / h,
                    "err_max_h": float(err.max()),
                    "vertices": len(mesh.vertices),
                }
            )
        row["device"] = dev.name if name.startswith("mpmfx") else "cpu"  # the peer runs on the CPU
        rows.append(row)
    return rows


def main(
    *,
    quick: bool = False,
    device: str | None = None,
    out: str = "renders/bench",
    peers: Sequence[str] | None = None,
    counts: Sequence[int] | None = None,
) -> int:
    """Every shape and sampling at each of --counts; 0 on success, 2 on a bad --peers / --counts."""
    count, calls = QUICK if quick else FULL
    counts = tuple(counts) if counts else (count,)
    if min(counts) < 1000:
        print(f"error: --counts {' '.join(map(str, counts))}: use at least 1000 particles", file=sys.stderr)
        return 2
    if peers is None:
        peers = [p for p in PEERS if quick and peer_missing(p) is None]
    unknown = [p for p in peers if p not in PEERS]
    missing = [f"{p} ({peer_missing(p)})" for p in peers if p in PEERS and peer_missing(p)]
    if unknown or missing:
        print(
            f"error: --peers: {'unknown here: ' + ' '.join(unknown) if unknown else ''}"
            f"{'not installed: ' + '; '.join(missing) if missing else ''} (surface-times runs: {' '.join(PEERS)})",
            file=sys.stderr,
        )
        return 2
    rows = []
    for n in counts:
        for shape in ("sphere", "torus", "box"):
            for sampling in ("lattice", "random"):
                case = time_case(shape, sampling, n, calls, device, peers)
                print_table(case, list(case[0]))
                rows += case
    print_table(rows, list(dict.fromkeys(k for r in rows for k in r)))
    print(f"table: {write_rows(rows, out, 'surface_times')} (+ .json)")
    return 0
