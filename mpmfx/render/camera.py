"""The shot camera: the config's, or a 3/4 view that frames the domain."""
from __future__ import annotations

import numpy as np


def default_camera(shot) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(position, look_at) in metres. Default: from front-right-above, 1.4 domain sizes away."""
    o, L = np.asarray(shot.domain.origin), shot.domain.size
    centre = o + np.array([0.5, 0.27, 0.5]) * L
    look = shot.render.camera_look_at or tuple(centre)
    pos = shot.render.camera_position or tuple(centre + np.array([0.8, 0.42, 1.25]) * L)
    return tuple(float(x) for x in pos), tuple(float(x) for x in look)
