"""Small-components pass: inside components (6-connected) holding fewer than
SurfaceParams.min_feature_particles particles become outside.

GPU: min-label sweeps along block lines over every block. CPU: a fill from the bodies on bit
words first labels 0 the components that cannot be small, then min-label sweeps a block per
thread run only over the blocks holding other inside voxels.
"""

from __future__ import annotations

import warp as wp

from mpmfx.surface.bitwords import bit, large_piece, vec8u
from mpmfx.surface.flood import active_rounds, fill_bits
from mpmfx.surface.kernel_modules import cpu_kernel
from mpmfx.surface.launch import launch_split, split
from mpmfx.surface.voxels import BS, BV, LABEL_NONE, TILE_INSIDE, line_start, line_voxel, slot, voxel_of

# forward only: nothing differentiates these kernels, and their adjoints lengthen the compile of the unrolled loops
wp.set_module_options({"enable_backward": False})


@wp.kernel
def init_inside_labels(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    phi: wp.array(dtype=float),
    labels: wp.array(dtype=wp.int32),
    base: int,
):
    """Inside voxels: own label t + 1, or 0 when touching an INSIDE tile (a big body); else -1."""
    t = wp.tid() + base
    lab = LABEL_NONE
    if phi[t] <= 0.0:
        lab = t + 1
        c = voxel_of(t, bcoord)
        for n in range(6):
            o = wp.vec3i(0)
            o[n // 2] = 2 * (n % 2) - 1
            if slot(bmap, c[0] + o[0], c[1] + o[1], c[2] + o[2]) == TILE_INSIDE:
                lab = 0
    labels[t] = lab


@wp.func
def sweep_min_line(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    axis: int,
    b: int,
    l: int,
):
    """Carry the smallest label through labelled voxels along line l of block b, both ways;
    returns how many labels it lowered."""
    corner = bcoord[b] * BS
    first, st = line_start(axis, l)
    count = int(0)
    for dirn in range(2):
        start = line_voxel(axis, wp.where(dirn == 0, -1, BS), l) + corner
        sl = slot(bmap, start[0], start[1], start[2])
        carry = LABEL_NONE
        if sl >= 0:
            carry = labels[sl]
        for q in range(BS):
            t = b * BV + first + wp.where(dirn == 0, q, BS - 1 - q) * st
            lab = labels[t]
            if lab >= 0 and carry >= 0 and carry < lab:
                labels[t] = carry
                lab = carry
                count += 1
            carry = lab
    return count


@wp.kernel
def sweep_min_labels(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    axis: int,
    changed: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    base: int,
):
    """Carry the smallest label through labelled voxels along one block line, both ways
    (blocks with active[b] != 0); moved[b] = 1 where a label of block b was lowered."""
    tid = wp.tid() + base
    b = tid // 64
    if active[b] == 0:
        return
    count = sweep_min_line(bcoord, bmap, labels, axis, b, tid - b * 64)
    if count > 0:
        changed[0] = 1  # flags: every writer stores the same value, no atomic contention
        moved[b] = 1


@wp.kernel
def count_component_particles(
    g: wp.array(dtype=wp.vec3),
    bmap: wp.array3d(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
):
    p = wp.tid()
    gp = g[p]
    s = slot(bmap, int(wp.round(gp[0])), int(wp.round(gp[1])), int(wp.round(gp[2])))
    if s >= 0:
        lab = labels[s]
        if lab > 0:
            wp.atomic_add(counts, lab, 1)


@wp.kernel
def remove_small_components(
    labels: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    min_count: int,
    outside_value: float,
    phi: wp.array(dtype=float),
    base: int,
):
    t = wp.tid() + base
    lab = labels[t]
    if lab > 0 and counts[lab] < min_count:
        phi[t] = outside_value


@cpu_kernel
def small_blocks(
    sign: wp.array(dtype=wp.uint64), reached: wp.array(dtype=wp.uint64), pending: wp.array(dtype=wp.int32), base: int
):
    """pending[b] = 1 where block b holds an inside voxel the fill from the bodies (seeds 2) did
    not reach (a voxel of a small component: labels_from_bits labels it), else 0 (thread = block)."""
    b = wp.tid() + base
    left = wp.uint64(0)
    for x in range(BS):
        left = left | ((~reached[b * BS + x]) & (~sign[b * BS + x]))
    pending[b] = wp.where(left != wp.uint64(0), 1, 0)


@cpu_kernel
def labels_from_bits(
    sign: wp.array(dtype=wp.uint64), reached: wp.array(dtype=wp.uint64), labels: wp.array(dtype=wp.int32), base: int
):
    """Labels of init_inside_labels after a fill from the bodies (seeds 2) for
    the 64 voxels of word w: outside -1, reached inside 0 (a component that is not small:
    seed_bits' bodies), the other inside voxels their own t + 1 (the blocks holding those:
    small_blocks)."""
    w = wp.tid() + base
    s = sign[w]
    left = (~reached[w]) & (~s)
    for q in range(BS * BS):
        t = w * BS * BS + q
        lab = LABEL_NONE
        if ((s >> wp.uint64(q)) & wp.uint64(1)) == wp.uint64(0):
            lab = 0
            if ((left >> wp.uint64(q)) & wp.uint64(1)) != wp.uint64(0):
                lab = t + 1
        labels[t] = lab


@wp.kernel
def seed_large_labels(
    phi: wp.array(dtype=float),
    mark: wp.array(dtype=wp.int32),
    min_count: int,
    labels: wp.array(dtype=wp.int32),
    base: int,
):
    """The voxel path's counterpart of seed_bits' large pieces (thread = block; its int32 marks
    and init_inside_labels' labels): label 0 for the inside voxels of a block
    whose inside voxels are one piece holding at least min_count particles' voxels, so the
    min-label sweeps start from 0 across a water sheet instead of carrying one least index
    over all of it (hundreds of rounds on a large random sheet)."""
    b = wp.tid() + base
    s = vec8u(wp.uint64(0))
    marked = int(0)
    for x in range(BS):
        w = wp.uint64(0)
        for q in range(BS * BS):
            t = b * BV + x * BS * BS + q
            if phi[t] > 0.0:
                w = w | bit(q)
            elif mark[t] != 0:
                marked += 1
        s[x] = w
    if large_piece(s, marked, min_count):
        for q in range(BV):
            if phi[b * BV + q] <= 0.0:
                labels[b * BV + q] = 0


@cpu_kernel
def sweep_min_labels_blocks(
    bcoord: wp.array(dtype=wp.vec3i),
    bmap: wp.array3d(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    changed: wp.array(dtype=wp.int32),
    moved: wp.array(dtype=wp.int32),
    base: int,
):
    """sweep_min_labels along x, y and z for the 64 lines of block b (thread =
    block), again until no label in the block moves (a label then crosses the block in one
    round, not one line sweep a round). The blocks left out (active[b] == 0: those without a
    small component, and after the first round those where nothing moved nearby) cost a thread
    each instead of 64 (a thread per line cost ~1 ms a launch over 2.1 M voxels' lines, one
    thread); moved[b] = 1 where a label was lowered. The lines run in another order than on a
    GPU, which the min-label sweeps allow: they end at each component's least label whatever
    the order (remove_small)."""
    b = wp.tid() + base
    if active[b] == 0:
        return
    count = int(0)
    while True:  # the block's own fixpoint: the three axes' sweeps until none lowers a label
        now = int(0)
        for ax in range(3):
            for l in range(BS * BS):
                now += sweep_min_line(bcoord, bmap, labels, ax, b, l)
        count += now
        if now == 0:
            break
    if count > 0:
        wp.atomic_add(changed, 0, count)
        moved[b] = 1


def remove_small(labels_of, bcoord, bmap, phi, g, mark, min_count: int, tiles) -> None:
    """Inside components (6-connected) holding fewer than min_count particles become outside;
    components touching an INSIDE tile are large by construction and stay, and so are those
    holding a block whose inside voxels are one piece with at least min_count particles' voxels
    (bitwords.large_piece: on the CPU they seed the bodies' fill, on a GPU they start the
    min-label sweeps at 0, which a water sheet with no INSIDE tile needs). labels_of: a
    variant's labels_* (None: no small component)."""
    nvox = phi.shape[0]
    labels = labels_of(bcoord, bmap, phi, mark, min_count)
    if labels is None:
        return
    counts = wp.zeros(nvox + 1, dtype=wp.int32)
    wp.launch(count_component_particles, g.shape[0], inputs=[g, bmap, labels, counts])
    split(wp, remove_small_components, nvox, [labels, counts, min_count, tiles[0], phi])


def labels_by_voxel(bcoord, bmap, phi, mark, min_count: int):
    """The component labels (int32 per voxel): min-label sweeps over every block, after the
    first round only near the last round's changes."""
    nvox = phi.shape[0]
    labels = wp.empty(nvox, dtype=wp.int32)
    split(wp, init_inside_labels, nvox, [bcoord, bmap, phi, labels])
    split(wp, seed_large_labels, bcoord.shape[0], [phi, mark, min_count, labels])

    def sweep(active, changed, moved):
        for axis in range(3):
            split(wp, sweep_min_labels, bcoord.shape[0] * 64, [bcoord, bmap, labels, active, axis, changed, moved])

    active_rounds(bcoord, bmap, wp.full(bcoord.shape[0], 1, dtype=wp.int32), sweep)
    return labels


def labels_by_block(bcoord, bmap, phi, mark, min_count: int):
    """The component labels (int32 per voxel), or None where no component is small (then no
    label is above 0 and nothing is removed). A fill from the bodies labels 0 at once the
    components that cannot be small: those touching an INSIDE tile, and those holding a block
    whose inside voxels are one piece within it with at least min_count particles' voxels
    (seed_bits). The min-label sweeps then run only over the blocks holding other inside voxels
    (drops, filaments: few), each block to its own fixpoint, after the first round only near
    the last round's changes. The labels differ from labels_by_voxel' (0 where those end at a
    component's least index), the components removed do not: 0 is never removed, and a label's
    count is its component's."""
    nvox = phi.shape[0]
    sign, reached, _ = fill_bits(bcoord, bmap, phi, mark, 0.0, "bodies", min_count)
    pending = wp.empty(bcoord.shape[0], dtype=wp.int32)
    launch_split(wp, small_blocks, bcoord.shape[0], [sign, reached, pending], device=phi.device, light=1)
    # bodies alone: the labels, their particle counts and the removal pass would find nothing to do
    if not pending.numpy().any():
        return None
    labels = wp.empty(nvox, dtype=wp.int32)
    launch_split(wp, labels_from_bits, sign.shape[0], [sign, reached, labels], device=phi.device)

    def sweep(active, changed, moved):  # a block per thread: the blocks left out cost ~nothing
        launch_split(
            wp,
            sweep_min_labels_blocks,
            bcoord.shape[0],
            [bcoord, bmap, labels, active, changed, moved],
            device=phi.device,
        )

    active_rounds(bcoord, bmap, pending, sweep)
    return labels
