"""The shot camera and the ground: the config's camera, or a 3/4 view; the solver's floor."""

from __future__ import annotations

import numpy as np

# The default view: from front-right-above (a direction from the scene towards the camera).
VIEW_DIRECTION = (0.8, 0.42, 1.25)


def default_camera(shot) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(position, look_at) in metres. Default: along VIEW_DIRECTION, 1.4 domain sizes away."""
    o, L = np.asarray(shot.domain.origin), shot.domain.size
    centre = o + np.array([0.5, 0.27, 0.5]) * L
    look = shot.render.camera_look_at or tuple(centre)
    pos = shot.render.camera_position or tuple(centre + np.array(VIEW_DIRECTION) * L)
    return tuple(float(x) for x in pos), tuple(float(x) for x in look)


def solver_box(shot) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(lo, hi) world corners (m) of the box the solver's walls hold material in (`Shot.wall_box`):
    the walls are planes inside the domain's faces, and material rests on them."""
    return shot.wall_box()


def solver_floor(shot) -> float:
    """World height (m) of the solver's floor: renders draw the ground here."""
    return solver_box(shot)[0][1]
