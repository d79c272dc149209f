"""Phase 3 — grid update: v = mv / m, gravity, damping, colliders, walls (docs/physics.md, "Boundaries").

This is the only place two pieces of material influence each other, and where all
contact happens. One thread per node; nodes sit at i * dx, i = 0..grid_n.

Multi-field contact (opt-in: with one field, two separate bodies fuse on contact): each body
has its own velocity field (its own block of nodes, first grid axis = field * nodes + i).
Where several fields meet at a node, a field moving toward the others along its outward
normal (minus its mass gradient) gets that normal velocity replaced by the node's
centre-of-mass one; its tangential slip keeps all but Coulomb friction (Bardenhagen et al.
2000). Fields separating from each other pass freely, so bodies part instead of fusing.
"""

from __future__ import annotations

import functools

import warp as wp

from .animated import MeshColliders, make_mesh_contact
from .bricks import BRICK, marked_node
from .clear_grid import zero_node
from .colliders import ColliderParams, apply_collider
from .slots import Count, WallCode
from .stepper import SubstepDev


@wp.struct
class GridParams:
    """Per-substep grid-update parameters.

    dt: s; dx: domain units; gravity: domain/s^2; damping_factor: 1 - damping*dt (>= 0);
    walls_lo / walls_hi: wall codes of the -x,-y,-z / +x,+y,+z faces; wall_friction: mu;
    wall_layer: domain units, the layer over which a wall's friction acts (0: the nodes at the
    wall only; SolverConfig.wall_layer);
    plane_lo / plane_hi: the walls' planes on every axis, domain units (SolverConfig.wall_planes);
    deterministic: 1 when
    P2G accumulated in fixed point; q_mass / q_mom: fixed-point quanta (mass, momentum);
    num_colliders: entries used in the collider array; nodes: grid_n + 1; n_fields: velocity
    fields (1 unless multi-field); contact_friction: Coulomb mu between fields.
    """

    dt: float
    dx: float
    gravity: wp.vec3
    damping_factor: float
    walls_lo: wp.vec3i
    walls_hi: wp.vec3i
    wall_friction: float
    wall_layer: float
    plane_lo: float
    plane_hi: float
    deterministic: int
    q_mass: float
    q_mom: float
    num_colliders: int
    nodes: int
    n_fields: int
    contact_friction: float


@wp.func
def apply_wall(v: wp.vec3, n_out: wp.vec3, wall: int, mu: float) -> wp.vec3:
    """Wall boundary on one face. n_out: outward face normal. Coulomb friction removes
    mu * |vn| of tangential speed, where vn is the normal speed stopped by the wall."""
    if wall == WallCode.STICKY:
        return wp.vec3(0.0)
    vn = wp.dot(v, n_out)  # > 0: moving into the wall
    if wall == WallCode.SEPARATE and vn <= 0.0:
        return v
    vt = v - vn * n_out
    if vn > 0.0:
        vt_len = wp.length(vt)
        if vt_len > 0.0:
            vt = vt * wp.max(0.0, 1.0 - mu * vn / vt_len)
    return vt


@wp.func
def apply_walls(v: wp.vec3, xn: wp.vec3, gp: GridParams, mu: float) -> wp.vec3:
    """The walls at a node at xn (domain units), friction mu at the node itself. A node on a
    wall's plane or beyond it gets the wall's condition: the last node held is the one on the
    plane, so material rests on the plane itself (the nodes beyond it are the guard that keeps
    the stencil on the grid). The half cell only absorbs rounding: the planes lie on nodes."""
    out = v
    reach = 0.5 * gp.dx
    for a in range(3):
        n_out = wp.vec3(0.0)
        if xn[a] < gp.plane_lo + reach:
            n_out[a] = -1.0
            out = apply_wall(out, n_out, gp.walls_lo[a], mu)
        if xn[a] > gp.plane_hi - reach:
            n_out[a] = 1.0
            out = apply_wall(out, n_out, gp.walls_hi[a], mu)
    return out


