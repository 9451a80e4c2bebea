"""The paper's benchmark scenes (``pscc.scenes.paper``, ``pscc.scenes.garments``) and the articulated body.

Every scene at its smallest scale: builds with the requested number of cloth triangles, starts free of
intersections (the solver accepts it and ipctk's ``has_intersections`` agrees) and simulates two frames
free of intersections. The body: forward kinematics moves a joint's descendants only and part meshes are
closed. Garment scenes: sewn from pattern panels whose seams start closed, on the skinned mannequin, with
the cloth and its anchors clear of the body.
"""

from __future__ import annotations

import math

import ipctk
import numpy as np
import pytest
from scipy.spatial import cKDTree

from pscc.bench.oracle import cloth_crossings
from pscc.errors import InputError
from pscc.scenes.body import EasedMotion, Joint, humanoid, rounded_core_mesh, spin
from pscc.scenes.garments import GARMENT_BODIES, GARMENT_DURATIONS, GARMENT_PIECES, sew_pieces
from pscc.scenes.mannequin import SkinnedMesh, surface_field
from pscc.scenes.paper import (
    MAX_SCALE,
    MIN_TRIANGLES,
    PAPER_SCENES,
    PAPER_TRIANGLES,
    build_paper_scene,
    check_scale,
    min_scale,
)
from pscc.sim.obstacles import rotation_from_axis_angle
from pscc.sim.scene import Scene
from pscc.sim.simulation import Simulation

NAMES = list(PAPER_SCENES)


def _has_intersections(faces: np.ndarray, positions: np.ndarray, scene: Scene) -> bool:
    """ipctk finds an edge-face crossing that involves the cloth and that no stitch joins (a skinned body may
    fold into itself at a bent joint; the cloth never may)."""
    if scene.stitches is None and not any(isinstance(o, SkinnedMesh) for o in scene.obstacles):
        mesh = ipctk.CollisionMesh(positions.astype(np.float64), ipctk.edges(faces), faces)
        return ipctk.has_intersections(mesh, positions.astype(np.float64))
    return cloth_crossings(positions, faces, scene.vertices.shape[0], scene.faces.shape[0], scene.stitches).size > 0


# ---------------------------------------------------------------------------------------------- sizes


def test_registry_and_paper_counts() -> None:
    assert set(PAPER_SCENES) == set(PAPER_TRIANGLES) == {"sphere", "twisting", "flag", "sphere-drop", "kungfu",
                                                        "falling", "dance"}
    assert PAPER_TRIANGLES["sphere"] == PAPER_TRIANGLES["twisting"] == 200_000
    assert PAPER_TRIANGLES["flag"] == 80_000 and PAPER_TRIANGLES["sphere-drop"] == 1_000_000
    assert (PAPER_TRIANGLES["kungfu"], PAPER_TRIANGLES["falling"], PAPER_TRIANGLES["dance"]) == (127_000, 172_000,
                                                                                               124_000)
    for name in NAMES:
        assert min_scale(name) * PAPER_TRIANGLES[name] == pytest.approx(MIN_TRIANGLES)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, MAX_SCALE * 1.01, "x", None, True])
def test_scale_is_validated(bad: object) -> None:
    with pytest.raises(InputError) as error:
        check_scale("flag", bad)  # type: ignore[arg-type]
    assert error.value.field == "--scale"
    with pytest.raises(InputError):
        PAPER_SCENES["kungfu"](bad)  # type: ignore[arg-type]


def test_scale_bounds_and_unknown_scene() -> None:
    assert check_scale("flag", min_scale("flag")) == min_scale("flag")
    assert check_scale("flag", "1") == 1.0
    with pytest.raises(InputError) as error:
        check_scale("flag", min_scale("flag") * 0.99)
    assert "5000" in error.value.fix
    with pytest.raises(InputError):
        min_scale("andy")
    with pytest.raises(InputError):
        build_paper_scene("andy")


# ---------------------------------------------------------------------------------------------- scenes


