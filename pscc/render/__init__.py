"""Headless rendering of simulation frames: a Warp ray caster, PNG/MP4 output, run-folder previews.

``from pscc.render import Renderer, fit_camera, render_run``; see ``docs/rendering.md``.
"""

from pscc.render.raycast import PALETTE, VIEWS, Camera, Renderer, fit_camera, scene_bounds
from pscc.render.video import animation_bounds, render_run, write_mp4, write_png

__all__ = [
    "PALETTE",
    "VIEWS",
    "Camera",
    "Renderer",
    "animation_bounds",
    "fit_camera",
    "render_run",
    "scene_bounds",
    "write_mp4",
    "write_png",
]
