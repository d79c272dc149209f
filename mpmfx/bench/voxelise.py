"""Speed of voxelise + thickness check on a large sphere, closed and with holes (as scanned and
game assets often are): ``mpmfx bench voxelise``."""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np
import trimesh

from mpmfx.geometry.thickness import check_thickness
from mpmfx.geometry.voxelise import voxelise


def bench_voxelise(n_tris: int = 100_000, grid_n: int = 256, *, ppc: int = 8, holes: bool = False) -> dict:
    """Time voxelise and check_thickness on a UV sphere of ~n_tris triangles.

    The sphere (radius 0.3 m) sits in the unit cube domain with grid_n cells per edge.
    holes: every 200th face is taken out, so the mesh is open and inside is settled by the
    winding number where the rays disagree (mpmfx.geometry.inside).
    Returns {"mesh", "n_tris", "grid_n", "particles", "voxelise_s", "check_s", "verdict"}.
    """

    count = max(8, int(round(np.sqrt(n_tris / 4.0))))  # uv_sphere: ~4 count^2 faces
    mesh = trimesh.creation.uv_sphere(radius=0.3, count=[count, count])
    mesh.apply_translation((0.5, 0.5, 0.5))
    if holes:
        mesh.update_faces(np.arange(len(mesh.faces)) % 200 != 0)
    t0 = time.perf_counter()
    vox = voxelise(mesh, origin=(0, 0, 0), size=1.0, grid_n=grid_n, ppc=ppc)
    t1 = time.perf_counter()
    report = check_thickness(mesh, grid_n=grid_n, origin=(0, 0, 0), size=1.0)
    t2 = time.perf_counter()
    return {
        "mesh": "open" if holes else "closed",
        "n_tris": int(len(mesh.faces)),
        "grid_n": grid_n,
        "particles": int(len(vox.points)),
        "voxelise_s": round(t1 - t0, 2),
        "check_s": round(t2 - t1, 2),
        "verdict": report.verdict.name,
    }


def main(*, quick: bool = False, device: str | None = None, out: str = "renders/bench") -> int:
    """`mpmfx bench voxelise`: a closed and an open sphere (CPU work: `device` is not used);
    --quick: 10k triangles, grid 64."""
    size = (10_000, 64) if quick else (100_000, 256)
    rows = []
    for holes in (False, True):
        with warnings.catch_warnings():  # the open sphere's "not watertight" is the point here
            warnings.simplefilter("ignore", UserWarning)
            rows.append(bench_voxelise(*size, holes=holes))
        print("  ".join(f"{k}={v}" for k, v in rows[-1].items()), flush=True)
    Path(out).mkdir(parents=True, exist_ok=True)
    (Path(out) / "voxelise.json").write_text(json.dumps(rows, indent=2))
    return 0
