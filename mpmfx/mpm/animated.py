"""Animated (deforming) mesh colliders: a triangle mesh whose vertices move frame by frame.

Each collider holds every sampled frame of its vertices on the device, uploaded once
((F, V) vec3: 12 bytes a vertex a frame, e.g. 10k vertices x 100 frames = 12 MB), so any
substep finds its pair of frames from the device-side time with no host work, inside a
captured chunk as well (a ring of two frames would need the host at every frame boundary).
Each substep (`AnimatedMeshes.pose_host` on the reference loop, `pose_device` in the device
stepper's chunk):

1. one thread a vertex sets the `wp.Mesh` points to the linear interpolation in time between
   the two frames around the substep's start, and the vertex velocity to the motion between the
   frames around its midpoint over their interval (shot clock), spread over the substep's sim
   seconds as `collider_velocity` does for the rigid colliders;
2. `wp.Mesh.refit()` refits the BVH to the new points (on a GPU a few kernel launches on the
   current stream, a memset and a CUB scan whose scratch comes from Warp's stream-ordered
   allocator: legal inside a CUDA graph capture where the device has a memory pool, Warp's default;
   with the winding number the refit also updates the BVH's solid-angle data, one more kernel).

The grid update (`make_mesh_contact`) then finds, at each node holding mass, the closest point
within `band` of the surface, and which side of the mesh the node is on (`INSIDE_TEST`): where
the closest point lies inside a face, the side of that face, exact there for a closed surface
(the node lies on the face's normal line); where it lies on an edge or a vertex, the generalised
winding number (`wp.mesh_query_point_sign_winding_number`; Warp's angle-weighted pseudo-normal
sign, `..._sign_normal`, takes points just outside a booleaned mesh's finely split faces for
inside). Asking the winding number everywhere costs about four times as much
(`lab/collider_cost.py`). At a node inside the mesh the
velocity relative to the surface velocity there (barycentric interpolation of the vertex
velocities, `wp.mesh_eval_velocity`: the collider's own deformation, not a rigid pose) loses
its approaching normal part and Coulomb friction, as the rigid colliders do (`apply_collider`).
The meshes must be closed and wound outward; a node near a face buried inside another closed
shell of the same mesh is taken for outside (material does not reach there).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from .slots import Clock, Status
from .stepper import StepperParams

__all__ = ["AnimatedMesh", "AnimatedMeshes", "MeshColliders", "BAND_CELLS"]

BAND_CELLS = 2.0  # grid cells: how deep inside its surface a node still meets an animated mesh


@dataclass(frozen=True)
class AnimatedMesh:
    """One animated mesh collider.

    times: (F,) float64 shot seconds of the samples, strictly increasing (F >= 1; outside them
        the first / last pose holds, still). points: (F, V, 3) float32 vertex positions, domain
        units, one row a sample. triangles: (T, 3) int32 vertex indices, the same every sample,
        wound outward. friction: Coulomb coefficient mu (>= 0).
    """

    times: np.ndarray
    points: np.ndarray
    triangles: np.ndarray
    friction: float = 0.0

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen)
        t = np.atleast_1d(np.asarray(self.times, np.float64))
        p = np.ascontiguousarray(self.points, np.float32)
        tri = np.ascontiguousarray(self.triangles, np.int32)
        if t.ndim != 1 or np.any(np.diff(t) <= 0):
            raise ValueError("AnimatedMesh.times: give F >= 1 strictly increasing sample times (s)")
        if p.ndim != 3 or p.shape[0] != len(t) or p.shape[2] != 3 or not np.all(np.isfinite(p)):
            raise ValueError(f"AnimatedMesh.points: expected finite (F={len(t)}, V, 3), got {p.shape}")
        if tri.ndim != 2 or tri.shape[1] != 3 or len(tri) == 0 or tri.min() < 0 or tri.max() >= p.shape[1]:
            raise ValueError("AnimatedMesh.triangles: expected (T, 3) indices into the V vertices")
        if self.friction < 0:
            raise ValueError(f"AnimatedMesh.friction = {self.friction} must be >= 0")
        set_("times", t)
        set_("points", p)
        set_("triangles", tri)


@wp.struct
class MeshColliders:
    """The grid update's view of the animated meshes: ids (wp.Mesh ids), friction (mu each),
    count, band (domain units: nodes deeper inside than this do not meet the mesh)."""

    ids: wp.array(dtype=wp.uint64)
    friction: wp.array(dtype=float)
    count: int
    band: float


@wp.func
def _segment(times: wp.array(dtype=wp.float64), t: wp.float64) -> int:
    """The i in [0, F-2] with times[i] <= t < times[i+1] (clamped at the ends)."""
    lo = int(0)
    hi = times.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if times[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo


@wp.kernel(enable_backward=False)
def _pose_points(
    times: wp.array(dtype=wp.float64),
    frames: wp.array2d(dtype=wp.vec3),
    clock: wp.array(dtype=wp.float64),
    points: wp.array(dtype=wp.vec3),
    vels: wp.array(dtype=wp.vec3),
):
    """Vertex v's position at the substep start clock[0] and its velocity (domain/s) over the
    substep [clock[0], clock[1]] (shot s) of clock[2] sim seconds; clock[3] == 0: leave both."""
    v = wp.tid()
    if clock[3] == wp.float64(0.0):
        return
    f = times.shape[0]
    if f == 1:
        points[v] = frames[0, v]
        vels[v] = wp.vec3(0.0)
        return
    t0 = clock[0]
    t1 = clock[1]
    i = _segment(times, t0)
    a = wp.clamp((t0 - times[i]) / (times[i + 1] - times[i]), wp.float64(0.0), wp.float64(1.0))
    points[v] = frames[i, v] + float(a) * (frames[i + 1, v] - frames[i, v])
    tm = wp.float64(0.5) * (t0 + t1)
    vel = wp.vec3(0.0)
    if tm > times[0] and tm < times[f - 1]:
        j = _segment(times, tm)
        rate = (t1 - t0) / (clock[2] * (times[j + 1] - times[j]))  # 1/s: per shot interval, on the sim clock
        vel = float(rate) * (frames[j + 1, v] - frames[j, v])
    vels[v] = vel


@wp.kernel(enable_backward=False)
def _stepper_clock(sp: StepperParams, clk: wp.array(dtype=wp.float64), clock: wp.array(dtype=wp.float64)):
    """The device stepper's substep as _pose_points reads it: the shot interval that
    `stepper.pose_colliders` poses the rigid colliders over, its sim dt, and whether it runs."""
    if int(clk[Clock.STATUS]) != Status.RUNNING:
        clock[3] = wp.float64(0.0)
        return
    clock[0] = clk[Clock.T0] + clk[Clock.DONE] / sp.time_scale
    clock[1] = clk[Clock.T1]
    if clk[Clock.LAST] == wp.float64(0.0):
        clock[1] = clk[Clock.T0] + (clk[Clock.DONE] + clk[Clock.DT]) / sp.time_scale
    clock[2] = clk[Clock.DT]
    clock[3] = wp.float64(1.0)


class AnimatedMeshes:
    """The animated meshes of one Solver on its device: every sample, a `wp.Mesh` each, and
    `params` (MeshColliders) for the grid update, which meets them within BAND_CELLS cells of
    dx (domain units) of their surface."""

    def __init__(self, meshes, device, dx: float):
        self.meshes = tuple(meshes)
        self.device = device
        with wp.ScopedDevice(device):
            self.clock = wp.zeros(4, dtype=wp.float64)  # t0, t1 (shot s), sim dt (s), active
            self.times = [wp.array(m.times, dtype=wp.float64) for m in self.meshes]
            self.frames = [wp.array(m.points, dtype=wp.vec3) for m in self.meshes]
            self.wp_meshes = [
                wp.Mesh(
                    points=wp.array(m.points[0], dtype=wp.vec3),
                    indices=wp.array(m.triangles.ravel(), dtype=wp.int32),
                    velocities=wp.zeros(m.points.shape[1], dtype=wp.vec3),
                    support_winding_number=True,
                )
                for m in self.meshes
            ]
            p = MeshColliders()
            p.ids = wp.array([m.id for m in self.wp_meshes], dtype=wp.uint64)
            p.friction = wp.array([float(m.friction) for m in self.meshes], dtype=float)
            p.count = len(self.meshes)
            p.band = float(BAND_CELLS * dx)
        self.params = p

    @property
    def device_bytes(self) -> int:
        """Device memory of the samples (bytes), beside the meshes' own points and BVHs."""
        return sum(m.points.nbytes for m in self.meshes)

    def _pose(self) -> None:
        for times, frames, mesh in zip(self.times, self.frames, self.wp_meshes):
            wp.launch(
                _pose_points,
                dim=frames.shape[1],
                device=self.device,
                inputs=[times, frames, self.clock, mesh.points, mesh.velocities],
            )
            mesh.refit()

    def pose_host(self, t0: float, t1: float, sim_dt: float) -> None:
        """Pose for the substep [t0, t1] (shot s) of sim_dt (s): the reference loop."""
        self.clock.assign(np.array([t0, t1, sim_dt, 1.0]))
        self._pose()

    def pose_device(self, sp, clk) -> None:
        """Pose for the substep the device stepper's `begin` set up in clk (no host read)."""
        wp.launch(_stepper_clock, dim=1, device=self.device, inputs=[sp, clk, self.clock])
        self._pose()

    @staticmethod
    def grid_argument(meshes: "AnimatedMeshes | None") -> MeshColliders:
        """The grid update's `mesh_cols`: `meshes.params`, or without animated meshes an
        empty one (never read: that kernel compiles no mesh code)."""
        return meshes.params if meshes is not None else _no_meshes()


