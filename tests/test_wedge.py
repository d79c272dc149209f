"""`mpmfx wedge` input: the values of a --vary."""

import pytest


def test_a_wedge_of_one_value_written_twice_is_refused():
    from mpmfx.wedge import parse_vary

    with pytest.raises(Exception, match="two or more different values"):
        parse_vary("surface.radius_scale=1,1.0")
    assert parse_vary("surface.radius_scale=1,1.5") == ("surface.radius_scale", [1, 1.5])


def test_the_cycles_tiles_of_a_wedge_share_one_camera_that_frames_every_variant(tmp_path, monkeypatch):
    """Each variant once framed its own bounds, so the view jumped between tiles."""
    import json

    import numpy as np
    from PIL import Image

    from mpmfx.render.camera import frame_box
    from mpmfx.stages import render
    from mpmfx.wedge import parse_vary, run_wedge, variant_shots
    from tests.conftest import write_tiny_shot

    cameras = {}

    def fake_blender(job_path, *, log):
        job = json.loads(job_path.read_text())
        cameras[job_path.parent.name] = job["camera"]
        for f, out in zip(job["frames"], job["outputs"]):
            Image.new("RGB", (job["width"], job["height"]), "#808080").save(out)
            yield f, 0.0, 0.0

    monkeypatch.setattr(render, "run_job", fake_blender)
    monkeypatch.setattr(render, "blender_version", lambda: "test")
    shot = write_tiny_shot(tmp_path, frame_end=2)
    shot.write_text(shot.read_text().replace('engine = "preview"', 'engine = "cycles"'))
    key, values = parse_vary("objects.0.scale=0.5,1.5")
    shots = variant_shots(shot, key, values)
    roots = run_wedge(shots, cache_root=tmp_path / "cache", frames=[1, 2], quiet=True)
    assert len(cameras) == 2 and len({json.dumps(c) for c in cameras.values()}) == 1
    boxes = [render.shown_bounds(s, {n: r[n] for n in ("simulate", "surface")}, [1, 2]) for s, r in zip(shots, roots)]
    lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    aspect = shots[0].render.width / shots[0].render.height
    union = frame_box(lo, hi, direction=render.VIEW_DIRECTION, aspect=aspect)
    alone = frame_box(*boxes[0], direction=render.VIEW_DIRECTION, aspect=aspect)
    (camera,) = {json.dumps(c) for c in cameras.values()}
    assert json.loads(camera)["position"] == pytest.approx(union[0])
    assert np.linalg.norm(np.subtract(alone[0], union[0])) > 0.05  # the small variant alone is framed closer
