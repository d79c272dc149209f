"""The advance's report sums in one reduction a frame, for the QA record: mass, momentum,
kinetic energy and the elastic (stored) energy of the live particles.

For the elastic energy each particle adds rest volume * energy density of its elastic state (see
`constitutive.solid_energy_density` and `tait_energy_density`), so kinetic + elastic
energy is the quantity an undamped, wall-free scene conserves. Summed in float64 (a
float32 sum over millions of particles loses the small changes QA looks for) and in a fixed
order: each thread sums a fixed set of particles (`stepper.chunk_particle`), then
`stepper.sum_partials` sums the threads' partial sums.
A float64 atomic on one address instead would serialise the threads and make the reported
energy differ between replays. One kernel for all six sums, and one read-back, so the GPU
does not sit idle waiting for a second.
"""

from __future__ import annotations

import functools

import warp as wp

from .constitutive import (
    MODE_SAND,
    MODE_SNOW,
    MODE_WATER,
    MaterialParams,
    solid_energy_density,
    tait_energy_density,
    vary_material,
    vec5,
)
from .state import SceneFlags, load_m33
from .stepper import chunk_particle

ENERGY_CHUNK = 64  # particles per thread: enough threads for the SVDs, few partial sums
SUMS = 6  # columns: mass, momentum (3), mass * |v|^2, rest volume * energy density


@functools.lru_cache(maxsize=None)
def make_report(flags: SceneFlags):
    """The report's reduction kernel, in the scene's module next to P2G and G2P (one compile):
    partial[b] = thread b's SUMS columns over its ENERGY_CHUNK live particles, float64."""
    has_solid = flags.solid
    has_water = flags.water
    varied = flags.varied

    @wp.kernel(enable_backward=False, module=flags.key)
    def report_partials(
        materials: wp.array(dtype=MaterialParams),
        material: wp.array(dtype=wp.int32),
        mass: wp.array(dtype=float),
        volume: wp.array(dtype=float),
        v: wp.array(dtype=wp.vec3),
        F: wp.array2d(dtype=wp.vec3),
        J: wp.array(dtype=float),
        Jp: wp.array(dtype=float),
        alive: wp.array(dtype=wp.int32),
        n: int,
        coalesced: int,
        partial: wp.array2d(dtype=wp.float64),
        vary: wp.array(dtype=vec5),
        pid: wp.array(dtype=wp.int32),
    ):
        b = wp.tid()
        acc = wp.vector(length=SUMS, dtype=wp.float64)
        for i in range(ENERGY_CHUNK):
            p = chunk_particle(b, i, ENERGY_CHUNK, partial.shape[0], coalesced)
            if p >= n:
                break
            if alive[p] != 0:
                mat = materials[material[p]]
                if wp.static(varied):
                    mat = vary_material(mat, vary[pid[p]])
                psi = float(0.0)
                if wp.static(has_solid):
                    if mat.mode == MODE_SNOW or mat.mode == MODE_SAND:
                        psi = solid_energy_density(mat, load_m33(F, p), Jp[p])
                if wp.static(has_water):
                    if mat.mode == MODE_WATER:
                        psi = tait_energy_density(mat, J[p])
                m = wp.float64(mass[p])
                vp = v[p]
                vx, vy, vz = wp.float64(vp[0]), wp.float64(vp[1]), wp.float64(vp[2])
                acc[0] = acc[0] + m
                acc[1] = acc[1] + m * vx
                acc[2] = acc[2] + m * vy
                acc[3] = acc[3] + m * vz
                acc[4] = acc[4] + m * (vx * vx + vy * vy + vz * vz)
                acc[5] = acc[5] + wp.float64(volume[p] * psi)
        for c in range(SUMS):
            partial[b, c] = acc[c]

    return report_partials