@wp.func
def node_velocity(
    gp: GridParams,
    grid_m: wp.array3d(dtype=float),
    grid_mv: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
    i: int,
    j: int,
    k: int,
):
    """(mass, velocity after gravity and damping) of one node of one field; v = 0 if empty."""
    m = float(0.0)
    mv = wp.vec3(0.0)
    if gp.deterministic != 0:
        m = float(grid_fixed[i, j, k, 0]) * gp.q_mass
        mv = (
            wp.vec3(float(grid_fixed[i, j, k, 1]), float(grid_fixed[i, j, k, 2]), float(grid_fixed[i, j, k, 3]))
            * gp.q_mom
        )
    else:
        m = grid_m[i, j, k]
        mv = grid_mv[i, j, k]
    v = wp.vec3(0.0)
    if m > 0.0:
        v = mv / m  # grid_mv held momentum until here
        v = (v + gp.dt * gp.gravity) * gp.damping_factor
    return m, v


@wp.func
def layer_friction(
    gp: GridParams,
    grid_m: wp.array3d(dtype=float),
    grid_mv: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
    v: wp.vec3,
    fo: int,
    i: int,
    j: int,
    k: int,
) -> wp.vec3:
    """The walls' Coulomb friction shared over their boundary layers (gp.wall_layer > 0), at node
    (i, j, k) of the field whose block starts at fo on the first axis; v: its velocity.

    Per wall and per column of nodes across it: the normal impulse J = sum m vn (> 0: into the
    wall) of the column's nodes on the plane or beyond it, and mu J taken off the tangential
    momentum of the column's nodes within wall_layer of the plane, each node's share weighted
    by w = 1 - d / wall_layer (d: its distance from the plane, 0 at the wall): a node's
    tangential speed is scaled by max(0, 1 - w mu J / sum w m |vt|). Unsaturated, the column
    loses mu J of tangential momentum on any grid; the sums read every node of the column
    (before the walls), so all of them agree on it without atomics."""
    xn = wp.vec3(float(i), float(j), float(k)) * gp.dx
    reach = 0.5 * gp.dx
    out = v
    for a in range(3):
        for side in range(2):
            wall = gp.walls_lo[a]
            plane = gp.plane_lo
            sgn = float(-1.0)
            if side == 1:
                wall = gp.walls_hi[a]
                plane = gp.plane_hi
                sgn = 1.0
            d = sgn * (plane - xn[a])  # distance from the plane into the domain (< 0: beyond it)
            if wall == WallCode.STICKY or d >= gp.wall_layer:
                continue
            n_out = wp.vec3(0.0)
            n_out[a] = sgn
            jn = float(0.0)
            share = float(0.0)
            c = int(0)
            if side == 1:
                c = gp.nodes - 1
            # walk the column from the domain face inward, through the guard, the plane and the layer
            while c >= 0 and c < gp.nodes:
                dc = sgn * (plane - float(c) * gp.dx)
                if dc >= gp.wall_layer:
                    break
                at = wp.vec3i(i, j, k)
                at[a] = c
                m, vc = node_velocity(gp, grid_m, grid_mv, grid_fixed, fo + at[0], at[1], at[2])
                if m > 0.0:
                    vn = wp.dot(vc, n_out)
                    if dc < reach and vn > 0.0:
                        jn += m * vn
                    share += (1.0 - wp.max(dc, 0.0) / gp.wall_layer) * m * wp.length(vc - vn * n_out)
                c -= int(sgn)
            if jn > 0.0 and share > 0.0:
                w = 1.0 - wp.max(d, 0.0) / gp.wall_layer
                vn_self = wp.dot(out, n_out)
                out = vn_self * n_out + (out - vn_self * n_out) * wp.max(0.0, 1.0 - w * gp.wall_friction * jn / share)
    return out


@wp.func
def mass_gradient(
    gp: GridParams,
    grid_normal: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
    i: int,
    j: int,
    k: int,
) -> wp.vec3:
    """Mass gradient of one field at a node (any consistent scale; only its direction is used)."""
    if gp.deterministic != 0:
        return wp.vec3(float(grid_fixed[i, j, k, 4]), float(grid_fixed[i, j, k, 5]), float(grid_fixed[i, j, k, 6]))
    return grid_normal[i, j, k]


