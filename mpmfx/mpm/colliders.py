"""Kinematic colliders: analytic shapes or a signed-distance grid, moved by keyframes.

A collider acts in the grid update (where all contact happens): at every node
inside it or on its surface (signed distance <= 0) the velocity relative to the collider loses its
approaching normal part, and its tangential part loses Coulomb friction, mu * |vn|.
Poses are keyframed on the shot clock and interpolated per substep (translation linear,
rotation slerp); the collider's own velocity comes from the pose change over the substep.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import warp as wp

__all__ = ["ColliderKind", "Collider", "ColliderParams", "ColliderKeys", "collider_velocity", "pose_matrix"]


class ColliderKind(enum.IntEnum):
    PLANE = 0  # half-space below the plane through `point` with outward `normal`
    BOX = 1  # axis-aligned (in the collider frame) box of `half_extents` about the origin
    SPHERE = 2  # ball of `radius` about the origin
    SDF = 3  # signed distance grid `sdf` (negative inside), local frame


def _f32(a, shape, name):
    arr = np.asarray(a, dtype=np.float32)
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise ValueError(f"Collider.{name}: expected finite values of shape {shape}, got {arr.shape}")
    return arr


@dataclass(frozen=True)
class Collider:
    """A rigid, kinematic collider.

    Attributes:
        kind: ColliderKind.
        friction: Coulomb coefficient mu (>= 0), dt-independent.
        times: (k,) float seconds on the shot clock, increasing; held constant outside.
        translations: (k, 3) float32, domain units: position of the local origin
            ((1, 3) = the same for all keyframes).
        rotations: (k, 4) float32 quaternions (x, y, z, w), local -> domain ((1, 4) = same).
        normal: (3,) plane normal, local frame (PLANE).
        point: (3,) a point on the plane, local frame (PLANE).
        half_extents: (3,) domain units (BOX).
        radius: domain units (SPHERE).
        sdf: (a, b, c) float32 signed distances, domain units, negative inside (SDF).
        sdf_origin: (3,) local position of sdf[0, 0, 0], domain units.
        sdf_voxel: voxel size, domain units. Outside the grid the collider is absent.
    """

    kind: ColliderKind
    friction: float = 0.0
    times: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    translations: np.ndarray = field(default_factory=lambda: np.zeros((1, 3), np.float32))
    rotations: np.ndarray = field(default_factory=lambda: np.array([[0, 0, 0, 1]], np.float32))
    normal: tuple[float, float, float] = (0.0, 1.0, 0.0)
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    half_extents: tuple[float, float, float] = (0.1, 0.1, 0.1)
    radius: float = 0.1
    sdf: np.ndarray | None = None
    sdf_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sdf_voxel: float = 0.0

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen)
        set_("kind", ColliderKind(self.kind))
        times = np.atleast_1d(np.asarray(self.times, dtype=np.float64))
        k = times.shape[0]
        if times.ndim != 1 or k < 1 or np.any(np.diff(times) <= 0):
            raise ValueError("Collider.times: give k >= 1 strictly increasing keyframe times (s)")
        set_("times", times)
        # a single translation / rotation holds for every keyframe
        trans = np.asarray(self.translations, np.float32).reshape(-1, 3)
        rots = np.asarray(self.rotations, np.float32).reshape(-1, 4)
        set_("translations", _f32(np.repeat(trans, k, 0) if len(trans) == 1 else trans, (k, 3), "translations"))
        q = _f32(np.repeat(rots, k, 0) if len(rots) == 1 else rots, (k, 4), "rotations")
        norms = np.linalg.norm(q, axis=1, keepdims=True)
        if np.any(norms < 1e-6):
            raise ValueError("Collider.rotations: quaternions must be non-zero (x, y, z, w)")
        set_("rotations", q / norms)
        if self.friction < 0:
            raise ValueError(f"Collider.friction = {self.friction} must be >= 0")
        if self.kind == ColliderKind.PLANE and np.linalg.norm(self.normal) < 1e-6:
            raise ValueError("Collider.normal must be non-zero for a PLANE")
        if self.kind == ColliderKind.SDF:
            if self.sdf is None or np.asarray(self.sdf).ndim != 3 or self.sdf_voxel <= 0:
                raise ValueError("Collider.sdf: an SDF collider needs a 3D sdf grid and sdf_voxel > 0")
            set_("sdf", np.ascontiguousarray(self.sdf, dtype=np.float32))

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Interpolated (translation (3,), quaternion xyzw (4,)) at shot time t, seconds."""
        ts = self.times
        if t <= ts[0] or len(ts) == 1:
            return self.translations[0].astype(np.float64), self.rotations[0].astype(np.float64)
        if t >= ts[-1]:
            return self.translations[-1].astype(np.float64), self.rotations[-1].astype(np.float64)
        i = int(np.searchsorted(ts, t, side="right")) - 1
        a = (t - ts[i]) / (ts[i + 1] - ts[i])
        pos = (1 - a) * self.translations[i] + a * self.translations[i + 1]
        return pos.astype(np.float64), _slerp(self.rotations[i], self.rotations[i + 1], a)


