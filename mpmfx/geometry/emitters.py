"""Emitters: a source volume sampled at the particles' spacing, refilled at a steady rate.

World units (metres, seconds on the shot clock). Every particle an emitter will ever emit is
made here, before the run, with its birth: the shot time at which it enters (the solver keeps it
dormant until then). So the particle count is known up front, emission is deterministic, and a
resumed run sees the same particles.

The source is sampled once on the voxelise stage's lattice (ppc particles a cell, domain
aligned), its m lattice points ordered downstream first (along the velocity; down, -y, for a
source at rest). Emitted particle j is lattice point j mod m of fill j // m, moved by its own
seeded jitter, and is born at start + (j + 1/2) * volume / rate: one particle every
volume / rate seconds, so the emitted volume per second is the rate. Within a fill the
downstream points come first, so a source whose velocity is about rate / (its cross-section)
sends out an even stream: each fill has left the source when the next begins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from mpmfx.geometry.inside import Lattice, inside_mask
from mpmfx.geometry.voxelise import _JITTER, node_lattice


class EmitterError(ValueError):
    """An emitter that cannot emit (an open mesh, an empty source); the message says why."""


@dataclass
class Emission:
    """What one emitter emits, in emission order.

    points: (n, 3) float64 world positions (m) at birth; birth: (n,) float64 shot time (s)
    at which each enters; volume: m^3 per particle (cell volume / ppc, as voxelise).
    """

    points: np.ndarray
    birth: np.ndarray
    volume: float


def shape_mesh(shape: str, *, size=(0.1, 0.1, 0.1), radius: float = 0.05) -> trimesh.Trimesh:
    """A box of edge lengths `size` (m) or a sphere of `radius` (m), centred at the origin."""
    if shape == "box":
        return trimesh.creation.box(extents=np.asarray(size, float))
    if shape == "sphere":
        return trimesh.creation.icosphere(subdivisions=4, radius=float(radius))
    raise EmitterError(f"unknown emitter shape {shape!r}: use box, sphere or mesh")


def emission_count(rate: float, duration: float, particle_volume: float) -> int:
    """Particles emitted at `rate` m^3/s for `duration` s, `particle_volume` m^3 each."""
    return int(round(rate * max(0.0, duration) / particle_volume))


def source_points(mesh, *, origin, size: float, grid_n: int, ppc: int) -> tuple[np.ndarray, float]:
    """The lattice points (m, 3) float64 (metres, before jitter) inside a closed `mesh`, on the
    voxelise stage's lattice (k = ppc^(1/3) a cell axis), and the lattice spacing h (m)."""
    if not mesh.is_watertight:
        raise EmitterError(
            "the source mesh is not closed (watertight): an emitter needs a volume; close it in your DCC "
            'or use shape = "box" / "sphere"'
        )
    k = int(round(ppc ** (1.0 / 3.0)))
    lat = node_lattice(mesh, origin=origin, size=size, grid_n=grid_n)
    fine = Lattice(origin=lat.origin + 0.5 * lat.h / k, h=lat.h / k, shape=tuple((n - 1) * k for n in lat.shape))
    idx = np.argwhere(inside_mask(mesh, fine))
    if len(idx) == 0:
        raise EmitterError(f"the source holds no particle at this grid (smaller than {fine.h:.3g} m): enlarge it")
    return fine.origin + idx * fine.h, fine.h


def emit(
    points: np.ndarray,
    h: float,
    *,
    particle_volume: float,
    rate: float,
    velocity,
    start: float,
    end: float,
    seed: int,
) -> Emission:
    """Every particle emitted from the source lattice `points` (source_points) at `rate` m^3/s
    from `start` to `end` s, with jitter of up to _JITTER * h drawn from default_rng(seed)."""
    n = emission_count(rate, end - start, particle_volume)
    v = np.asarray(velocity, float)
    flow = v / np.linalg.norm(v) if np.any(v) else np.array([0.0, -1.0, 0.0])
    downstream = points @ flow
    order = np.lexsort((np.arange(len(points)), -downstream))  # downstream first; ties in lattice order
    j = np.arange(n)
    rng = np.random.default_rng(seed)
    jitter = _JITTER * (rng.random((n, 3)) - 0.5)
    pts = points[order[j % len(points)]] + jitter * h
    birth = start + (j + 0.5) * (particle_volume / rate)
    return Emission(points=pts, birth=birth, volume=float(particle_volume))
