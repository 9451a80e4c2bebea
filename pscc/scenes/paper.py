"""The paper's benchmark scenes (PSCC, I3D 2018, Fig. 10 and Fig. 13), procedural and sized by ``scale``.

``scale`` is the fraction of the paper's cloth triangle count (:data:`PAPER_TRIANGLES`): 1.0 is the
paper's resolution; the smallest allowed scale (:func:`min_scale`) gives about
:data:`MIN_TRIANGLES` cloth triangles, small enough for a CPU. Obstacles come on top of the count.

Regular scenes (this module): ``sphere``, ``twisting``, ``flag``, ``sphere-drop``. Garment scenes
(:mod:`pscc.scenes.garments`): ``kungfu`` (the paper's Andy), ``falling``, ``dance`` (Bishop).
The paper publishes only the descriptions, triangle counts and time steps; every other parameter
(sizes, spacing, pins, motions, wind, materials) is chosen here, stated in each builder's docstring
and justified in ``docs/scenes.md``.

Units: metres, seconds, kilograms; z is up. Cloth material: :class:`pscc.sim.config.ClothMaterial`
defaults (cotton-like, 2 mm thickness) unless a builder says otherwise. Time steps: the paper's
(1/200 s, 1/100 s for the flag) with 25 frames per second, so every frame is a whole number of
steps.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet, icosphere
from pscc.scenes.body import EasedMotion, rounded_core_mesh
from pscc.scenes.garments import dance, falling, kungfu
from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.obstacles import Handle, Obstacle, Transform, rotation_from_axis_angle
from pscc.sim.scene import Scene

PAPER_TRIANGLES: dict[str, int] = {
    "sphere": 200_000,
    "twisting": 200_000,
    "flag": 80_000,
    "sphere-drop": 1_000_000,
    "kungfu": 127_000,
    "falling": 172_000,
    "dance": 124_000,
}
"""Cloth triangles of each benchmark in the paper (Fig. 10, Fig. 14); ``kungfu`` is Andy, ``dance`` is Bishop."""

MIN_TRIANGLES: int = 5000
"""Cloth triangles at the smallest allowed scale of every scene."""

MAX_SCALE: float = 4.0
"""Largest allowed scale (P-Cloth ran these scenes at up to 3.5 times the paper's resolution)."""


def min_scale(name: str) -> float:
    """Smallest allowed scale of scene ``name``: about :data:`MIN_TRIANGLES` cloth triangles.

    Raises:
        InputError: unknown scene.
    """
    if name not in PAPER_TRIANGLES:
        raise InputError("argument", "scene", f"unknown paper scene {name!r}",
                         f"use one of {', '.join(PAPER_TRIANGLES)}")
    return MIN_TRIANGLES / PAPER_TRIANGLES[name]


def check_scale(name: str, scale: float) -> float:
    """Validate ``scale`` for scene ``name`` and return it as a float.

    Raises:
        InputError: unknown scene, or a scale that is not a number in [min_scale(name), MAX_SCALE].
    """
    low = min_scale(name)
    fix = (f"pass --scale between {low:.4g} (about {MIN_TRIANGLES} triangles) and {MAX_SCALE:g} "
           f"(1 = the paper's {PAPER_TRIANGLES[name]} triangles)")
    if isinstance(scale, bool):
        raise InputError("argument", "--scale", f"{scale!r} is not a number", fix)
    try:
        value = float(scale)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", "--scale", f"{scale!r} is not a number", fix) from exc
    if not math.isfinite(value) or value < low * (1.0 - 1e-9) or value > MAX_SCALE:
        raise InputError("argument", "--scale", f"{scale!r} is outside [{low:.4g}, {MAX_SCALE:g}] for {name}", fix)
    return value


def _grid(triangles: int, width: float, height: float) -> tuple[int, int]:
    """Cells (nx, ny), nearly square, with 2 nx ny as close as possible to ``triangles``."""
    aspect = width / height
    guess = math.sqrt(triangles / (2.0 * aspect))
    best: tuple[float, int, int] | None = None
    for ny in range(max(2, math.floor(guess) - 2), math.ceil(guess) + 3):
        for nx in {max(2, math.floor(triangles / (2.0 * ny))), max(2, math.ceil(triangles / (2.0 * ny)))}:
            error = abs(2 * nx * ny - triangles) + 1e-3 * abs(nx / ny - aspect)
            if best is None or error < best[0]:
                best = (error, nx, ny)
    assert best is not None
    return best[1], best[2]


def _stack(sheets: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> tuple[np.ndarray, ...]:
    """Concatenate sheets ``(vertices, faces, rest)``; object id = sheet index."""
    vertices, faces, rest, ids = [], [], [], []
    offset = 0
    for index, (v, f, r) in enumerate(sheets):
        vertices.append(v)
        faces.append(f + offset)
        rest.append(r)
        ids.append(np.full(f.shape[0], index, dtype=np.int32))
        offset += v.shape[0]
    return (np.concatenate(vertices).astype(np.float32), np.concatenate(faces).astype(np.int32),
            np.concatenate(rest).astype(np.float32), np.concatenate(ids))


def _sphere_subdivisions(scale: float) -> int:
    return 4 if scale >= 0.25 else 3


# ---------------------------------------------------------------------------------------------- sphere

SPHERE_PERIOD: float = 2.5
"""Period [s] of the forward-and-back motion of the ``sphere`` scene's ball."""


def _swing(start: np.ndarray, travel: np.ndarray, period: float) -> Callable[[float], Transform]:
    """Translation ``start + travel (1 - cos(2 pi t / period)) / 2``: starts at rest, forward and back forever."""

    def motion(t: float) -> Transform:
        phase = 0.5 * (1.0 - math.cos(2.0 * math.pi * float(t) / period))
        return np.eye(3), start + phase * travel

    return motion


def sphere(scale: float) -> Scene:
    """Three hanging cloths hit by a sphere moving forward and back (200K triangles at scale 1).

    * cloths: three 1 m x 1 m sheets (a third of the triangles each; 183 x 182 cells at scale 1),
      hanging in the planes y = 0, 0.04, 0.08 (4 cm apart: 20 thicknesses, close enough that the
      sphere pushes all three into each other), x in [-0.5, 0.5], z in [0, 1], each pinned along its
      whole top edge (z = 1);
    * sphere: radius 0.2 m, centre x = 0, z = 0.5 (the middle of the cloths), y(t) = -0.35 +
      0.8 (1 - cos(2 pi t / 2.5)) / 2: starts at rest 15 cm in front of the first cloth, travels 0.8 m
      through all three (its far side reaches y = 0.65) and back every 2.5 s (peak speed 1.0 m/s);
    * time: dt = 1/200 s (the paper's), 25 frames/s, 8 steps per frame.
    """
    scale = check_scale("sphere", scale)
    nx, ny = _grid(round(scale * PAPER_TRIANGLES["sphere"] / 3.0), 1.0, 1.0)
    sheets, handles = [], []
    offset = 0
    for k in range(3):
        grid, faces, rest = grid_sheet(nx, ny, 1.0, 1.0)
        vertices = np.stack([grid[:, 0] - 0.5, np.full(grid.shape[0], 0.04 * k), grid[:, 1]], axis=1)
        top = np.flatnonzero(grid[:, 1] >= 1.0 - 1e-6)
        handles.append(Handle(top + offset, name=f"cloth {k} top edge"))
        sheets.append((vertices.astype(np.float32), faces, rest))
        offset += vertices.shape[0]
    vertices, faces, rest, ids = _stack(sheets)
    ball_vertices, ball_faces = icosphere(0.2, _sphere_subdivisions(scale))
    ball = Obstacle(ball_vertices, ball_faces, name="sphere",
                    motion=_swing(np.array([0.0, -0.35, 0.5]), np.array([0.0, 0.8, 0.0]), SPHERE_PERIOD))
    return Scene(name="sphere", description="three hanging cloths hit by a sphere moving forward and back",
                 vertices=vertices, faces=faces, rest=rest, object_ids=ids, handles=handles, obstacles=[ball],
                 frame_time=1.0 / 25.0, steps_per_frame=8)


# ---------------------------------------------------------------------------------------------- twisting

TWISTING_TURN: float = math.pi
"""Total turn of the ``twisting`` ball about the vertical axis [rad] (half a turn)."""

TWISTING_START: float = 1.0
"""Time [s] the ``twisting`` ball starts turning (when the cloths have draped)."""

TWISTING_TURN_TIME: float = 1.5
"""Time [s] the ``twisting`` ball takes for its turn (smoothstep: starts and stops at rest, peak
angular speed 1.5 x TWISTING_TURN / TWISTING_TURN_TIME = half a turn per second)."""

TWISTING_TACK_RADIUS: float = 0.05
"""Radius [m] of the disc at the centre of each ``twisting`` cloth (in material space) that is
stitched to the ball and turns with it."""

TWISTING_FRICTION: float = 0.9
"""Friction coefficient of the ``twisting`` cloths (the default is 0.3)."""

TWISTING_CORNER_SHIFT: tuple[float, float] = (0.217, -0.33)
"""Inward (along x and y each) and vertical travel [m] of the ``twisting`` corners while draping."""


def _ball_turn(t: float) -> Transform:
    """The ``twisting`` ball (and the stitched cloth centres): a turn about +z by TWISTING_TURN
    between TWISTING_START and TWISTING_START + TWISTING_TURN_TIME, smoothstep in time."""
    x = min(max((float(t) - TWISTING_START) / TWISTING_TURN_TIME, 0.0), 1.0)
    angle = TWISTING_TURN * x * x * (3.0 - 2.0 * x)
    return rotation_from_axis_angle(np.array([0.0, 0.0, angle])), np.zeros(3)


def twisting(scale: float) -> Scene:
    """Three cloths twisting severely as the ball under them turns (200K triangles at scale 1).

    * cloths: three 1 m x 1 m horizontal sheets stacked 1 cm apart, the lowest 1 cm above the top of
      the ball (z = 0.31, 0.32, 0.33), centred on the ball's axis;
    * corners: the corner vertex of each sheet is held and moved (eased, 0 -> 1 s) 0.22 m inwards
      along x and y and 0.33 m down, to 0.40 m from the axis at the height of the ball's centre
      (z = -0.02 .. 0): the layers hang loosely over the ball (the path over the ball along a diagonal
      is 19 % shorter than the half diagonal), then the corners stay (point pins: the cloth can pivot
      about them);
    * centres: a disc of radius 5 cm at the centre of each sheet (material space) is stitched to the
      top of the ball and turns with it, so the ball drives the twist (friction alone lets the ball
      slip under the layers at about 20 degrees, see docs/scenes.md);
    * ball: radius 0.3 m, centre at the origin, turning half a turn about the vertical axis from 1.0 s
      to 2.5 s (smoothstep: from rest to half a turn per second and back to rest), then still: the
      three layers twist against their held corners by over 100 degrees around the stitches and stay
      twisted;
    * friction 0.9 (the default is 0.3; cloth on rubber): the layers grip the ball and each other;
    * time: dt = 1/200 s (the paper's), 25 frames/s, 8 steps per frame.
    """
    scale = check_scale("twisting", scale)
    nx, ny = _grid(round(scale * PAPER_TRIANGLES["twisting"] / 3.0), 1.0, 1.0)
    sheets, handles = [], []
    for k in range(3):
        grid, faces, rest = grid_sheet(nx, ny, 1.0, 1.0)
        vertices = grid - np.array([0.5, 0.5, -(0.31 + 0.01 * k)], dtype=np.float32)
        sheets.append((vertices.astype(np.float32), faces, rest))
    for cx in (0.0, 1.0):
        for cy in (0.0, 1.0):
            # One handle per corner for the three layers: they move alike.
            corner = np.flatnonzero((np.abs(grid[:, 0] - cx) <= 1e-6) & (np.abs(grid[:, 1] - cy) <= 1e-6))
            inward = np.array([0.5 - cx, 0.5 - cy, 0.0]) / 0.5 * TWISTING_CORNER_SHIFT[0]
            target = inward + np.array([0.0, 0.0, TWISTING_CORNER_SHIFT[1]])
            motion = EasedMotion([0.0, 1.0], translations=np.stack([np.zeros(3), target]))
            ids = np.concatenate([corner + k * grid.shape[0] for k in range(3)])
            handles.append(Handle(ids, motion=motion, name=f"corner ({cx:g}, {cy:g})"))
    centre = np.flatnonzero(np.linalg.norm(rest - rest.mean(axis=0), axis=1) <= TWISTING_TACK_RADIUS)
    for k in range(3):
        handles.append(Handle(centre + k * grid.shape[0], motion=_ball_turn, name=f"cloth {k} centre stitch"))
    vertices, faces, rest, object_ids = _stack(sheets)
    ball_vertices, ball_faces = icosphere(0.3, _sphere_subdivisions(scale))
    ball = Obstacle(ball_vertices, ball_faces, motion=_ball_turn, name="ball")
    return Scene(name="twisting", description="three cloths twist severely as the ball under them turns",
                 vertices=vertices, faces=faces, rest=rest, object_ids=object_ids,
                 material=ClothMaterial(friction=TWISTING_FRICTION), handles=handles, obstacles=[ball],
                 frame_time=1.0 / 25.0, steps_per_frame=8)


# ---------------------------------------------------------------------------------------------- flag

FLAG_WIND: tuple[float, float, float] = (5.0, 3.0, 0.0)
"""Wind velocity of the ``flag`` scene [m/s] (5.8 m/s, 31 degrees off the flag's initial plane)."""

FLAG_AIR_DRAG: float = 1.0
"""Normal air drag of the ``flag`` scene [kg/(m^2 s)]."""


def flag(scale: float) -> Scene:
    """A flag waving in the wind (80K triangles at scale 1).

    * flag: 1.5 m x 1.0 m (3:2), in the vertical plane y = 0, x in [0.032, 1.532], z in [2, 3]
      (245 x 163 cells at scale 1), pinned along its whole pole side (x = 0.032);
    * pole: a static capsule of radius 2 cm along the z axis from z = 0 to 3.2 (1.2 cm from the
      pinned edge), so the flag can wrap around it;
    * wind: constant (5, 3, 0) m/s with air drag 1 kg/(m^2 s) (``SolverConfig.wind``/``air_drag``): at
      31 degrees to the flag it starts pushing at once (3 N/m^2 on the flat flag, 1.6 times its
      weight per area) and swings it round to stream and flap; gravity as usual. No gusts (the
      solver's wind is constant);
    * time: dt = 1/100 s (the paper's), 25 frames/s, 4 steps per frame.
    """
    scale = check_scale("flag", scale)
    nx, ny = _grid(round(scale * PAPER_TRIANGLES["flag"]), 1.5, 1.0)
    grid, faces, rest = grid_sheet(nx, ny, 1.5, 1.0)
    vertices = np.stack([grid[:, 0] + 0.032, np.zeros(grid.shape[0]), grid[:, 1] + 2.0], axis=1).astype(np.float32)
    pole_side = np.flatnonzero(grid[:, 0] <= 1e-6)
    pole_vertices, pole_faces = rounded_core_mesh(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 3.2]]), 0.02, 16, 6)
    return Scene(name="flag", description="a flag pinned along its pole waves in the wind",
                 vertices=vertices, faces=faces, rest=rest, object_ids=np.zeros(faces.shape[0], dtype=np.int32),
                 solver=SolverConfig(wind=FLAG_WIND, air_drag=FLAG_AIR_DRAG),
                 handles=[Handle(pole_side, name="pole side")],
                 obstacles=[Obstacle(pole_vertices, pole_faces, name="pole")],
                 frame_time=1.0 / 25.0, steps_per_frame=4)


