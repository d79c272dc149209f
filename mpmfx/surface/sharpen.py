"""Sharpening pass (SurfaceParams.sharp_edges): a smoothed level set given back its sharp convex
edges and corners (the same kernels on every device).

A random sample thins where a body's faces meet (a quarter or an eighth of a ball of neighbours),
so the field rounds and dents an edge, and the flow rounds it further: on the 100k random box,
vertices within 2 h of an edge averaged 0.18-0.20 h off, the faces 0.10, and the worst vertex,
always at an edge or a corner, passed 1 h on some samples. Extended marching cubes and dual
contouring keep such edges by meshing where the faces' tangent planes meet; here the planes are
fitted on the smoothed field and the field is set to the planes' intersection (the largest of
their signed distances, a convex wedge or corner, rounded within 2 voxels of the crest) before
marching cubes, which then needs no change.

Only where the edge gate is open (edges.edge_gate: the blurred weights curve like an
edge), only outward (material is added at a convex crest, never removed), and only where the
planes found around a cell support each other (every plane's points lie under the others'), at
least two (three at a corner) and not back to back (a sheet's rim). Planes come from pairs of
points on the zero level, 2.5 and 5.5 spacings out from the cell along the surface, kept only
where the surface is flat there: both points' normals, and the normals 1.5 spacings to each side
of each, agree within 12 degrees, and a plane needs 3 of a cell's 16 directions. A round body is
flat nowhere over those spans (a torus whose tube is 5 spacings across, blobs of 300 particles:
not a vertex moved; random spheres and tori of 20k-100k: at most 0.07 % of vertices, by at most
0.01 h), where
shorter spans (4 spacings, 1 to the sides) found "faces" around such a tube and moved 73 % of
its vertices by up to 1.2 h. Each cell decides (decide_cells), then sharpens as far as the
decisions around it agree (sharpen_cells, sharpen_weight): a narrow face's votes come and go
along its edge, and all-or-nothing cells left ledges there. Lengths are voxels; a cell is 2^3
voxels (voxels.gate_cell), voxel (i, j, k)'s value sits at the point (i, j, k).

On a moving body marching cubes cuts a sharp crest differently as it crosses voxel planes (the
crest is rounded within 2 voxels: unrounded, the gliding block's edges' shading turned 52 degrees
p99 between frames, rounded 28), and a face's plane, fitted afresh every frame, turns a little:
each plane's normal is a mean over many directions' normals (DIRECTIONS), and the sharpening is
blended by the gates interpolated to each voxel (gate_at). Rendered, the gliding 20k block then
changes as little from frame to frame as without sharp edges (mpmfx.bench.surface_flicker)."""

import math

import warp as wp

from mpmfx.surface.launch import launch_split, scan, split
from mpmfx.surface.sharpen_planes import (
    CELL_PLANES,
    NEAR_PLANES,
    cell_at,
    cell_corner,
    cell_planes,
    flag_cells,
    merge_planes,
    plane_cell,
)
from mpmfx.surface.voxels import BS, slot

# forward only: nothing differentiates these kernels; their adjoint code would only lengthen the compile
wp.set_module_options({"enable_backward": False})

SHARP = {  # sharpen()'s settings; lengths in particle spacings h unless said
    "band": 3.0,  # voxels: cells whose centre lies this near the zero level
    "thin": 2.5,  # and where the body is thicker than this (a sheet is its faces back to back)
    "near": 2.5,
    "far": 5.5,  # a direction's two points: near out from the cell, then on along the surface to far
    "width": 1.5,  # the points to each side whose normals must agree too
    "cos_flat": math.cos(math.radians(12.0)),  # normals that agree
    "plane_tol": 0.5,  # each point this near the other's tangent plane
    "cos_same": math.cos(math.radians(15.0)),  # planes closer than this are one
    "votes": 3.0,  # directions that must find a plane (of DIRECTIONS, 16; at 2, a spot of a 20k random torus passed)
    "support": 0.3,  # voxels: a plane's points this far over another's at most (convex)
    "cos_apart": math.cos(math.radians(65.0)),  # at least two planes this far apart (an edge, not a face)
    "cos_open": math.cos(math.radians(120.0)),  # and none further (faces back to back: a sheet's rim)
    "limit": 1.5,  # the most the field moves outward
    "rounding": 2.0,  # voxels: the crest's radius (0 flickered twice as much on a moving box, 3 gave back a third of the gain)
    # cells on each side whose decisions weigh a cell's sharpening (sharpen_weight): at
    # 0 each cell sharpened all or nothing, and where a narrow face's votes hovered about `votes`
    # along an edge it stopped and started in ledges up to 1.3 h high (water_dam's splash frame)
    "spread": 2,
}

