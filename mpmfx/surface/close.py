"""Closing pass (SurfaceParams.close_voids): the morphological closing of the inside by a
ball, which fills the dents of sample voids before the smoothing."""

from __future__ import annotations

import warp as wp

from mpmfx.surface.launch import launch_nonempty
from mpmfx.surface.redistance import add_scalar

CLOSE_GATE = (0.06, 0.12)  # x the closing radius: fills the closing drops / keeps in full (close_voids)

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def add_clamp(a: wp.array(dtype=float), value: float, clip: float):
    """a = clamp(a + value, -clip, clip)."""
    t = wp.tid()
    a[t] = wp.clamp(a[t] + value, -clip, clip)


@wp.kernel
def gate_closing(closed: wp.array(dtype=float), dist: wp.array(dtype=float), lo: float, hi: float):
    """Keep the closing's fill dist - closed only where it is deeper than lo voxels (a lattice
    face's uniform shift, an edge it eroded numerically: dist kept), in full from hi voxels
    (the voids it fills), in part in between (no jump as a fill grows past lo between frames).
    close_voids."""
    t = wp.tid()
    fill = dist[t] - closed[t]
    w = wp.clamp((fill - lo) / wp.max(hi - lo, 1e-6), 0.0, 1.0)
    closed[t] = dist[t] - w * fill


def close_voids(redistance, bcoord, bmap, dist, rho: float, clip: float):
    """The morphological closing of the inside of the distance `dist` (voxels, +-clip) by a ball
    of radius rho voxels, as a distance (a new array): grown by rho, redistanced, shrunk by rho.
    redistance: a variant's redistance_*. Dents a ball of radius rho cannot enter from outside
    (the voids of random samples) fill; convex edges stay as they are, where the blur that
    follows fills dents only while it rounds them (SurfaceParams.close_voids).
    Only where the closing fills by more than CLOSE_GATE[0] x rho (in full from CLOSE_GATE[1] x
    rho, a ramp between so that a fill growing between frames does not jump): on the grid,
    grow-redistance-shrink is not the identity on a flat face. It moves a lattice box's faces
    out uniformly by 0.03 h ("fine") to 0.05 h ("fast") at rho = h, and erodes convex edges by
    up to 0.2 h, where the voids it should fill move the distance 0.2-1.5 h. Gated, lattice
    faces stay as without the closing and random samples keep most of its gain."""
    grown = wp.clone(dist)
    launch_nonempty(wp, add_scalar, grown.shape[0], [grown, -rho])
    # converged to its clip: the gate compares it with dist wherever the closing fills
    closed = redistance(bcoord, bmap, grown, clip + rho, clip + rho)
    launch_nonempty(wp, add_clamp, closed.shape[0], [closed, rho, clip])
    launch_nonempty(wp, gate_closing, closed.shape[0], [closed, dist, CLOSE_GATE[0] * rho, CLOSE_GATE[1] * rho])
    return closed