# ---------------------------------------------------------------------------------------------- sphere-drop

SPHERE_DROP_PERIOD: float = 2.0
"""Period [s] of the ``sphere-drop`` sphere's sideways motion."""


def sphere_drop(scale: float) -> Scene:
    """One rectangular cloth falling on a moving sphere (1M triangles at scale 1; the paper's Fig. 13).

    * cloth: a 2 m x 2 m horizontal sheet (707 x 707 cells at scale 1, 2.8 mm cells), centred above
      the sphere, 5 cm above its top (z = 0.45), falling freely;
    * sphere: radius 0.4 m, centre starting at the origin and moving along x as
      0.4 (1 - cos(2 pi t / 2)) / 2 (starts at rest, 0.4 m out and back every 2 s, peak speed
      0.63 m/s), so the draped cloth is dragged and slides;
    * time: dt = 1/200 s (the paper's), 25 frames/s, 8 steps per frame.
    """
    scale = check_scale("sphere-drop", scale)
    nx, ny = _grid(round(scale * PAPER_TRIANGLES["sphere-drop"]), 2.0, 2.0)
    grid, faces, rest = grid_sheet(nx, ny, 2.0, 2.0)
    vertices = (grid - np.array([1.0, 1.0, -0.45], dtype=np.float32)).astype(np.float32)
    ball_vertices, ball_faces = icosphere(0.4, _sphere_subdivisions(scale))
    ball = Obstacle(ball_vertices, ball_faces, name="sphere",
                    motion=_swing(np.zeros(3), np.array([0.4, 0.0, 0.0]), SPHERE_DROP_PERIOD))
    return Scene(name="sphere-drop", description="a large rectangular cloth falls on a moving sphere",
                 vertices=vertices, faces=faces, rest=rest, object_ids=np.zeros(faces.shape[0], dtype=np.int32),
                 obstacles=[ball], frame_time=1.0 / 25.0, steps_per_frame=8)


PAPER_SCENES: dict[str, Callable[[float], Scene]] = {
    "sphere": sphere,
    "twisting": twisting,
    "flag": flag,
    "sphere-drop": sphere_drop,
    "kungfu": kungfu,
    "falling": falling,
    "dance": dance,
}
"""Builders of the paper's benchmarks by name; each takes ``scale`` (see :func:`check_scale`)."""


def build_paper_scene(name: str, scale: float | None = None) -> Scene:
    """Build benchmark ``name`` at ``scale`` (default: :func:`min_scale`, about 5K cloth triangles).

    Raises:
        InputError: unknown scene or a scale out of range.
    """
    if name not in PAPER_SCENES:
        raise InputError("argument", "scene", f"unknown paper scene {name!r}", f"use one of {', '.join(PAPER_SCENES)}")
    return PAPER_SCENES[name](min_scale(name) if scale is None else scale)

