"""The surfacer's copy to the host, pageable against the pool of page-locked buffers
(pinned.PINNED), on the GPU: per case, "fast", rounds of download(pinned=False) and
download(pinned=True) alternating on one device result, each result kept until the next call
of its kind (as a frame loop keeps the last frame), medians in ms; and whether both give the
same bytes.

    python3 scripts/host_copy_probe.py [count]
"""
import sys
import time

import numpy as np
import warp as wp

from mpmfx.bench.surface_cases import OURS, PARTICLE_RADIUS_PER_SPACING, sample_shape
from mpmfx.surface import SurfaceParams
from mpmfx.surface.sparse import surface_on_device

count = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000_000
wp.config.quiet = True
wp.init()
print(wp.get_device().name, flush=True)
for shape, sampling in (("torus", "lattice"), ("torus", "random"), ("box", "random"), ("sphere", "lattice")):
    x, h = sample_shape(shape, count, sampling)
    kw = dict(OURS["fast"])
    params = SurfaceParams(PARTICLE_RADIUS_PER_SPACING * h, voxel_size=kw.pop("voxel_h") * h, dense_output=False, **kw)
    d = surface_on_device(wp.array(x, dtype=wp.vec3), None, params)
    wp.synchronize()
    times = {False: [], True: []}
    last = {}
    for _ in range(6):
        for pinned in (False, True):
            t0 = time.perf_counter()
            last[pinned] = d.download(params, pinned=pinned)
            times[pinned].append(time.perf_counter() - t0)
    a, b = last[False], last[True]
    same = (np.array_equal(a.mesh.vertices, b.mesh.vertices) and np.array_equal(a.mesh.faces, b.mesh.faces)
            and np.array_equal(a.sparse.values, b.sparse.values) and np.array_equal(a.sparse.block_ijk, b.sparse.block_ijk))
    mb = (a.mesh.vertices.nbytes * 2 + a.mesh.faces.nbytes + a.sparse.values.nbytes) / 1e6
    print(f"{shape} {sampling} {len(x)}: {mb:.0f} MB; pageable {1e3 * np.median(times[False]):.1f} ms "
          f"(first {1e3 * times[False][0]:.1f}), pinned pool {1e3 * np.median(times[True]):.1f} ms "
          f"(first {1e3 * times[True][0]:.1f}); same bytes: {same}", flush=True)
