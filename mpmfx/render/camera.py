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


FOCAL_MM, FILM_MM = 35.0, 36.0  # the render camera's lens and film width (horizontal fit)


def frame_box(lo, hi, *, direction, aspect: float, focal_mm: float = 35.0, margin: float = 1.08):
    """(position, look_at) in metres for a camera looking along -`direction` (from the camera
    towards the scene is -direction) that fits the box [lo, hi] (m, (3,) each) in a picture of
    width / height `aspect` on 36 mm film.

    Each box corner must project inside the film: with the view axes fixed, the nearest
    camera distance that keeps every corner in frame is solved per corner and the largest wins.
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = (lo + hi) / 2
    back = np.asarray(direction, float) / np.linalg.norm(direction)
    right = np.cross((0.0, 1.0, 0.0), back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    tan_h = 18.0 / focal_mm / margin
    tan_v = tan_h / aspect
    dist = 0.0
    for i in range(8):
        c = np.where([i & 1, i & 2, i & 4], hi, lo) - centre
        depth = c @ back  # towards the camera
        dist = max(dist, abs(c @ right) / tan_h + depth, abs(c @ up) / tan_v + depth)
    return tuple(float(x) for x in centre + back * dist), tuple(float(x) for x in centre)


def frames_bounds(shot) -> bool:
    """Whether the render camera frames what was simulated (Cycles, no `render.camera_position`)."""
    r = shot.render
    return r.camera_position is None and str(getattr(r.engine, "value", r.engine)) == "cycles"


def camera_inputs(shot) -> dict:
    """What `render_camera` depends on besides the frames' bounds (for a cache key)."""
    r = shot.render
    out = {"aspect": r.width / r.height}
    if frames_bounds(shot):
        return {**out, "mode": r.mode, "floor": solver_floor(shot), "domain": shot.domain.model_dump(mode="json")}
    return {**out, "camera": default_camera(shot)}


def render_camera(shot, bounds=None) -> dict:
    """The camera the render looks through, which the exported USD carries too: {position,
    look_at (m), focal_length, horizontal_aperture, vertical_aperture (mm)}. Cycles without
    `render.camera_position` frames `bounds` ((lo, hi) m of what is shown over the shot, the
    ground contact kept in; None: the domain) along VIEW_DIRECTION; otherwise the config's
    camera or the 3/4 view (`default_camera`)."""
    r = shot.render
    aspect = r.width / r.height
    if frames_bounds(shot):
        o, L = np.asarray(shot.domain.origin, float), float(shot.domain.size)
        lo, hi = (np.asarray(b, float) for b in (bounds or (o, o + L)))
        lo[1] = min(lo[1], solver_floor(shot))
        pos, look = frame_box(lo, hi, direction=VIEW_DIRECTION, aspect=aspect, focal_mm=FOCAL_MM)
    else:
        pos, look = default_camera(shot)
    return {
        "position": pos,
        "look_at": look,
        "focal_length": FOCAL_MM,
        "horizontal_aperture": FILM_MM,
        "vertical_aperture": FILM_MM / aspect,
    }