@wp.func
def field_contact(v: wp.vec3, v_cm: wp.vec3, normal_in: wp.vec3, mu: float) -> wp.vec3:
    """Multi-field contact: normal_in is the field's mass gradient (points into its body)."""
    ln = wp.length(normal_in)
    if ln < 1.0e-20:
        return v
    n = -normal_in / ln  # outward normal of this body
    dv = v - v_cm
    dn = wp.dot(dv, n)
    if dn <= 0.0:
        return v  # separating or sliding: no contact force
    dvt = dv - dn * n
    lt = wp.length(dvt)
    if lt > 0.0:
        dvt = dvt * wp.max(0.0, 1.0 - mu * dn / lt)
    return v_cm + dvt


@wp.func
def boundaries(
    gp: GridParams,
    colliders: wp.array(dtype=ColliderParams),
    sdf: wp.array(dtype=float),
    counts: wp.array(dtype=wp.int32),
    grid_m: wp.array3d(dtype=float),
    grid_mv: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
    v: wp.vec3,
    fo: int,
    i: int,
    j: int,
    k: int,
) -> wp.vec3:
    """A node's velocity after the colliders and the walls (zero, and counted, if not finite).
    fo: the first-axis offset of the node's field block (layer_friction)."""
    xn = wp.vec3(float(i), float(j), float(k)) * gp.dx
    for c in range(gp.num_colliders):
        v = apply_collider(colliders[c], sdf, xn, v, 0.5 * gp.dx)
    if gp.wall_layer > 0.0 and gp.wall_friction > 0.0:
        v = layer_friction(gp, grid_m, grid_mv, grid_fixed, v, fo, i, j, k)
        v = apply_walls(v, xn, gp, 0.0)  # the walls' normal condition; their friction is the layer's
    else:
        v = apply_walls(v, xn, gp, gp.wall_friction)
    if not wp.isfinite(v):
        wp.atomic_add(counts, Count.GRID_NONFINITE, 1)
        v = wp.vec3(0.0)  # the substep is rejected anyway; keep G2P finite
    return v


@wp.func
def update_node(
    gp: GridParams,
    grid_m: wp.array3d(dtype=float),
    grid_mv: wp.array3d(dtype=wp.vec3),
    grid_normal: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
    colliders: wp.array(dtype=ColliderParams),
    sdf: wp.array(dtype=float),
    grid_v: wp.array3d(dtype=wp.vec3),
    counts: wp.array(dtype=wp.int32),
    i: int,
    j: int,
    k: int,
):
    """Node (i, j, k) of every field: velocity from momentum, gravity, damping, field contact,
    colliders, walls."""
    m_tot = float(0.0)
    p_tot = wp.vec3(0.0)
    grad_tot = wp.vec3(0.0)
    if gp.n_fields > 1:
        for f in range(gp.n_fields):
            m, v = node_velocity(gp, grid_m, grid_mv, grid_fixed, f * gp.nodes + i, j, k)
            m_tot += m
            p_tot += m * v
            grad_tot += mass_gradient(gp, grid_normal, grid_fixed, f * gp.nodes + i, j, k)
    for f in range(gp.n_fields):
        fi = f * gp.nodes + i
        m, v = node_velocity(gp, grid_m, grid_mv, grid_fixed, fi, j, k)
        if m > 0.0:
            if m < m_tot * (1.0 - 1.0e-6):  # another field shares this node
                g = mass_gradient(gp, grid_normal, grid_fixed, fi, j, k)
                # own gradient minus the others': for two fields the normals are exactly
                # opposite, so the contact impulses cancel and momentum is conserved
                v = field_contact(v, p_tot / m_tot, 2.0 * g - grad_tot, gp.contact_friction)
            v = boundaries(gp, colliders, sdf, counts, grid_m, grid_mv, grid_fixed, v, f * gp.nodes, i, j, k)
        grid_v[fi, j, k] = v


