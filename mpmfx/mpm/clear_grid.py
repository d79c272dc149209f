"""Phase 1 — clear the grid: mass and momentum accumulators to zero (docs/physics.md).

The grid is scratch memory: nothing on it survives a substep. A device memset does the
job, unless the last P2G marked the node bricks it touched (the brick P2G, inside a chunk):
then only those are zeroed, since a shot's grid is mostly empty space and a full memset is a
noticeable share of a substep.
"""

from __future__ import annotations

import warp as wp

from .bricks import BRICK, marked_node


def clear_grid(grid_m, grid_mv, grid_normal, grid_fixed, *, deterministic: bool, multi_field: bool, marks=None) -> None:
    """Zero the accumulators P2G is about to write (float or fixed-point ones; the mass
    gradients too in multi-field mode). marks: per node brick (bricks.node_brick order,
    int32), 1 where the last P2G wrote; given, only those bricks are zeroed."""
    if marks is not None:
        nn = grid_fixed.shape[0] if deterministic else grid_m.shape[0]
        wp.launch(
            _clear_marked,
            dim=marks.shape[0] * BRICK**3,
            device=marks.device,
            inputs=[marks, -(-nn // BRICK), nn, int(deterministic), grid_m, grid_mv, grid_fixed],
        )
        return
    if deterministic:
        grid_fixed.zero_()
        return
    grid_m.zero_()
    grid_mv.zero_()
    if multi_field:
        grid_normal.zero_()


@wp.func
def zero_node(
    deterministic: int,
    grid_m: wp.array3d(dtype=float),
    grid_mv: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
    i: int,
    j: int,
    k: int,
):
    """Zero node (i, j, k)'s accumulators: its fixed-point channels, or its mass and momentum.
    Also the brick path's grid update, which clears what it has read (grid_update.py)."""
    if deterministic != 0:
        for c in range(grid_fixed.shape[3]):
            grid_fixed[i, j, k, c] = wp.int64(0)
    else:
        grid_m[i, j, k] = 0.0
        grid_mv[i, j, k] = wp.vec3(0.0)


@wp.kernel(enable_backward=False)
def _clear_marked(
    marks: wp.array(dtype=wp.int32),
    nb: int,
    nodes: int,
    deterministic: int,
    grid_m: wp.array3d(dtype=float),
    grid_mv: wp.array3d(dtype=wp.vec3),
    grid_fixed: wp.array4d(dtype=wp.int64),
):
    node = marked_node(marks, wp.tid(), nb, nodes)
    if node[0] >= 0:
        zero_node(deterministic, grid_m, grid_mv, grid_fixed, node[0], node[1], node[2])
