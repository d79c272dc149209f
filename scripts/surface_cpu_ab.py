"""Before / after of the CPU surfacer, back to back: two source trees (e.g. an unpacked
`git archive` of main and this checkout) surface the bench's 100k particles case by case,
each in its own process, alternating which tree runs first; splashsurf runs in each process
of the second tree. Prints one line per (tree, case, setting) and writes them as JSON.

    python3 scripts/surface_cpu_ab.py --before /tmp/base --after . --rounds 2 --out ab.json

Seconds: the best of `--calls` whole calls (host particles -> host mesh) after a warm-up, the
default surfacer threads (MPMFX_SURFACE_THREADS); mesh: a hash of the vertices and faces, so
equal hashes mean the very same mesh.
"""
import argparse
import hashlib
import json
import os
import subprocess
import sys
import time

CASES = [(s, m) for m in ("lattice", "random") for s in ("sphere", "torus", "box")]


def worker(shape: str, sampling: str, count: int, calls: int, splash: bool) -> list[dict]:
    import numpy as np
    import warp as wp

    from mpmfx.bench.surface_cases import OURS, _row, sample_shape
    from mpmfx.surface import PARTICLE_RADIUS_PER_SPACING, SurfaceParams, surface_particles

    wp.config.quiet = True
    wp.init()
    x, h = sample_shape(shape, count, sampling)
    rows = []
    for label, setting in OURS.items():
        setting = dict(setting)
        params = SurfaceParams(particle_radius=PARTICLE_RADIUS_PER_SPACING * h, voxel_size=setting.pop("voxel_h") * h,
                               dense_output=False, **setting)
        times = []
        for _ in range(calls + 1):
            t0 = time.perf_counter()
            res = surface_particles(x, None, params, device="cpu")
            times.append(time.perf_counter() - t0)
        v, f = res.mesh.vertices, res.mesh.faces
        row = _row(shape, sampling, x, h, f"mpmfx {label}", "", min(times[1:]), v, f)
        row["mesh"] = hashlib.sha1(np.ascontiguousarray(v).tobytes() + np.ascontiguousarray(f).tobytes()).hexdigest()[:12]
        rows.append(row)
    if splash:
        from mpmfx.bench.surface_peers import run_peer

        p = run_peer("splashsurf", x, h, sampling, repeats=calls)
        rows.append(_row(shape, sampling, x, h, "splashsurf", "", p.seconds, p.vertices, p.faces))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True)
    ap.add_argument("--after", required=True)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--calls", type=int, default=3)
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--no-splash", action="store_true")
    ap.add_argument("--out", default="")
    ap.add_argument("--worker", nargs=2)
    a = ap.parse_args()
    if a.worker:
        print("ROWS", json.dumps(worker(*a.worker, a.count, a.calls, not a.no_splash)))
        return
    out = []
    for r in range(a.rounds):
        for i, (shape, sampling) in enumerate(CASES):
            trees = [("before", a.before), ("after", a.after)]
            if (i + r) % 2:
                trees.reverse()
            for tag, tree in trees:
                env = {**os.environ, "PYTHONPATH": os.path.abspath(tree)}
                cmd = [sys.executable, os.path.abspath(__file__), "--before", a.before, "--after", a.after,
                       "--calls", str(a.calls), "--count", str(a.count), "--worker", shape, sampling]
                if tag == "before" or a.no_splash:
                    cmd.append("--no-splash")
                load = os.getloadavg()[0]
                p = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=os.path.abspath(tree))
                line = [ln for ln in p.stdout.splitlines() if ln.startswith("ROWS ")]
                if not line:
                    sys.exit(f"{tag} {shape} {sampling} failed:\n{p.stderr[-3000:]}")
                for row in json.loads(line[0][5:]):
                    row.update(tree=tag, round=r, load=load)
                    out.append(row)
                    print(f"{tag:6s} {shape:6s} {sampling:7s} {row['method']:12s} {row['seconds']:.3f}s "
                          f"mean {row['err_mean_h']:.4f} h max {row['err_max_h']:.3f} h pieces {row['components']} "
                          f"mesh {row.get('mesh', '-')} load {load:.2f}", flush=True)
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