def pose_matrix(times, translations, rotations, t: float) -> np.ndarray:
    """(4,4) rigid transform at shot time t (s) of keyframes as `Collider` takes them: the
    solver's own interpolation (linear translation, slerp rotation), for USD and renders."""
    p, (x, y, z, w) = Collider(
        kind=ColliderKind.PLANE, times=times, translations=translations, rotations=rotations
    ).pose(t)
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = p
    return m


def _slerp(q0, q1, a):
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    d = float(np.dot(q0, q1))
    if d < 0:  # shortest arc
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
    else:
        th = np.arccos(d)
        q = (np.sin((1 - a) * th) * q0 + np.sin(a * th) * q1) / np.sin(th)
    return q / np.linalg.norm(q)


def collider_velocity(c: Collider, t0: float, t1: float, sim_dt: float):
    """Pose at t0 and the rigid velocity over [t0, t1] (shot s) spread over sim_dt (sim s).

    Returns (pos (3,), quat (4,), lin_vel (3,) domain/s, ang_vel (3,) rad/s).
    """
    p0, q0 = c.pose(t0)
    p1, q1 = c.pose(t1)
    lin = (p1 - p0) / sim_dt
    # relative rotation q1 * conj(q0) -> axis-angle / dt
    x0, y0, z0, w0 = -q0[0], -q0[1], -q0[2], q0[3]
    x1, y1, z1, w1 = q1
    dq = np.array(
        [
            w1 * x0 + x1 * w0 + y1 * z0 - z1 * y0,
            w1 * y0 - x1 * z0 + y1 * w0 + z1 * x0,
            w1 * z0 + x1 * y0 - y1 * x0 + z1 * w0,
            w1 * w0 - x1 * x0 - y1 * y0 - z1 * z0,
        ]
    )
    if dq[3] < 0:
        dq = -dq
    s = np.linalg.norm(dq[:3])
    ang = np.zeros(3) if s < 1e-12 else dq[:3] / s * (2.0 * np.arctan2(s, dq[3]) / sim_dt)
    return p0, q0, lin, ang


@wp.struct
class ColliderParams:
    """Device form of one collider at the current substep."""

    kind: int
    friction: float
    pos: wp.vec3
    rot: wp.quat
    lin_vel: wp.vec3
    ang_vel: wp.vec3
    normal: wp.vec3
    point: wp.vec3
    half_extents: wp.vec3
    radius: float
    sdf_offset: int
    sdf_shape: wp.vec3i
    sdf_origin: wp.vec3
    sdf_voxel: float


def pack_colliders(colliders, t0: float, t1: float, sim_dt: float) -> list:
    """Host Colliders -> list of ColliderParams for the substep [t0, t1] (shot clock)."""
    out, offset = [], 0
    for c in colliders:
        pos, q, lin, ang = collider_velocity(c, t0, t1, sim_dt)
        p = ColliderParams()
        p.kind = int(c.kind)
        p.friction = float(c.friction)
        p.pos = wp.vec3(*pos)
        p.rot = wp.quat(*q)
        p.lin_vel = wp.vec3(*lin)
        p.ang_vel = wp.vec3(*ang)
        n = np.asarray(c.normal, np.float64)
        p.normal = wp.vec3(*(n / np.linalg.norm(n)))
        p.point = wp.vec3(*c.point)
        p.half_extents = wp.vec3(*c.half_extents)
        p.radius = float(c.radius)
        p.sdf_offset = offset
        if c.sdf is not None:
            p.sdf_shape = wp.vec3i(*c.sdf.shape)
            offset += c.sdf.size
        p.sdf_origin = wp.vec3(*c.sdf_origin)
        p.sdf_voxel = float(c.sdf_voxel)
        out.append(p)
    return out