@functools.lru_cache(maxsize=None)
def make_mesh_boundaries(inside_test: str):
    """wp.func (gp, mc, v, i, j, k) -> v: a node's velocity after the animated meshes (their
    side decided by `inside_test`, animated.INSIDE_TESTS), then the walls again (each wall is a
    projection, so a node no mesh touched keeps what `boundaries` gave it)."""
    contact = make_mesh_contact(inside_test)

    @wp.func
    def mesh_boundaries(gp: GridParams, mc: MeshColliders, v: wp.vec3, i: int, j: int, k: int) -> wp.vec3:
        xn = wp.vec3(float(i), float(j), float(k)) * gp.dx
        v = wp.static(contact)(mc, xn, v, gp.dx)
        mu = gp.wall_friction
        if gp.wall_layer > 0.0:
            mu = 0.0  # the layer's friction was applied once, in `boundaries`
        return apply_walls(v, xn, gp, mu)

    return mesh_boundaries


@functools.lru_cache(maxsize=None)
def make_grid_update(*, device_clock: bool = False, sparse: bool = False, clears: bool = False, meshes: str = ""):
    """The grid-update kernel; device_clock as in p2g.make_p2g. sparse: launched over the
    node bricks (BRICK^3 threads each, `marks` order), it updates only those `marks` flags
    (the brick P2G's, p2g_brick.py): G2P reads no other node, and the others' velocities are
    left as they were. Otherwise launched over the nodes (3D). clears (sparse only): each node's
    mass and momentum are zeroed once read, which is the next substep's clear (the same marked
    bricks), so that substep launches none; only where G2P reads no node mass (water volume
    recovery does). meshes: the scene's animated mesh colliders' inside test (animated.py
    INSIDE_TESTS), met after the rigid ones; "" without any, and `mesh_cols` is never read."""
    module = (
        ("mpmfx_mpm_grid_dev" if device_clock else __name__)
        + ("_sparse" if sparse else "")
        + ("_clears" if clears else "")
        + (f"_meshes_{meshes}" if meshes else "")
    )

    mesh_boundaries = make_mesh_boundaries(meshes) if meshes else None

    @wp.kernel(enable_backward=False, module=module)
    def grid_update(
        gp: GridParams,
        grid_m: wp.array3d(dtype=float),
        grid_mv: wp.array3d(dtype=wp.vec3),
        grid_normal: wp.array3d(dtype=wp.vec3),
        grid_fixed: wp.array4d(dtype=wp.int64),
        colliders: wp.array(dtype=ColliderParams),
        sdf: wp.array(dtype=float),
        grid_v: wp.array3d(dtype=wp.vec3),
        counts: wp.array(dtype=wp.int32),
        marks: wp.array(dtype=wp.int32),
        sub: wp.array(dtype=SubstepDev),
        mesh_cols: MeshColliders,
    ):
        if wp.static(device_clock):
            if sub[0].active == 0:
                return
            gp.dt = sub[0].dt
            gp.damping_factor = sub[0].damping_factor
        if wp.static(sparse):  # (one field: the brick P2G has no multi-field mode)
            node = marked_node(marks, wp.tid(), (gp.nodes + BRICK - 1) // BRICK, gp.nodes)
            if node[0] >= 0:
                m, v = node_velocity(gp, grid_m, grid_mv, grid_fixed, node[0], node[1], node[2])
                if m > 0.0:
                    v = boundaries(
                        gp, colliders, sdf, counts, grid_m, grid_mv, grid_fixed, v, 0, node[0], node[1], node[2]
                    )
                    if wp.static(bool(meshes)):
                        v = wp.static(mesh_boundaries)(gp, mesh_cols, v, node[0], node[1], node[2])
                grid_v[node[0], node[1], node[2]] = v
                if wp.static(clears):
                    zero_node(gp.deterministic, grid_m, grid_mv, grid_fixed, node[0], node[1], node[2])
        else:
            i, j, k = wp.tid()
            update_node(gp, grid_m, grid_mv, grid_normal, grid_fixed, colliders, sdf, grid_v, counts, i, j, k)
            if wp.static(bool(meshes)):
                for f in range(gp.n_fields):
                    fi = f * gp.nodes + i
                    m, _v = node_velocity(gp, grid_m, grid_mv, grid_fixed, fi, j, k)
                    if m > 0.0:
                        grid_v[fi, j, k] = wp.static(mesh_boundaries)(gp, mesh_cols, grid_v[fi, j, k], i, j, k)

    return grid_update


grid_update = make_grid_update()  # the reference kernel
