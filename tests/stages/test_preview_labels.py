"""The preview's burned-in label names the frame it is on, whatever `render.frame_step` says."""

from __future__ import annotations

from mpmfx.render.frames import FrameRenderer
from mpmfx.shotfile import load_shot_config
from mpmfx.stages.runner import ShotRun
from tests.conftest import write_tiny_shot


def test_every_preview_frame_is_drawn_with_its_own_label(tmp_path, monkeypatch):
    # frame_step = 3 from frame 1 would draw 1, 4, 7 and hold the rest, so --frames 5:8 showed
    # frame 4's picture and label on frames 5 and 6, and frame 7's on frame 8
    shot = write_tiny_shot(tmp_path, frame_end=8)
    shot.write_text(shot.read_text().replace("movie = false", "movie = false\nframe_step = 3"))
    drawn: list[str] = []
    original = FrameRenderer.surfaces

    def surfaces(self, meshes, path, *, label=""):
        drawn.append(label.split("  ")[0])
        return original(self, meshes, path, label=label)

    monkeypatch.setattr(FrameRenderer, "surfaces", surfaces)
    run = ShotRun(load_shot_config(shot), cache_root=tmp_path / "cache", quiet=True, workers=1, publish=False)
    run.run(frames=list(range(5, 9)))
    assert drawn == [f"frame {f}" for f in range(5, 9)]
    frames = run.entries()["render"].root / "frames"
    assert len({(frames / f"{f:04d}.png").read_bytes() for f in range(5, 9)}) == 4