class ColliderKeys:
    """Every collider's keyframes on the device, so a substep poses its colliders there
    (`pose_colliders`, the device stepper) exactly as `pack_colliders` does on the host:
    times (K,) float64 s, translations (K,) vec3, rotations (K,) quat xyzw, and per collider
    the offset and count of its keys."""

    def __init__(self, colliders, device):
        self.n = len(colliders)
        cat = lambda f: np.concatenate([f(c) for c in colliders])  # noqa: E731
        counts = np.array([len(c.times) for c in colliders], np.int32)
        with wp.ScopedDevice(device):
            self.times = wp.array(cat(lambda c: c.times), dtype=wp.float64)
            self.translations = wp.array(cat(lambda c: c.translations), dtype=wp.vec3)
            self.rotations = wp.array(cat(lambda c: c.rotations), dtype=wp.quat)
            self.offsets = wp.array(np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32), dtype=wp.int32)
            self.counts = wp.array(counts, dtype=wp.int32)


@wp.func
def _key_index(times: wp.array(dtype=wp.float64), o: int, k: int, t: wp.float64) -> int:
    """Collider.pose's searchsorted(side="right") - 1: the last key at or before t; -1 at or
    before the first key (or a single key), k - 1 at or after the last."""
    if k == 1 or t <= times[o]:
        return -1
    if t >= times[o + k - 1]:
        return k - 1
    i = int(0)
    while i + 1 < k and times[o + i + 1] <= t:
        i += 1
    return i


@wp.func
def _key_pos(
    keys_t: wp.array(dtype=wp.float64), keys_p: wp.array(dtype=wp.vec3), o: int, k: int, t: wp.float64
) -> wp.vec3d:
    """Collider.pose's translation: float32 lerp as numpy does it on float32 keys."""
    i = _key_index(keys_t, o, k, t)
    if i < 0:
        return wp.vec3d(keys_p[o])
    if i == k - 1:
        return wp.vec3d(keys_p[o + k - 1])
    a = (t - keys_t[o + i]) / (keys_t[o + i + 1] - keys_t[o + i])
    return wp.vec3d(float(wp.float64(1.0) - a) * keys_p[o + i] + float(a) * keys_p[o + i + 1])


@wp.func
def _key_rot(
    keys_t: wp.array(dtype=wp.float64), keys_q: wp.array(dtype=wp.quat), o: int, k: int, t: wp.float64
) -> wp.quatd:
    """Collider.pose's rotation: _slerp in float64."""
    i = _key_index(keys_t, o, k, t)
    if i < 0:
        return wp.quatd(keys_q[o])
    if i == k - 1:
        return wp.quatd(keys_q[o + k - 1])
    a = (t - keys_t[o + i]) / (keys_t[o + i + 1] - keys_t[o + i])
    q0 = wp.quatd(keys_q[o + i])
    q1 = wp.quatd(keys_q[o + i + 1])
    d = wp.dot(q0, q1)
    if d < wp.float64(0.0):  # shortest arc
        q1 = -q1
        d = -d
    q = q0
    if d > wp.float64(0.9995):
        q = q0 + a * (q1 - q0)
    else:
        th = wp.acos(d)
        q = (wp.sin((wp.float64(1.0) - a) * th) * q0 + wp.sin(a * th) * q1) / wp.sin(th)
    return q / wp.length(q)


@wp.func
def pose_collider(
    c: int,
    keys_t: wp.array(dtype=wp.float64),
    keys_p: wp.array(dtype=wp.vec3),
    keys_q: wp.array(dtype=wp.quat),
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    t0: wp.float64,
    t1: wp.float64,
    sim_dt: wp.float64,
    out: wp.array(dtype=ColliderParams),
):
    """collider_velocity of collider c over the shot interval [t0, t1] spread over sim_dt
    (s), written into its ColliderParams (the static fields stay as packed)."""
    o = offsets[c]
    k = counts[c]
    p0 = _key_pos(keys_t, keys_p, o, k, t0)
    p1 = _key_pos(keys_t, keys_p, o, k, t1)
    q0 = _key_rot(keys_t, keys_q, o, k, t0)
    q1 = _key_rot(keys_t, keys_q, o, k, t1)
    # relative rotation q1 * conj(q0) -> axis-angle / dt, as collider_velocity
    x0 = -q0[0]
    y0 = -q0[1]
    z0 = -q0[2]
    w0 = q0[3]
    dq = wp.quatd(
        q1[3] * x0 + q1[0] * w0 + q1[1] * z0 - q1[2] * y0,
        q1[3] * y0 - q1[0] * z0 + q1[1] * w0 + q1[2] * x0,
        q1[3] * z0 + q1[0] * y0 - q1[1] * x0 + q1[2] * w0,
        q1[3] * w0 - q1[0] * x0 - q1[1] * y0 - q1[2] * z0,
    )
    if dq[3] < wp.float64(0.0):
        dq = -dq
    axis = wp.vec3d(dq[0], dq[1], dq[2])
    s = wp.length(axis)
    ang = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    if s >= wp.float64(1e-12):
        ang = axis / s * (wp.float64(2.0) * wp.atan2(s, dq[3]) / sim_dt)
    p = out[c]
    p.pos = wp.vec3(p0)
    p.rot = wp.quat(q0)
    p.lin_vel = wp.vec3((p1 - p0) / sim_dt)
    p.ang_vel = wp.vec3(ang)
    out[c] = p


