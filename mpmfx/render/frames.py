"""Offscreen PyVista renders of surfaces (the look) and particles (the debug look for tuning motion)."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np

from mpmfx.cache import atomic_path
from mpmfx.render import import_pyvista

# Colour per material family, keyed by preset name (unknown names fall back to grey).
COLOURS = {
    "Soft": "#f4f7fb",
    "Mushy": "#eef2f7",
    "Goopy": "#e3e9f0",
    "Wet": "#d5e2ec",
    "Slush": "#c9dbe8",
    "Elastic": "#e8577a",
    "Granular": "#d8b47c",
    "CohesiveGranular": "#c79f6a",
    "Water": "#3d8fd6",
    "Tracer": "#ffd23f",
}
PALETTE = ["#e8577a", "#3d8fd6", "#d8b47c", "#7ac74f", "#f4f7fb", "#b07cc6"]


def colour_for(name: str, index: int) -> str:
    return COLOURS.get(name, PALETTE[index % len(PALETTE)])


class FrameRenderer:
    """One plotter reused for every frame of a shot (creating a render window is the slow part)."""

    def __init__(self, *, size: tuple[int, int], camera: tuple, domain: tuple, floor: float, title: str = ""):
        """camera: (position, look_at) m; domain: (origin (3,) m, size m); floor: ground height (m),
        the solver's floor (`mpmfx.render.camera.solver_floor`)."""
        pv = self.pv = import_pyvista()
        self.plotter = pv.Plotter(off_screen=True, window_size=size, lighting="three lights")
        self.plotter.set_background("#20242c", top="#5d6d82")
        origin, L = np.asarray(domain[0], float), float(domain[1])
        # The ground where the material rests (no domain box: its edges drew as scratches).
        ground = pv.Plane(
            center=(origin[0] + L / 2, floor, origin[2] + L / 2), direction=(0, 1, 0), i_size=L * 1.6, j_size=L * 1.6
        )
        self.plotter.add_mesh(ground, color="#8a8f98", ambient=0.25, diffuse=0.7, specular=0.0, name="floor")
        self.plotter.camera_position = [camera[0], camera[1], (0, 1, 0)]
        self.plotter.camera.view_angle = 35.0
        self.title = title
        self._names: list[str] = []

    def _clear(self):
        for n in self._names:
            self.plotter.remove_actor(n, render=False)
        self._names = []

    def surfaces(self, meshes: dict[str, tuple[np.ndarray, np.ndarray, str]], path: Path, *, label: str = ""):
        """meshes: name -> (vertices (m,3) m, faces (k,3) int, colour). Writes a PNG to `path`."""
        self._clear()
        for name, (v, f, colour) in meshes.items():
            if len(f) == 0:
                continue
            faces = np.hstack([np.full((len(f), 1), 3), f]).astype(np.int64).ravel()
            mesh = self.pv.PolyData(np.asarray(v, np.float64), faces).compute_normals(auto_orient_normals=False)
            water = colour == COLOURS["Water"]
            self.plotter.add_mesh(
                mesh,
                color=colour,
                smooth_shading=True,
                specular=0.6 if water else 0.2,
                specular_power=40,
                opacity=0.85 if water else 1.0,
                name=name,
            )
            self._names.append(name)
        return self._shoot(path, label)

    def particles(self, points: dict[str, tuple[np.ndarray, str]], radius: float, path: Path, *, label: str = ""):
        """The debug look: big soft blobs, one colour per group, for tuning motion before the look
        (the tutorial "Material Point Method: Step by Step", "How to tune, as a process")."""
        self._clear()
        for name, (x, colour) in points.items():
            if len(x) == 0:
                continue
            self.plotter.add_points(
                np.asarray(x, np.float64),
                color=colour,
                point_size=max(2.0, radius),
                render_points_as_spheres=True,
                name=name,
            )
            self._names.append(name)
        return self._shoot(path, label)

    def _shoot(self, path: Path, label: str) -> Path:
        self.plotter.add_text(f"{self.title}  {label}", font_size=9, color="white", name="label")
        self._names.append("label")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.tmp.png")
        try:
            self.plotter.screenshot(str(tmp))
        except BaseException:
            tmp.unlink(missing_ok=True)  # PIL leaves its partial file on a full disk
            raise
        tmp.replace(path)
        return path

    def close(self):
        self.plotter.close()


def write_movie(frames: list[Path], path: Path, *, fps: float) -> Path:
    """H.264 mp4 of the PNGs (imageio-ffmpeg ships its own ffmpeg binary), written atomically."""
    # H.264 needs even sizes only; 8 would resize 540-high frames
    with (
        atomic_path(path) as tmp,
        imageio.get_writer(tmp, fps=fps, codec="libx264", quality=8, macro_block_size=2) as w,
    ):
        for f in frames:
            w.append_data(imageio.imread(f))
    return path