@pytest.mark.parametrize("name", NAMES)
def test_scene_builds_intersection_free_and_simulates_two_frames(name: str) -> None:
    scale = min_scale(name)
    scene = PAPER_SCENES[name](scale)
    triangles = scene.faces.shape[0]
    assert abs(triangles - scale * PAPER_TRIANGLES[name]) <= 0.1 * scale * PAPER_TRIANGLES[name]
    assert scene.vertices.shape == (scene.rest.shape[0], 3) and scene.rest.shape[1] == 2
    assert scene.object_ids.shape == (triangles,) and scene.vertices.dtype == np.float32
    assert scene.faces.dtype == np.int32 and scene.object_ids.dtype == np.int32
    # Every cloth piece starts unstrained: its rest edge lengths are its 3-D edge lengths (pattern panels
    # wrapped on a curved surface: up to the chord of a curved edge, 1 - chord / arc ~ (cell / radius)^2 / 24,
    # 2 % for the 4 cm cells of the smallest scale on a 6 cm sleeve).
    edges = np.unique(np.sort(np.concatenate([scene.faces[:, [0, 1]], scene.faces[:, [1, 2]],
                                              scene.faces[:, [2, 0]]]), axis=1), axis=0)
    length_3d = np.linalg.norm(scene.vertices[edges[:, 0]] - scene.vertices[edges[:, 1]], axis=1)
    length_rest = np.linalg.norm(scene.rest[edges[:, 0]] - scene.rest[edges[:, 1]], axis=1)
    np.testing.assert_allclose(length_3d, length_rest, rtol=0.025 if name in GARMENT_BODIES else 1e-4, atol=1e-6)
    if scene.stitches is not None:  # sewn seams start closed
        rows = scene.stitches.astype(np.int64)
        assert np.abs(scene.vertices[rows[:, 0]] - scene.vertices[rows[:, 1]]).max() < 1e-5

    simulation = Simulation(scene, device="cpu")  # raises InputError on an intersecting initial state
    solver = simulation.solver
    faces = solver.collision_faces
    assert not _has_intersections(faces, simulation.state.positions.numpy(), scene)
    initial = scene.vertices.astype(np.float64)
    for frame in range(2):
        stats = simulation.step_frame()
        positions = simulation.state.positions.numpy()
        assert np.all(np.isfinite(positions))
        assert not _has_intersections(faces, positions, scene), f"{name}: intersection after frame {frame + 1}"
        for handle in scene.handles:
            rotation, translation = handle.transform(simulation.time)
            np.testing.assert_allclose(positions[handle.vertices], initial[handle.vertices] @ rotation.T + translation,
                                       atol=1e-5)
        assert stats["counts"]["halvings"] == 0


@pytest.mark.parametrize("name", NAMES)
def test_motions_start_at_rest(name: str) -> None:
    scene = PAPER_SCENES[name](min_scale(name))
    eps = 1e-3
    movers = [(o.positions(0.0).astype(np.float64), o.positions(eps).astype(np.float64)) for o in scene.obstacles]
    for handle in scene.handles:
        x = scene.vertices[handle.vertices].astype(np.float64)
        r0, c0 = handle.transform(0.0)
        r1, c1 = handle.transform(eps)
        movers.append((x @ r0.T + c0, x @ r1.T + c1))
    for before, after in movers:
        assert np.abs(after - before).max() / eps < 0.05  # m/s: at rest at t = 0


# ---------------------------------------------------------------------------------------------- body


def test_part_meshes_are_closed_and_on_the_surface() -> None:
    body = humanoid()
    for part in body.parts.values():
        vertices, faces = part.mesh()
        directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        assert np.unique(directed, axis=0).shape[0] == directed.shape[0], part.name  # consistently oriented
        undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
        assert np.all(counts == 2), part.name  # closed: every edge in two faces
        assert vertices.shape[0] - undirected.shape[0] + faces.shape[0] == 2, part.name  # a sphere
        tri = vertices[faces].astype(np.float64)
        volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
        assert volume > 0.0, part.name  # outward
        np.testing.assert_allclose(part.surface_distance(vertices), 0.0, atol=1e-6)
    vertices, faces = rounded_core_mesh(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), 0.1)
    assert np.all(np.isfinite(vertices)) and faces.min() == 0 and faces.max() == vertices.shape[0] - 1


def test_forward_kinematics_moves_children_not_parents() -> None:
    turn = rotation_from_axis_angle(np.array([0.0, 0.4, 0.0]))
    body = humanoid({"shoulder_l": lambda t: turn})
    moved = {"upper_arm_l", "forearm_l"}
    for name in body.parts:
        rotation, translation = body.transform(name, 1.0)
        if name in moved:
            np.testing.assert_allclose(rotation, turn, atol=1e-12)
        else:
            np.testing.assert_allclose(rotation, np.eye(3), atol=1e-12)
            np.testing.assert_allclose(translation, 0.0, atol=1e-12)
    pivot = np.asarray(next(j.pivot for j in body.joints if j.name == "shoulder_l"))
    rotation, translation = body.transform("upper_arm_l", 1.0)
    np.testing.assert_allclose(rotation @ pivot + translation, pivot, atol=1e-12)  # turns about its pivot
    # A child's rotation composes with its parent's: the elbow's pivot follows the shoulder.
    bend = rotation_from_axis_angle(np.array([0.3, 0.0, 0.0]))
    body = humanoid({"shoulder_l": lambda t: turn, "elbow_l": lambda t: bend}, translation=lambda t: np.array(
        [0.0, 0.0, -t]))
    elbow = np.asarray(next(j.pivot for j in body.joints if j.name == "elbow_l"))
    shoulder_r, shoulder_c = body.transform("upper_arm_l", 1.0)
    forearm_r, forearm_c = body.transform("forearm_l", 1.0)
    np.testing.assert_allclose(forearm_r, turn @ bend, atol=1e-12)
    np.testing.assert_allclose(forearm_r @ elbow + forearm_c, shoulder_r @ elbow + shoulder_c, atol=1e-12)
    np.testing.assert_allclose(body.transform("head", 1.0)[1], [0.0, 0.0, -1.0], atol=1e-12)  # root moves all
    assert body.descendants("shoulder_l") == {"shoulder_l", "elbow_l"}


