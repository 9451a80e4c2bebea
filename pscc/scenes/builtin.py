"""The three built-in test scenes of ``pscc simulate``: ``drape``, ``stack`` and ``twist``.

Every scene is procedural and sized by a requested triangle count (the cloth's; obstacles come on
top). Units: metres, seconds, kilograms. The parameters below are chosen, not taken from the
paper (which does not give them for these test scenes):

* ``drape``: a 1 m x 1 m sheet, horizontal, 0.1 m above a static sphere of radius 0.25 m and
  0.05 m off its centre (so the folds are not symmetric), falls under gravity, wraps the sphere and
  folds onto itself around it.
* ``stack``: three 0.8 m x 0.8 m sheets, 1 cm apart, lying above a static 1.2 m ground grid. A
  sphere of radius 0.15 m comes down (0.5 s), presses the layers to 1.8 cm above the ground,
  slides 0.2 m sideways (0.5 s) dragging them by friction, and lifts off (0.5 s).
* ``twist``: a 1 m x 0.25 m strip whose two short ends are clamped (handles). The ends turn in
  opposite directions about the strip's long axis at half a turn per second each and approach each
  other at 5 cm/s each, so the strip coils into heavy self-contact after about one second.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pscc._memory import SIMULATION_BYTES_PER_TRIANGLE, check_fits
from pscc.errors import InputError
from pscc.mesh.generate import grid_sheet, icosphere
from pscc.sim.obstacles import Handle, KeyframedMotion, Obstacle, Transform
from pscc.sim.scene import Scene

DEFAULT_TRIANGLES: dict[str, int] = {"drape": 2000, "stack": 3000, "twist": 2000}
"""Cloth triangles of each scene when ``--triangles`` is not given (CPU-friendly)."""

MIN_TRIANGLES: int = 32
"""Smallest cloth of any scene."""


def _grid_for(triangles: int, aspect: float) -> tuple[int, int]:
    """Cells (nx, ny) of a grid with nx / ny ~ aspect and 2 nx ny ~ triangles."""
    ny = max(2, round(math.sqrt(triangles / (2.0 * aspect))))
    nx = max(2, round(triangles / (2.0 * ny)))
    return nx, ny


def _sheet(triangles: int, width: float, height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    nx, ny = _grid_for(triangles, width / height)
    return grid_sheet(nx, ny, width, height)


def drape(triangles: int) -> Scene:
    """A sheet falling on a sphere (see the module docstring)."""
    vertices, faces, rest = _sheet(triangles, 1.0, 1.0)
    vertices = vertices - np.array([0.45, 0.5, -0.35], dtype=np.float32)  # centre (0.05, 0, 0.35)
    sphere_vertices, sphere_faces = icosphere(0.25, 3 if triangles >= 8000 else 2)
    return Scene(
        name="drape", description="a 1 m sheet falls on a sphere and folds on itself",
        vertices=vertices.astype(np.float32), faces=faces, rest=rest,
        object_ids=np.zeros(faces.shape[0], dtype=np.int32),
        obstacles=[Obstacle(sphere_vertices, sphere_faces, name="sphere")],
    )


def _stack_sphere(t: float) -> Transform:
    motion = KeyframedMotion(times=np.array([0.0, 0.5, 1.0, 1.5]),
                             translations=np.array([[0.0, 0.0, 0.45], [0.0, 0.0, 0.168], [0.2, 0.0, 0.168],
                                                    [0.2, 0.0, 0.45]]))
    return motion(t)


def stack(triangles: int) -> Scene:
    """Three layers pressed by a moving sphere (see the module docstring)."""
    per_layer = max(MIN_TRIANGLES, triangles // 3)
    layer_vertices, layer_faces, layer_rest = _sheet(per_layer, 0.8, 0.8)
    vertices, faces, rest, object_ids = [], [], [], []
    for layer in range(3):
        offset = layer * layer_vertices.shape[0]
        vertices.append(layer_vertices + np.array([-0.4, -0.4, 0.01 * (layer + 1)], dtype=np.float32))
        faces.append(layer_faces + offset)
        rest.append(layer_rest)
        object_ids.append(np.full(layer_faces.shape[0], layer, dtype=np.int32))
    ground_vertices, ground_faces, _ = grid_sheet(8, 8, 1.2, 1.2)
    ground_vertices = ground_vertices - np.array([0.6, 0.6, 0.0], dtype=np.float32)
    sphere_vertices, sphere_faces = icosphere(0.15, 3 if triangles >= 8000 else 2)
    return Scene(
        name="stack", description="three layers on the ground pressed and dragged by a moving sphere",
        vertices=np.concatenate(vertices).astype(np.float32), faces=np.concatenate(faces).astype(np.int32),
        rest=np.concatenate(rest).astype(np.float32), object_ids=np.concatenate(object_ids),
        obstacles=[Obstacle(ground_vertices, ground_faces, name="ground"),
                   Obstacle(sphere_vertices, sphere_faces, motion=_stack_sphere, name="sphere")],
    )


def _end_motion(direction: float, pivot: np.ndarray) -> Callable[[float], Transform]:
    """Turn about the x axis through ``pivot`` at half a turn per second and move along x at 5 cm/s."""

    def motion(t: float) -> Transform:
        angle = direction * math.pi * t
        cos, sin = math.cos(angle), math.sin(angle)
        rotation = np.array([[1.0, 0.0, 0.0], [0.0, cos, -sin], [0.0, sin, cos]])
        shift = np.array([-direction * 0.05 * min(t, 4.0), 0.0, 0.0])
        return rotation, pivot - rotation @ pivot + shift

    return motion


def twist(triangles: int) -> Scene:
    """A strip twisted by its two rotating ends (see the module docstring)."""
    vertices, faces, rest = _sheet(triangles, 1.0, 0.25)
    vertices = vertices - np.array([0.5, 0.125, 0.0], dtype=np.float32)
    x = vertices[:, 0]
    left = np.flatnonzero(x <= x.min() + 1e-6)
    right = np.flatnonzero(x >= x.max() - 1e-6)
    pivot = np.zeros(3)
    return Scene(
        name="twist", description="a strip twisted by its two rotating ends into heavy self-contact",
        vertices=vertices.astype(np.float32), faces=faces, rest=rest,
        object_ids=np.zeros(faces.shape[0], dtype=np.int32),
        handles=[Handle(left, _end_motion(-1.0, pivot), name="left end"),
                 Handle(right, _end_motion(1.0, pivot), name="right end")],
    )


SCENES: dict[str, Callable[[int], Scene]] = {"drape": drape, "stack": stack, "twist": twist}
"""Scene builders by name; each takes the requested number of cloth triangles."""


def build_scene(name: str, triangles: int | None = None) -> Scene:
    """Build a built-in scene.

    Args:
        name: one of :data:`SCENES`.
        triangles: requested cloth triangles (the result is within a few percent); default
            :data:`DEFAULT_TRIANGLES`.

    Raises:
        InputError: unknown scene or a bad triangle count.
    """
    if name not in SCENES:
        raise InputError("argument", "scene", f"unknown scene {name!r}", f"use one of {', '.join(SCENES)}")
    if triangles is None:
        triangles = DEFAULT_TRIANGLES[name]
    if isinstance(triangles, bool) or not isinstance(triangles, int | np.integer) or triangles < MIN_TRIANGLES:
        raise InputError("argument", "triangles", f"{triangles!r} is not an integer >= {MIN_TRIANGLES}",
                         f"pass --triangles {MIN_TRIANGLES} or more")
    check_fits(int(triangles) * SIMULATION_BYTES_PER_TRIANGLE, what=f"a {name} scene of {int(triangles):,} triangles",
               source="argument", field="--triangles", fix="pass fewer --triangles")
    return SCENES[name](int(triangles))
