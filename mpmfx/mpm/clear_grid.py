"""Phase 1 — clear the grid: mass and momentum accumulators to zero (guide §3).

The grid is scratch memory: nothing on it survives a substep. A device memset does the
job, so this phase compiles no kernel.
"""

from __future__ import annotations


def clear_grid(grid_m, grid_mv, grid_normal, grid_fixed, *, deterministic: bool, multi_field: bool) -> None:
    """Zero the accumulators P2G is about to write (float or fixed-point ones; the mass
    gradients too in multi-field mode)."""
    if deterministic:
        grid_fixed.zero_()
        return
    grid_m.zero_()
    grid_mv.zero_()
    if multi_field:
        grid_normal.zero_()
