"""Bit words of a block for the CPU topology passes (:mod:`mpmfx.surface.flood`,
:mod:`mpmfx.surface.components`).

A block's 512 voxels are 8 words of 64 bits, word x (the local x index) holding bit y * 8 + z:
`sign` (phi > 0) and `reached`. A thread takes one block, lets its reached voxels spread to
6-neighbours of the same sign inside the block until nothing changes (a few dozen word
operations per step instead of a voxel at a time), after first taking in the reached voxels
of the face neighbours in active blocks.
"""

import warp as wp

from mpmfx.surface.voxels import BS, TILE_INSIDE, TILE_OUTSIDE

vec8u = wp.types.vector(length=8, dtype=wp.uint64)

ALL = wp.constant(wp.uint64(0xFFFFFFFFFFFFFFFF))

Z_LOW = wp.constant(wp.uint64(0x7F7F7F7F7F7F7F7F))  # bit z of each y group, z = 0..6 (z + 1 in the group)

Z_FIRST = wp.constant(wp.uint64(0x0101010101010101))  # z = 0 of each y group

Y_LOW = wp.constant(wp.uint64(0x00FFFFFFFFFFFFFF))  # y groups 0..6

BYTE = wp.constant(wp.uint64(0xFF))


@wp.func
def bit(q: int):
    return wp.uint64(1) << wp.uint64(q)


@wp.func
def face_mask(axis: int, side: int):
    """Bits of a word on the block face `axis` (1: y, 2: z) at side 0 (low) or 1 (high)."""
    m = wp.uint64(0)
    if axis == 1:
        m = BYTE << wp.uint64(56 * side)
    else:
        m = Z_FIRST << wp.uint64(7 * side)
    return m


@wp.func
def tile_face(code: int, axis: int, side: int):
    """face_mask(axis, side) where `code` is a tile, else 0."""
    m = wp.uint64(0)
    if code < 0:
        m = face_mask(axis, side)
    return m


@wp.func
def by_tile(code: int, face: wp.uint64, out_face: wp.uint64, inside_face: wp.uint64):
    """(out_face, inside_face) with `face` added to the one of tile `code` (none if active)."""
    if code == TILE_OUTSIDE:
        return out_face | face, inside_face
    if code == TILE_INSIDE:
        return out_face, inside_face | face
    return out_face, inside_face


@wp.func
def spread(s: vec8u, r: vec8u):
    """r grown to its fixpoint inside one block: each set bit spreads to the 6-neighbours of
    the same sign (s) within the block's 8 words."""
    grow = int(1)
    while grow != 0:
        grow = int(0)
        for x in range(BS):  # along z and y inside each word
            ez = (~(s[x] ^ (s[x] >> wp.uint64(1)))) & Z_LOW  # bit q: voxels q and q + 1 (z) share a sign
            ey = (~(s[x] ^ (s[x] >> wp.uint64(8)))) & Y_LOW  # voxels q and q + 8 (y)
            w = r[x]
            more = int(1)
            while more != 0:
                v = (
                    w
                    | ((w & ez) << wp.uint64(1))
                    | ((w >> wp.uint64(1)) & ez)
                    | ((w & ey) << wp.uint64(8))
                    | ((w >> wp.uint64(8)) & ey)
                )
                more = wp.where(v != w, 1, 0)
                w = v
            r[x] = w
        for x in range(BS - 1):  # along x, up then down
            ex = ~(s[x] ^ s[x + 1])
            v = r[x + 1] | (r[x] & ex)
            if v != r[x + 1]:
                r[x + 1] = v
                grow = int(1)
        for k in range(BS - 1):
            x = BS - 2 - k
            ex = ~(s[x] ^ s[x + 1])
            v = r[x] | (r[x + 1] & ex)
            if v != r[x]:
                r[x] = v
                grow = int(1)
    return r


@wp.func
def large_piece(s: vec8u, marked: int, min_count: int):
    """Whether a block's inside voxels (the bits clear in its sign words s) are one piece within
    the block (6-connected) holding at least min_count particles' voxels (marked of them): its
    component then holds at least min_count particles (count_component_particles counts a
    particle at its nearest voxel, as the marks are set), so it is not small."""
    if marked < min_count:
        return False
    x0 = int(0)
    while x0 < BS - 1 and s[x0] == ALL:
        x0 += 1
    inside = ~s[x0]
    first = vec8u(wp.uint64(0))
    first[x0] = inside & (~inside + wp.uint64(1))  # the block's first inside voxel
    r = spread(s, first)
    for x in range(BS):
        if r[x] != ~s[x]:
            return False
    return True


@wp.func
def take_face(own: wp.uint64, own_sign: wp.uint64, nr: wp.uint64, ns: wp.uint64, face: wp.uint64):
    """own with the face bits whose neighbour across the face (nr, ns: its reached and sign
    bits moved onto own's face positions) is reached and of the same sign."""
    return own | (nr & (~(ns ^ own_sign)) & face)
