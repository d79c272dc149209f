"""Host side of the CPU topology pass (mpmfx.surface.bitfill_kernels): the flood fills of
mpmfx.surface.sparse._flood and the component labels of _remove_small, on bit words.

Same results as the voxel-line sweeps a GPU runs (the same closed fills, the same labels
where they matter), fewer launches and less work per voxel.
"""

from __future__ import annotations

import logging

from mpmfx.surface.launch import launch_split
from mpmfx.surface.line_kernels import rows
from mpmfx.surface.sparse import BS, MAX_SWEEP_ROUNDS, active_rounds

log = logging.getLogger(__name__)

SEEDS = {"bubbles": 0, "specks": 1, "bodies": 2}  # bitfill_kernels.seed_bits' modes


def flood_bits(wp, T, bcoord, bmap, phi, mark, seed_depth: float, seeds: str, min_count: int = 0):
    """(sign, reached, rounds): bit words of a block each (8 per block) after filling from
    the `seeds` (SEEDS) through same-sign active voxels, a block per thread per round, over
    the blocks near those that changed in the previous round (T.active_blocks)."""
    from mpmfx.surface import bitfill_kernels as F

    nact = bcoord.shape[0]
    sign, reached = wp.empty(nact * BS, dtype=wp.uint64), wp.empty(nact * BS, dtype=wp.uint64)
    pending = wp.empty(nact, dtype=wp.int32)
    blocks = {"device": phi.device, "min_split": 1}  # a block per thread: few threads, much work each
    launch_split(wp, F.seed_bits, nact, [bcoord, bmap, rows(phi), mark, seed_depth, SEEDS[seeds], min_count, sign, reached, pending],
                 **blocks)

    def sweep(active, changed, moved):  # a round visits only the blocks near the last round's changes: light
        launch_split(wp, F.flood_bits, nact, [bcoord, bmap, sign, reached, active, changed, moved], **blocks, light=1)

    rounds, settled = active_rounds(wp, T, bcoord, bmap, pending, sweep)
    if not settled:
        log.warning("topology flood fill did not settle in %d rounds; some bubbles may remain", MAX_SWEEP_ROUNDS)
    return sign, reached, rounds


def flip_unreached(wp, reached, phi, tiles) -> None:
    """topology_kernels.flip_unreached from the bit words: unreached outside voxels -> tiles[1]
    (inside), unreached inside ones -> tiles[0]."""
    from mpmfx.surface import bitfill_kernels as F

    launch_split(wp, F.flip_unreached_bits, reached.shape[0], [reached, tiles[1], tiles[0], phi], device=phi.device,
                 light=BS)  # a word per block line


def small_labels(wp, T, bcoord, bmap, phi, mark, min_count: int):
    """The component labels of sparse._remove_small (int32 per voxel), or None where no
    component is small (then no label is above 0 and nothing is removed). A fill from the
    bodies labels 0 at once the components that cannot be small: those touching an INSIDE tile,
    and those holding a block whose inside voxels are one piece within it with at least
    min_count particles' voxels (bitfill_kernels.seed_bits; a water sheet has no INSIDE tile,
    and before these seeds all of it went through the sweeps: the default shot's 24 frames
    spent 1.13 s of their 5-6 s of surfacing there). The min-label sweeps then run only over
    the blocks holding other inside voxels (drops, filaments: few), each block to its own
    fixpoint, after the first round only near the last round's changes. The labels differ
    from the GPU's sweeps over every block (0 where those end at a component's least index),
    the components removed do not: 0 is never removed, and a label's count is its component's."""
    from mpmfx.surface import bitfill_kernels as F

    nvox = phi.shape[0]
    sign, reached, _ = flood_bits(wp, T, bcoord, bmap, phi, mark, 0.0, "bodies", min_count)
    pending = wp.empty(bcoord.shape[0], dtype=wp.int32)
    launch_split(wp, F.small_blocks, bcoord.shape[0], [sign, reached, pending], device=phi.device, light=1)
    # bodies alone (every block of the bench's twelve cases): the labels (8 MB at 100k "fine"),
    # their particle counts and the removal pass would find nothing to do
    if not pending.numpy().any():
        return None
    labels = wp.empty(nvox, dtype=wp.int32)
    launch_split(wp, F.labels_from_bits, sign.shape[0], [sign, reached, labels], device=phi.device)

    def sweep(active, changed, moved):  # a block per thread: the blocks left out cost ~nothing
        launch_split(wp, F.sweep_min_labels_blocks, bcoord.shape[0], [bcoord, bmap, labels, active, changed, moved],
                     device=phi.device)

    active_rounds(wp, T, bcoord, bmap, pending, sweep)
    return labels