# cells on each side whose planes a cell takes (planes are looked for in every other cell): at 2 a
# cell near a corner missed its third face, and cells along an edge dropped out frame to frame
# where the few planes within reach failed (100k random box "fine", 12 seeds: corners 0.24 h;
# the moving block's vertices p99 0.19 h off the previous frame); at 6, 0.16 h and 0.08 h
REACH = wp.constant(6)
# a cell's decision (decide_cells): its planes meet at an edge or corner to sharpen; they do not
# (too few, not apart, not convex, back to back); or the edge ends here (a corner without its
# third face, an edge past its last cell)
SHARPEN = wp.constant(1)
NOT_EDGE = wp.constant(0)
EDGE_END = wp.constant(-1)


@wp.func
def even_step(c: int, n: int):
    """The n-th of the REACH + 1 offsets from cell coordinate c, from -REACH up, to a coordinate
    that is even (the cells that look for planes; the last one passes REACH where c is odd)."""
    return -REACH + (c + REACH) % 2 + 2 * n


@wp.func
def gate_at(bmap: wp.array3d(dtype=wp.int32), gate: wp.array(dtype=float), x: wp.vec3i):
    """The cells' gates interpolated trilinearly to voxel x (a cell's value sits at its centre):
    one gate for all of a cell's voxels stepped the sharpened field at the cells' faces, and a
    moving body's surface rippled along its edges (the gliding block, rendered white at 800 x
    600: its pixels changed 1.50 levels a frame on average, 1.42 interpolated; 1.32 without
    sharp edges)."""
    fx = (float(x[0]) - 0.5) * 0.5
    fy = (float(x[1]) - 0.5) * 0.5
    fz = (float(x[2]) - 0.5) * 0.5
    i = int(wp.floor(fx))
    j = int(wp.floor(fy))
    k = int(wp.floor(fz))
    tx = fx - float(i)
    ty = fy - float(j)
    tz = fz - float(k)
    g = float(0.0)
    for q in range(8):
        a = q // 4
        b = (q // 2) % 2
        c = q % 2
        w = wp.where(a == 1, tx, 1.0 - tx) * wp.where(b == 1, ty, 1.0 - ty) * wp.where(c == 1, tz, 1.0 - tz)
        v = cell_at(bmap, 2 * (i + a), 2 * (j + b), 2 * (k + c))
        if v >= 0:
            g += w * gate[v]
    return g


@wp.func
def edge_both_sides(
    bmap: wp.array3d(dtype=wp.int32),
    flags: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    e: wp.vec3i,
    pn: wp.array(dtype=wp.vec3),
    pw: wp.array(dtype=float),
    qn: wp.array(dtype=wp.vec3),
    qw: wp.array(dtype=float),
    s: int,
    votes: float,
    cos_same: float,
):
    """Whether cells that saw the two kept planes (qn, qw of thread s) lie on both sides of the
    cell at even voxel e along their edge (a voxel or more each way): past the end of an edge,
    where no cell saw the third face, they lie on one side and level with it only."""
    na = wp.vec3(0.0)
    nb = wp.vec3(0.0)
    for c in range(NEAR_PLANES):
        o = s * NEAR_PLANES + c
        if qw[o] >= votes:
            if wp.length_sq(na) == 0.0:
                na = wp.normalize(qn[o])
            else:
                nb = wp.normalize(qn[o])
    t = wp.normalize(wp.cross(na, nb))
    lo = float(1.0e30)
    hi = float(-1.0e30)
    # nested loops over the cells that look for planes (one loop over all 7^3 offsets, each
    # decoded by division, made the boxes' calls 8-11 ms longer on the CPU at 100k)
    for ii in range(REACH + 1):
        di = even_step(e[0] // 2, ii)
        for jj in range(REACH + 1):
            dj = even_step(e[1] // 2, jj)
            for kk in range(REACH + 1):
                dk = even_step(e[2] // 2, kk)
                if di > REACH or dj > REACH or dk > REACH:
                    continue
                v = plane_cell(bmap, flags, slots, e, di, dj, dk)
                if v < 0:
                    continue
                for m in range(CELL_PLANES):
                    i = v * CELL_PLANES + m
                    if pw[i] > 0.0:
                        nk = wp.normalize(pn[i])
                        if wp.dot(nk, na) > cos_same or wp.dot(nk, nb) > cos_same:
                            d = wp.dot(wp.vec3(float(2 * di), float(2 * dj), float(2 * dk)), t)
                            lo = wp.min(lo, d)
                            hi = wp.max(hi, d)
    return lo <= -1.0 and hi >= 1.0


@wp.kernel
def decide_cells(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    sample: wp.array(dtype=float),
    flags: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    cells: wp.array(dtype=wp.int32),
    pn: wp.array(dtype=wp.vec3),
    pp: wp.array(dtype=wp.vec3),
    pw: wp.array(dtype=float),
    cos_same: float,
    votes: float,
    support: float,
    cos_apart: float,
    cos_open: float,
    qn: wp.array(dtype=wp.vec3),
    qp: wp.array(dtype=wp.vec3),
    qw: wp.array(dtype=float),
    state: wp.array(dtype=wp.int32),
    base: int,
):
    """Flagged cell cells[s]: the planes found by the cells within REACH cells merged into at
    most NEAR_PLANES (qn, qp, qw: the cell's, kept for sharpen_cells), those found `votes` times
    or more kept, and state[s] the cell's decision. SHARPEN where at least two are kept (three
    where edge_gate saw a corner), apart by more than cos_apart somewhere and nowhere by more
    than cos_open (faces nearly back to back are a sheet's rim: their intersection would run
    the sheet on past it), every kept plane's mean point lies under every other kept plane
    (within `support`: a convex edge or corner), and, for two, cells that saw them lie on both
    sides along their edge (edge_both_sides); EDGE_END where only those last two tests fail (a
    corner without its third face, an edge past its end); else NOT_EDGE."""
    s = wp.tid() + base
    u = cells[s]
    state[s] = NOT_EDGE
    for m in range(NEAR_PLANES):
        qn[s * NEAR_PLANES + m] = wp.vec3(0.0)
        qp[s * NEAR_PLANES + m] = wp.vec3(0.0)
        qw[s * NEAR_PLANES + m] = 0.0
    e = cell_corner(bcoord, u)  # even voxel: its cell's coordinates are e / 2
    if (e[0] // 2) % 2 != 0 or (e[1] // 2) % 2 != 0 or (e[2] // 2) % 2 != 0:
        v = plane_cell(bmap, flags, slots, e, 0, 0, 0)  # its own planes, where a corner looked for them
        if v >= 0:
            merge_planes(v, s, pn, pp, pw, qn, qp, qw, cos_same)
    for ii in range(REACH + 1):  # as in edge_both_sides
        di = even_step(e[0] // 2, ii)
        for jj in range(REACH + 1):
            dj = even_step(e[1] // 2, jj)
            for kk in range(REACH + 1):
                dk = even_step(e[2] // 2, kk)
                if di > REACH or dj > REACH or dk > REACH:
                    continue
                v = plane_cell(bmap, flags, slots, e, di, dj, dk)
                if v >= 0:
                    merge_planes(v, s, pn, pp, pw, qn, qp, qw, cos_same)
    kept = int(0)
    apart = bool(False)
    for c in range(NEAR_PLANES):
        o = s * NEAR_PLANES + c
        if qw[o] < votes:
            continue
        kept += 1
        nc = wp.normalize(qn[o])
        for c2 in range(NEAR_PLANES):
            o2 = s * NEAR_PLANES + c2
            if c2 == c or qw[o2] < votes:
                continue
            if wp.dot(nc, qp[o2] / qw[o2] - qp[o] / qw[o]) > support:
                return  # not convex here
            turn = wp.dot(nc, wp.normalize(qn[o2]))
            if turn < cos_open:
                return  # faces nearly back to back: a sheet's rim or a blade, not an edge to extend
            if turn < cos_apart:
                apart = True
    if kept < 2 or not apart:
        return
    if kept < 3 and sample[u] < 0.0:
        state[s] = (
            EDGE_END  # a corner (edge_gate's sample < 0) needs its three faces: two would run its edge on past it
        )
        return
    if kept == 2 and not edge_both_sides(bmap, flags, slots, e, pn, pw, qn, qw, s, votes, cos_same):
        state[s] = EDGE_END  # the end of an edge, where no cell saw the third face: two planes would run it on
        return
    state[s] = SHARPEN


@wp.func
def sharpen_weight(
    bmap: wp.array3d(dtype=wp.int32),
    flags: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    state: wp.array(dtype=wp.int32),
    e: wp.vec3i,
    spread: int,
):
    """How fully the cell at even voxel e sharpens: 2 x the share of SHARPEN among the decided
    cells within `spread` cells on each axis (EDGE_END ones left out), less 1, in 0 .. 1 (1 at
    spread 0)."""
    n = int(0)
    yes = int(0)
    for di in range(-spread, spread + 1):
        for dj in range(-spread, spread + 1):
            for dk in range(-spread, spread + 1):
                v = cell_at(bmap, e[0] + 2 * di, e[1] + 2 * dj, e[2] + 2 * dk)
                if v >= 0 and flags[v] != 0:
                    st = state[slots[v]]
                    if st != EDGE_END:
                        n += 1
                        yes += wp.where(st == SHARPEN, 1, 0)
    return wp.clamp(2.0 * float(yes) / float(n) - 1.0, 0.0, 1.0)


# a Warp module of its own: the two kernels' modules compile side by side (decide_cells' alone was
# the surfacer's longest compile)
@wp.kernel(enable_backward=False, module=__name__ + "_cells")
def sharpen_cells(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    gate: wp.array(dtype=float),
    flags: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    cells: wp.array(dtype=wp.int32),
    state: wp.array(dtype=wp.int32),
    votes: float,
    limit: float,
    rounding: float,
    spread: int,
    qn: wp.array(dtype=wp.vec3),
    qp: wp.array(dtype=wp.vec3),
    qw: wp.array(dtype=float),
    base: int,
):
    """Each cell that decide_cells passed (SHARPEN; its kept planes in qn, qp, qw): each of its
    voxels takes the planes' intersection's signed distance (the largest of theirs, rounded
    within `rounding` of the crest: marching cubes cuts a crest sharper than a voxel or two
    differently wherever it falls between voxel planes, and a moving body's edges then flicker)
    where that is lower (outward), by at most `limit`, blended by the gates interpolated to
    each voxel (gate_at) and by sharpen_weight over `spread` cells. Writes only the cell's own
    voxels and reads no other value of phi: it runs in place."""
    s = wp.tid() + base
    if state[s] != SHARPEN:
        return
    e = cell_corner(bcoord, cells[s])
    weight = sharpen_weight(bmap, flags, slots, state, e, spread)
    if weight == 0.0:
        return
    t0 = slot(bmap, e[0], e[1], e[2])
    for q in range(8):
        x = wp.vec3(e + wp.vec3i(q // 4, (q // 2) % 2, q % 2))
        fs = float(-1.0e30)
        usq = float(0.0)
        for c in range(NEAR_PLANES):
            o = s * NEAR_PLANES + c
            if qw[o] >= votes:
                pl = wp.dot(wp.normalize(qn[o]), x - qp[o] / qw[o])
                fs = wp.max(fs, pl)
                uu = wp.max(pl + rounding, 0.0)
                usq += uu * uu
        if usq > 0.0:  # near the crest: the planes' intersection rounded by `rounding`
            fs = wp.sqrt(usq) - rounding
        t = t0 + ((q // 4) * BS + (q // 2) % 2) * BS + q % 2
        g = gate_at(bmap, gate, e + wp.vec3i(q // 4, (q // 2) % 2, q % 2))
        f = phi[t]
        target = wp.max(wp.min(f, fs), f - limit)
        phi[t] = f + weight * g * (target - f)


def sharpen(bcoord, bmap, phi, tiles, gate, sample, h: float) -> None:
    """Convex edges and corners of the smoothed field `phi` made sharp again, in place
    (SHARP's settings; gate, sample: mpmfx.surface.edges'; h: the particle
    spacing in voxels). The cells whose edge gate is open and that lie near the zero level are
    numbered (a scan); every other one of them on each axis, and every corner, finds the faces
    around it; each takes its neighbours' faces' intersection where they form a convex edge or
    corner. A body with no open gate costs a launch over its cells and one host read."""
    ncell = gate.shape[0]
    if ncell == 0:
        return
    c = SHARP
    flags = wp.empty(ncell, dtype=wp.int32)
    split(wp, flag_cells, ncell, [bcoord, bmap, phi, *tiles, gate, c["band"], c["thin"] * h, flags])
    slots = scan(wp, flags, inclusive=False)
    count = int(slots[ncell - 1 : ncell].numpy()[0] + flags[ncell - 1 : ncell].numpy()[0])
    if count == 0:
        return
    cells = wp.empty(count, dtype=wp.int32)
    pn, pp = wp.empty(count * CELL_PLANES, dtype=wp.vec3), wp.empty(count * CELL_PLANES, dtype=wp.vec3)
    pw = wp.empty(count * CELL_PLANES, dtype=float)
    split(
        wp,
        cell_planes,
        ncell,
        [
            bcoord,
            bmap,
            phi,
            *tiles,
            sample,
            flags,
            slots,
            c["near"] * h,
            c["far"] * h,
            c["width"] * h,
            c["cos_flat"],
            c["plane_tol"] * h,
            c["cos_same"],
            cells,
            pn,
            pp,
            pw,
        ],
    )
    qn, qp = wp.empty(count * NEAR_PLANES, dtype=wp.vec3), wp.empty(count * NEAR_PLANES, dtype=wp.vec3)
    qw = wp.empty(count * NEAR_PLANES, dtype=float)
    state = wp.empty(count, dtype=wp.int32)
    launch_split(
        wp,
        decide_cells,
        count,
        [
            bcoord,
            bmap,
            sample,
            flags,
            slots,
            cells,
            pn,
            pp,
            pw,
            c["cos_same"],
            c["votes"],
            c["support"],
            c["cos_apart"],
            c["cos_open"],
            qn,
            qp,
            qw,
            state,
        ],
        device=phi.device,
        min_split=256,
    )  # a few hundred cells already: each thread does much
    launch_split(
        wp,
        sharpen_cells,
        count,
        [
            bcoord,
            bmap,
            phi,
            gate,
            flags,
            slots,
            cells,
            state,
            c["votes"],
            c["limit"] * h,
            c["rounding"],
            c["spread"],
            qn,
            qp,
            qw,
        ],
        device=phi.device,
        min_split=256,
    )  # a few hundred cells already: each thread does much