def concat_sdfs(colliders) -> np.ndarray:
    """All SDF grids, flattened C-order one after another (offsets as in pack_colliders)."""
    parts = [c.sdf.ravel() for c in colliders if c.sdf is not None]
    return np.concatenate(parts) if parts else np.zeros(1, np.float32)


@wp.func
def sample_sdf(c: ColliderParams, sdf: wp.array(dtype=float), xl: wp.vec3) -> float:
    """Trilinear signed distance from the collider's grid; +1e6 (absent) outside it."""
    g = (xl - c.sdf_origin) / c.sdf_voxel
    if g[0] < 0.0 or g[1] < 0.0 or g[2] < 0.0:
        return 1.0e6
    i = int(wp.floor(g[0]))
    j = int(wp.floor(g[1]))
    k = int(wp.floor(g[2]))
    if i >= c.sdf_shape[0] - 1 or j >= c.sdf_shape[1] - 1 or k >= c.sdf_shape[2] - 1:
        return 1.0e6
    fx = g[0] - float(i)
    fy = g[1] - float(j)
    fz = g[2] - float(k)
    sy = c.sdf_shape[2]
    sx = c.sdf_shape[1] * sy
    o = c.sdf_offset + i * sx + j * sy + k
    c00 = wp.lerp(sdf[o], sdf[o + sx], fx)
    c10 = wp.lerp(sdf[o + sy], sdf[o + sx + sy], fx)
    c01 = wp.lerp(sdf[o + 1], sdf[o + sx + 1], fx)
    c11 = wp.lerp(sdf[o + sy + 1], sdf[o + sx + sy + 1], fx)
    return wp.lerp(wp.lerp(c00, c10, fy), wp.lerp(c01, c11, fy), fz)


@wp.func
def collider_phi(c: ColliderParams, sdf: wp.array(dtype=float), xl: wp.vec3) -> float:
    """Signed distance (domain units, < 0 inside) at local position xl."""
    if c.kind == 0:
        return wp.dot(xl - c.point, c.normal)
    if c.kind == 1:
        q = wp.vec3(wp.abs(xl[0]), wp.abs(xl[1]), wp.abs(xl[2])) - c.half_extents
        outside = wp.length(wp.vec3(wp.max(q[0], 0.0), wp.max(q[1], 0.0), wp.max(q[2], 0.0)))
        return outside + wp.min(wp.max(q[0], wp.max(q[1], q[2])), 0.0)
    if c.kind == 2:
        return wp.length(xl) - c.radius
    return sample_sdf(c, sdf, xl)


@wp.func
def apply_collider(c: ColliderParams, sdf: wp.array(dtype=float), xn: wp.vec3, v: wp.vec3, h: float) -> wp.vec3:
    """Grid-node velocity after contact with collider c. xn: node position, domain units;
    h: finite-difference step for the normal, domain units."""
    xl = wp.quat_rotate_inv(c.rot, xn - c.pos)
    phi = collider_phi(c, sdf, xl)
    if phi > 0.0:  # a node on the surface is held too, so material rests on the surface
        return v
    gl = wp.vec3(
        collider_phi(c, sdf, xl + wp.vec3(h, 0.0, 0.0)) - collider_phi(c, sdf, xl - wp.vec3(h, 0.0, 0.0)),
        collider_phi(c, sdf, xl + wp.vec3(0.0, h, 0.0)) - collider_phi(c, sdf, xl - wp.vec3(0.0, h, 0.0)),
        collider_phi(c, sdf, xl + wp.vec3(0.0, 0.0, h)) - collider_phi(c, sdf, xl - wp.vec3(0.0, 0.0, h)),
    )
    if c.kind == 0:
        gl = c.normal
    if wp.length(gl) < 1.0e-12:
        return v
    n = wp.quat_rotate(c.rot, wp.normalize(gl))
    v_col = c.lin_vel + wp.cross(c.ang_vel, xn - c.pos)
    v_rel = v - v_col
    vn = wp.dot(v_rel, n)
    if vn >= 0.0:
        return v  # separating
    vt = v_rel - vn * n
    vt_len = wp.length(vt)
    if vt_len > 0.0:
        vt = vt * wp.max(0.0, 1.0 + c.friction * vn / vt_len)  # Coulomb: lose mu*|vn|
    return v_col + vt