@functools.lru_cache(maxsize=None)
def _no_meshes() -> MeshColliders:
    p = MeshColliders()
    p.count = 0
    p.band = 0.0
    return p


FACE_EPS = 1.0e-3  # barycentric: a closest point nearer a face's edge than this is on the edge


@wp.func
def _inside_winding(mid: wp.uint64, xn: wp.vec3, band: float, dx: float):
    """(inside 0/1, face, u, v) of the node xn against mesh mid within band (domain units):
    the closest point, and the generalised winding number for the side."""
    q = wp.mesh_query_point_sign_winding_number(mid, xn, band)
    inside = int(0)
    if q.result and q.sign < 0.0:
        inside = 1
    return inside, q.face, q.u, q.v


@wp.func
def _inside_parity(mid: wp.uint64, xn: wp.vec3, band: float, dx: float):
    """As _inside_winding, the side from the parity of ray crossings."""
    q = wp.mesh_query_point_sign_parity(mid, xn, band)
    inside = int(0)
    if q.result and q.sign < 0.0:
        inside = 1
    return inside, q.face, q.u, q.v


@wp.func
def _inside_faces(mid: wp.uint64, xn: wp.vec3, band: float, dx: float):
    """As _inside_winding, the side from the face normal where the closest point lies inside a
    face (exact there for a closed, outward-wound surface: the node lies on that face's normal
    line), the winding number only where it lies on an edge or a vertex, or on the face itself."""
    q = wp.mesh_query_point_no_sign(mid, xn, band)
    if not q.result:
        return int(0), int(0), 0.0, 0.0
    w = 1.0 - q.u - q.v
    if wp.min(wp.min(q.u, q.v), w) > FACE_EPS:
        s = wp.dot(wp.mesh_eval_face_normal(mid, q.face), xn - wp.mesh_eval_position(mid, q.face, q.u, q.v))
        if s > 1.0e-4 * dx:
            return int(0), q.face, q.u, q.v
        if s < -1.0e-4 * dx:
            return int(1), q.face, q.u, q.v
    return _inside_winding(mid, xn, band, dx)  # (its closest point again: Warp has no winding number alone)


