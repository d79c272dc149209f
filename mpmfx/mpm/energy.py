"""Elastic (stored) energy of the particles: one reduction per frame, for the QA record.

Each particle adds rest volume * energy density of its elastic state (see
`constitutive.solid_energy_density` and `tait_energy_density`), so kinetic + elastic
energy is the quantity an undamped, wall-free scene conserves. Summed in float64 (a
float32 sum over millions of particles loses the small changes QA looks for) and in a fixed
order: each thread sums a fixed set of particles (`stepper.chunk_particle`), then
`stepper.sum_partials` sums the threads' partial sums.
A float64 atomic on one address instead serialised the threads (34 ms for 19M particles
on an H100, once a frame) and made the reported energy differ between replays.
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
)
from .state import SceneFlags, load_m33
from .stepper import chunk_particle

ENERGY_CHUNK = 64  # particles per thread: enough threads for the SVDs, few partial sums


@functools.lru_cache(maxsize=None)
def make_energy(flags: SceneFlags):
    """Energy reduction kernel, in the scene's module next to P2G and G2P (one compile)."""
    has_solid = flags.solid
    has_water = flags.water

    @wp.kernel(enable_backward=False, module=flags.key)
    def elastic_energy(
        materials: wp.array(dtype=MaterialParams),
        material: wp.array(dtype=wp.int32),
        volume: wp.array(dtype=float),
        F: wp.array2d(dtype=wp.vec3), J: wp.array(dtype=float), Jp: wp.array(dtype=float),
        alive: wp.array(dtype=wp.int32), n: int, coalesced: int,
        partial: wp.array2d(dtype=wp.float64),
    ):
        b = wp.tid()
        acc = wp.float64(0.0)
        for i in range(ENERGY_CHUNK):
            p = chunk_particle(b, i, ENERGY_CHUNK, partial.shape[0], coalesced)
            if p >= n:
                break
            if alive[p] != 0:
                mat = materials[material[p]]
                psi = float(0.0)
                if wp.static(has_solid):
                    if mat.mode == MODE_SNOW or mat.mode == MODE_SAND:
                        psi = solid_energy_density(mat, load_m33(F, p), Jp[p])
                if wp.static(has_water):
                    if mat.mode == MODE_WATER:
                        psi = tait_energy_density(mat, J[p])
                acc = acc + wp.float64(volume[p] * psi)
        partial[b, 0] = acc

    return elastic_energy