def test_body_rejects_bad_hierarchies() -> None:
    body = humanoid()
    parts = list(body.parts.values())
    with pytest.raises(InputError):
        type(body)([Joint("a", "b", (0, 0, 0)), Joint("b", None, (0, 0, 0))], [])
    with pytest.raises(InputError):
        type(body)(body.joints, parts, {"wrist": lambda t: np.eye(3)})
    with pytest.raises(InputError):
        body.motion("tail")


@pytest.mark.parametrize("name", list(GARMENT_BODIES))
def test_garments_are_sewn_panels_on_the_mannequin_and_keep_clear_of_it(name: str) -> None:
    body = GARMENT_BODIES[name]()
    scene = PAPER_SCENES[name](min_scale(name))
    assert len(scene.obstacles) == 1 and isinstance(scene.obstacles[0], SkinnedMesh)
    # Several panels per garment, every panel sewn to another (or to itself, a sleeve), each piece's panels
    # one cloth object.
    pieces = GARMENT_PIECES[name](body)
    sewn_mesh = sew_pieces(pieces, 0.03)
    panels = len(sewn_mesh.panel_names)
    assert panels >= 2 * len(pieces) - 2 and panels >= 5
    assert int(scene.object_ids.max()) + 1 == len(pieces)
    owner = np.zeros(sewn_mesh.vertices.shape[0], dtype=np.int64)
    owner[sewn_mesh.faces.reshape(-1)] = np.repeat(sewn_mesh.panel_ids, 3)
    rows = sewn_mesh.stitches.astype(np.int64)
    sewn = set(owner[rows[:, 0]].tolist()) | set(owner[rows[:, 1]].tolist())
    assert sewn == set(range(panels))
    assert np.array_equal(np.unique(sewn_mesh.object_ids), np.arange(len(pieces)))
    # The cloth starts at least 5 mm off the mannequin's surface.
    field = surface_field(body)
    assert field(scene.vertices.astype(np.float64)).min() >= 0.005
    # Anchored top edges keep at least 5 mm off the skinned surface over the animation (point-triangle
    # distances to the faces around the 6 nearest skin vertices): an anchor the skin reaches pinches cloth
    # between two scripted surfaces.
    skin = scene.obstacles[0]
    faces_of = [[] for _ in range(skin.rest_vertices.shape[0])]
    for f, tri in enumerate(skin.faces):
        for v in tri:
            faces_of[v].append(f)
    for t in np.linspace(0.0, GARMENT_DURATIONS[name], 9):
        surface = skin.positions(t).astype(np.float64)
        tree = cKDTree(surface)
        for handle in scene.handles:
            rotation, translation = handle.transform(t)
            points = scene.vertices[handle.vertices].astype(np.float64) @ rotation.T + translation
            _, near = tree.query(points, k=6)
            for point, vertices in zip(points, near, strict=True):
                faces = {f for v in vertices for f in faces_of[v]}
                gap = min(ipctk.point_triangle_distance(point, *surface[skin.faces[f]]) for f in faces) ** 0.5
                assert gap >= 0.005, (handle.name, t, gap)


def test_eased_motion_is_smooth_and_starts_at_rest() -> None:
    motion = EasedMotion([0.0, 1.0, 2.0], translations=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]]),
                         rotations=np.array([[0, 0, 0], [0, 0, 1.0], [0, 0, 2.0]]))
    eps = 1e-4
    for t in (0.0, 1.0, 2.0):  # zero velocity at every keyframe (C1 through it)
        before, after = motion(t - eps), motion(t + eps)
        assert np.abs(after[1] - before[1]).max() / (2 * eps) < 1e-3
        assert np.abs(after[0] - before[0]).max() / (2 * eps) < 1e-3
    np.testing.assert_allclose(motion(0.5)[1], [0.5, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(motion(1.0)[0], rotation_from_axis_angle(np.array([0.0, 0.0, 1.0])), atol=1e-12)
    turn = spin((0.0, 0.0, 1.0), 1.0, 0.5, 1.0)
    np.testing.assert_allclose(turn(0.0), np.eye(3), atol=1e-12)
    np.testing.assert_allclose(turn(1.5), np.eye(3), atol=1e-9)
    np.testing.assert_allclose(turn(1.0), rotation_from_axis_angle(np.array([0.0, 0.0, math.pi])), atol=1e-9)
    with pytest.raises(InputError):
        EasedMotion([0.0, 0.0])