@wp.func
def _meet_mesh(mid: wp.uint64, face: int, u: float, w: float, xn: wp.vec3, v: wp.vec3, dx: float, mu: float) -> wp.vec3:
    """The velocity v of node xn, inside mesh mid, after meeting its surface at the closest point
    (face, u, w): the approaching normal part of the velocity relative to the surface's own goes,
    and Coulomb friction mu takes mu |vn| of the tangential part."""
    cp = wp.mesh_eval_position(mid, face, u, w)
    d = cp - xn  # inside: from the node out to the surface
    dl = wp.length(d)
    n = wp.mesh_eval_face_normal(mid, face)
    if dl > 1.0e-4 * dx:
        n = d / dl
    v_col = wp.mesh_eval_velocity(mid, face, u, w)
    v_rel = v - v_col
    vn = wp.dot(v_rel, n)
    if vn < 0.0:  # approaching: else separating, passes
        vt = v_rel - vn * n
        vt_len = wp.length(vt)
        if vt_len > 0.0:
            vt = vt * wp.max(0.0, 1.0 + mu * vn / vt_len)  # Coulomb: lose mu*|vn|
        v = v_col + vt
    return v


def make_mesh_contact(inside_test: str):
    """The grid update's wp.func (mc, xn, v, dx) -> v for every animated mesh, the side decided
    by `inside_test` (INSIDE_TESTS)."""
    query = {"winding": _inside_winding, "parity": _inside_parity, "faces": _inside_faces}[inside_test]

    @wp.func
    def mesh_contact(mc: MeshColliders, xn: wp.vec3, v: wp.vec3, dx: float) -> wp.vec3:
        for c in range(mc.count):
            mid = mc.ids[c]
            inside, face, u, w = wp.static(query)(mid, xn, mc.band, dx)
            if inside == 1:
                v = _meet_mesh(mid, face, u, w, xn, v, dx, mc.friction[c])
        return v

    return mesh_contact


INSIDE_TESTS = ("winding", "parity", "faces")  # lab/collider_cost.py times each (docs/benchmarks.md)
INSIDE_TEST = "faces"  # the one Solvers build their grid update with
