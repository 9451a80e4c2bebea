"""The paper's garment benchmarks on a skinned mannequin: ``kungfu``, ``falling``, ``dance``.

The paper's Andy (kung-fu, 127K triangles), Falling (172K) and Bishop (swing dance, 124K) use
artist-made garments and motion-captured characters that are not public. These are procedural
stand-ins with the same cloth resolution and the same kind of collision work (several garments,
several panels each, layered, on a body moving fast). The body is the skeleton and motions of
:func:`pscc.scenes.body.humanoid` dressed as one smooth, closed, skinned surface
(:func:`pscc.scenes.mannequin.mannequin`).

**Garments are sewn from patterns** (:mod:`pscc.scenes.patterns`). Each garment piece
(:class:`GarmentPiece`) is a tube of cloth around a body part (torso, pelvis, a leg, an arm) cut
into flat pattern panels: front and back panels sewn at the side seams (shirt, robe, vest, skirt),
front and back leg panels sewn at the inseam and outseam (trousers), one sleeve panel sewn into a
tube at its underarm seam; a vest's, robe's or bolero's front is two panels left open between them.
Each panel's rest shape is its flat pattern (the exact development of the cone it is wrapped on), so
it starts unstrained; the seams start closed, vertex on vertex, and are stitches of the scene (stiff
zero-length springs and hard constraints: see docs/simulator.md). Each panel's top edge is
**anchored** to one body part (a :class:`pscc.sim.obstacles.Handle` moving rigidly with the part's
joint): it stands in for the waistbands, collars and shoulder seams that hold real garments on a
body. Pieces are fitted 1.5 cm off the body and layered 5-8 mm apart; measured at t = 0 the cloth is at
least 6 mm from the mannequin (where a straight trouser leg passes the thigh's fillet) and the closest
vertices of two pieces are 7 mm apart.

Units: metres, seconds. See ``docs/scenes.md`` for every parameter and why it was chosen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pscc.errors import InputError
from pscc.scenes.body import Body, EasedMotion, arm_direction, elbow_axis, humanoid, spin
from pscc.scenes.mannequin import mannequin
from pscc.scenes.patterns import Panel, Wrap, mesh_panel, seam_stitches
from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.obstacles import Handle
from pscc.sim.scene import Scene

# ---------------------------------------------------------------------------------------------- pieces


@dataclass(frozen=True)
class GarmentPiece:
    """One part of a garment: a tube of cloth around a body part, sewn from pattern panels.

    The tube lies on ``wrap`` between the axis fractions ``top_f`` and ``bottom_f``. It is cut into
    panels at ``seams`` (3-D directions from the axis: each names the arc position farthest along
    it) and, when ``opening`` > 0, left open over that width [m] around ``opening_toward`` (the front
    of a vest or robe). Consecutive panels are sewn along their shared seam line; a tube with one
    seam and no opening is a single panel sewn to itself (a sleeve). The panels' top edges are
    anchored to the body part ``anchor``.

    Attributes:
        name: label; the panels are named ``"{name} {i}"``.
        wrap: the cone the panels are cut from.
        seams: seam directions.
        opening_toward: direction of the middle of the opening.
        opening: width of the opening [m] (0: closed).
        anchor: body part whose joint carries the top edges (``None``: free).
        top_f: axis fraction of the top edge.
        bottom_f: axis fraction of the bottom edge.
    """

    name: str
    wrap: Wrap
    seams: tuple[tuple[float, float, float], ...]
    opening_toward: tuple[float, float, float] = (0.0, 1.0, 0.0)
    opening: float = 0.0
    anchor: str | None = None
    top_f: float = 0.0
    bottom_f: float = 1.0

    def panels(self) -> tuple[list[Panel], list[tuple[int, int]]]:
        """The pattern panels, left to right around the axis, and the sewn seams as ``(i, j)``: the
        right seam line of panel ``i`` is sewn to the left one of panel ``j``."""
        wrap = self.wrap
        perimeter = wrap.perimeter
        cuts = sorted({round(wrap.arc_toward(d), 9) for d in self.seams})
        gap = None
        if self.opening > 0.0:
            middle = wrap.arc_toward(self.opening_toward)
            half = 0.5 * self.opening
            gap = ((middle - half) % perimeter, (middle + half) % perimeter)
            cuts = sorted(set(cuts) | {round(gap[0], 9), round(gap[1], 9)})
        if not cuts:
            raise InputError(self.name, "seams", "a tube needs at least one seam or an opening",
                             "give one or more seam directions")
        intervals = list(zip(cuts, cuts[1:] + [cuts[0] + perimeter], strict=True))
        kept = [gap is None or not _within(0.5 * (left + right) % perimeter, gap) for left, right in intervals]
        panels, index = [], {}
        for k, (left, right) in enumerate(intervals):
            if kept[k]:
                index[k] = len(panels)
                panels.append(Panel(f"{self.name} {len(panels)}", wrap, left, right, self.top_f, self.bottom_f))
        count = len(intervals)
        sewn = [(index[k], index[(k + 1) % count]) for k in range(count) if kept[k] and kept[(k + 1) % count]]
        return panels, sewn


def _within(s: float, gap: tuple[float, float]) -> bool:
    """Whether arc length ``s`` lies inside the (possibly wrapping) arc interval ``gap``."""
    a, b = gap
    return a <= s <= b if a <= b else (s >= a or s <= b)


@dataclass
class GarmentMesh:
    """The meshed panels of a set of garment pieces, ready for a :class:`pscc.sim.scene.Scene`.

    Attributes:
        vertices: (n, 3) float32 positions [m].
        faces: (m, 3) int32 triangles.
        rest: (n, 2) float32 pattern coordinates, panels laid out side by side [m].
        object_ids: (m,) int32 piece index of each triangle: a piece's panels, sewn into one surface, are
            one cloth object (so the normal-cone certificate may treat its closed seams as interior).
        stitches: (s, 4) float64 rows ``(i, j, j, 0)`` of the sewn seams.
        anchors: ``(vertex ids, body part)`` of each anchored panel's top edge.
        panel_names: one name per panel.
        panel_ids: (m,) int32 panel index of each triangle.
    """

    vertices: np.ndarray
    faces: np.ndarray
    rest: np.ndarray
    object_ids: np.ndarray
    stitches: np.ndarray
    anchors: list[tuple[np.ndarray, str]]
    panel_names: list[str]
    panel_ids: np.ndarray


def sew_pieces(pieces: list[GarmentPiece], cell: float) -> GarmentMesh:
    """Mesh every panel of ``pieces`` with cells of about ``cell`` [m] and sew their seams."""
    vertices, faces, rest, objects, panel_ids, stitches, anchors, names = [], [], [], [], [], [], [], []
    offset = 0
    layout_x = 0.0
    for piece_index, piece in enumerate(pieces):
        panels, sewn = piece.panels()
        meshes = [mesh_panel(panel, cell) for panel in panels]
        starts = []
        for panel, mesh in zip(panels, meshes, strict=True):
            starts.append(offset)
            flat = mesh.rest.astype(np.float64)
            flat = flat - [flat[:, 0].min() - layout_x, flat[:, 1].min()]
            layout_x = float(flat[:, 0].max()) + 0.05  # the next pattern piece 5 cm to the right
            vertices.append(mesh.vertices)
            faces.append(mesh.faces + offset)
            rest.append(flat.astype(np.float32))
            objects.append(np.full(mesh.faces.shape[0], piece_index, dtype=np.int32))
            panel_ids.append(np.full(mesh.faces.shape[0], len(names), dtype=np.int32))
            names.append(panel.name)
            if piece.anchor is not None:
                anchors.append((mesh.top_edge + offset, piece.anchor))
            offset += mesh.vertices.shape[0]
        positions = np.concatenate(vertices)
        for i, j in sewn:
            stitches.append(seam_stitches(meshes[i].right_seam + starts[i], meshes[j].left_seam + starts[j],
                                          positions))
    return GarmentMesh(np.concatenate(vertices), np.concatenate(faces).astype(np.int32),
                       np.concatenate(rest), np.concatenate(objects),
                       np.concatenate(stitches) if stitches else np.zeros((0, 4)), anchors, names,
                       np.concatenate(panel_ids))


def _cell_for(pieces: list[GarmentPiece], triangles: int) -> float:
    """Cell size giving about ``triangles`` triangles over all panels (within a few per cent)."""
    area = 0.0
    for piece in pieces:
        for panel in piece.panels()[0]:
            corners = panel.wrap.develop(np.linspace(panel.s_left, panel.s_right, 257), np.full(257, panel.top_f))
            bottom = panel.wrap.develop(np.linspace(panel.s_right, panel.s_left, 257), np.full(257, panel.bottom_f))
            outline = np.concatenate([corners, bottom])
            x, y = outline[:, 0], outline[:, 1]
            area += 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    cell = math.sqrt(area / (triangles * math.sqrt(3.0) / 4.0))
    for _ in range(2):
        count = sum(mesh_panel(panel, cell).faces.shape[0] for piece in pieces for panel in piece.panels()[0])
        cell *= math.sqrt(count / triangles)
    return cell


def _garment_scene(name: str, description: str, body: Body, garments: dict[str, list[GarmentPiece]], scale: float,
                   frame_time: float, steps_per_frame: int, material: ClothMaterial | None = None) -> Scene:
    """Mesh and sew every garment's panels (one object id per piece), anchor their top edges and add the
    skinned mannequin (:func:`pscc.scenes.mannequin.mannequin`) as the one obstacle."""
    from pscc.scenes.paper import PAPER_TRIANGLES, check_scale

    scale = check_scale(name, scale)
    for joint, (rotation, translation) in body.pose(0.0).items():
        if not (np.allclose(rotation, np.eye(3), atol=1e-9) and np.allclose(translation, 0.0, atol=1e-9)):
            raise InputError(name, f"animation[{joint}]", "the pose at t = 0 is not the rest pose",
                             "start every track at the identity (garments are fitted to the rest pose)")
    pieces = [p for group in garments.values() for p in group]
    cell = _cell_for(pieces, round(scale * PAPER_TRIANGLES[name]))
    sewn = sew_pieces(pieces, cell)
    handles = [Handle(ids, motion=body.motion(part), name=f"{sewn.panel_names[k]} anchor")
               for k, (ids, part) in enumerate(sewn.anchors)]
    body_cell = min(0.02, max(0.01, 1.2 * cell))
    return Scene(
        name=name, description=description,
        vertices=sewn.vertices, faces=sewn.faces, rest=sewn.rest, object_ids=sewn.object_ids,
        material=material if material is not None else ClothMaterial(),
        solver=SolverConfig(),
        handles=handles,
        obstacles=[mannequin(body, cell=body_cell)],
        stitches=sewn.stitches,
        frame_time=frame_time, steps_per_frame=steps_per_frame,
    )


# ---------------------------------------------------------------------------------------------- shared garments

_UP = (0.0, 0.0, 1.0)
_DOWN = (0.0, 0.0, -1.0)
_FRONT = (0.0, 1.0, 0.0)
_LEFT = (1.0, 0.0, 0.0)
_RIGHT = (-1.0, 0.0, 0.0)
_SIDE_SEAMS = (_LEFT, _RIGHT)
_TORSO_HALF, _TORSO_RADIUS = 0.08, 0.10  # the humanoid's torso slab (stadium cross-section)
_CLEARANCE = 0.015  # body to first layer
_LAYER = 0.008  # between layers


def _torso_piece(name: str, top: float, bottom: float, flare: float, offset: float, opening: float,
                 reference_top: float = 1.29) -> GarmentPiece:
    """Front and back panels around the torso sewn at the sides (the front cut in two when open),
    anchored to it at ``top``.

    All torso layers share one cone: at height z the cross-section is stadium(0.08 l, (0.115 + offset) l)
    with l = 1 + flare (reference_top - z) / 0.37, so a layer with a larger ``offset`` stays outside one
    with a smaller offset by at least the difference.
    """

    def scale(z: float) -> float:
        return 1.0 + flare * (reference_top - z) / 0.37

    base = _TORSO_RADIUS + _CLEARANCE + offset
    wrap = Wrap((0.0, 0.0, top), (0.0, 0.0, bottom), half_length=_TORSO_HALF * scale(top), radius=base * scale(top),
                end_scale=scale(bottom) / scale(top))
    return GarmentPiece(name, wrap, _SIDE_SEAMS, opening_toward=_FRONT, opening=opening, anchor="torso")


def _sleeve(body: Body, side: str, name: str, radius: float, begin: float, end: float, flare: float) -> GarmentPiece:
    """A sleeve around the upper arm from ``begin`` to ``end`` metres past the shoulder pivot: one panel
    sewn into a tube along its underarm seam."""
    shoulder = np.asarray(next(j.pivot for j in body.joints if j.name == f"shoulder_{side}"))
    direction = arm_direction(side)
    wrap = Wrap(tuple(shoulder + begin * direction), tuple(shoulder + end * direction), half_length=0.0,
                radius=radius, end_scale=flare, long_axis=(0.0, 1.0, 0.0))
    return GarmentPiece(name, wrap, (_DOWN,), anchor=f"upper_arm_{side}")


def _leg(body: Body, side: str, name: str, top: float, bottom: float) -> GarmentPiece:
    """A trouser leg around thigh and shin from height ``top`` to ``bottom``, anchored to the thigh:
    front and back panels sewn along the inseam and the outseam."""
    thigh, shin = body.parts[f"thigh_{side}"], body.parts[f"shin_{side}"]
    hip = np.asarray(thigh.core[0])
    ankle = np.asarray(shin.core[1])

    def axis_at(z: float) -> np.ndarray:
        return hip + (z - hip[2]) / (ankle[2] - hip[2]) * (ankle - hip)

    top_radius = thigh.radius + _CLEARANCE
    bottom_radius = shin.radius + _CLEARANCE
    wrap = Wrap(tuple(axis_at(top)), tuple(axis_at(bottom)), half_length=0.0, radius=top_radius,
                end_scale=bottom_radius / top_radius, long_axis=(0.0, 1.0, 0.0))
    return GarmentPiece(name, wrap, _SIDE_SEAMS, anchor=f"thigh_{side}")


def _pelvis_piece(name: str, top: float, bottom: float, radius: float, flare: float,
                  opening: float = 0.0) -> GarmentPiece:
    """Front and back panels around the pelvis and hips sewn at the sides, anchored to the pelvis at ``top``
    (a waistband)."""
    wrap = Wrap((0.0, 0.0, top), (0.0, 0.0, bottom), half_length=0.06, radius=radius, end_scale=flare)
    return GarmentPiece(name, wrap, _SIDE_SEAMS, opening_toward=_FRONT, opening=opening, anchor="pelvis")


def _x(angle: float) -> np.ndarray:
    return np.array([math.radians(angle), 0.0, 0.0])


def _y(angle: float) -> np.ndarray:
    return np.array([0.0, math.radians(angle), 0.0])


def _z(angle: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.radians(angle)])


def _keys(times: list[float], poses: list[dict[str, np.ndarray]], joints: tuple[str, ...]) -> dict[str, Callable]:
    """Rotation tracks per joint from keyframe poses (rotation vectors; joints missing from a pose are 0)."""
    tracks = {}
    for joint in joints:
        rotations = np.stack([pose.get(joint, np.zeros(3)) for pose in poses])
        tracks[joint] = EasedMotion(times, rotations=rotations).rotation
    return tracks


def _abduct(side: str, angle: float) -> np.ndarray:
    """Rotation vector raising arm or leg ``side`` sideways by ``angle`` degrees (negative: towards the body)."""
    return _y(-angle if side == "l" else angle)


def _elbow(side: str, angle: float) -> np.ndarray:
    return elbow_axis(side) * math.radians(angle)


# ---------------------------------------------------------------------------------------------- kungfu

KUNGFU_DURATION: float = 3.4
"""Length of the kung-fu animation [s] (the body holds the last pose afterwards)."""


def kungfu_body() -> Body:
    """The kung-fu animation: guard, right front kick, left punch with a torso twist, left side kick.

    Keyframes (s): 0 rest; 0.5 guard (fists up: shoulders forward 35 deg, elbows bent 85 deg,
    knees bent 25 deg); 1.0 right knee chambered (hip 80 deg forward, knee 85 deg); 1.3 front kick
    (knee straight); 1.7 back to guard; 2.1 left punch (torso turned 35 deg right, left arm forward
    80 deg and straight); 2.6 left side kick (hip 55 deg sideways, torso leaning 12 deg right);
    3.0 guard; 3.4 rest.
    """
    joints = ("spine", "hip_l", "knee_l", "hip_r", "knee_r", "shoulder_l", "elbow_l", "shoulder_r", "elbow_r")
    guard = {"shoulder_l": _x(35.0), "shoulder_r": _x(35.0), "elbow_l": _elbow("l", 85.0),
             "elbow_r": _elbow("r", 85.0), "hip_l": _x(12.0), "knee_l": _x(-25.0), "hip_r": _x(12.0),
             "knee_r": _x(-25.0)}
    chamber = {**guard, "hip_r": _x(80.0), "knee_r": _x(-85.0), "spine": _x(-8.0)}
    kick = {**guard, "hip_r": _x(80.0), "knee_r": _x(-3.0), "spine": _x(-12.0)}
    punch = {**guard, "spine": _z(-35.0), "shoulder_l": _x(80.0), "elbow_l": _elbow("l", 5.0),
             "shoulder_r": _x(25.0), "elbow_r": _elbow("r", 90.0)}
    side_kick = {**guard, "hip_l": _abduct("l", 55.0), "knee_l": _x(-10.0), "spine": _y(12.0) + _z(-10.0)}
    rest: dict[str, np.ndarray] = {}
    times = [0.0, 0.5, 1.0, 1.3, 1.7, 2.1, 2.6, 3.0, 3.4]
    poses = [rest, guard, chamber, kick, guard, punch, side_kick, guard, rest]
    return humanoid(_keys(times, poses, joints))


def kungfu_garments(body: Body) -> dict[str, list[GarmentPiece]]:
    """The pieces of trousers, shirt and vest of ``kungfu``, fitted to the body's rest pose, by garment."""
    return {
        "trousers": [_pelvis_piece("trousers hips", 1.00, 0.66, 0.125, 1.0),
                     _leg(body, "l", "trousers left leg", 0.70, 0.14),
                     _leg(body, "r", "trousers right leg", 0.70, 0.14)],
        "shirt": [_torso_piece("shirt body", 1.29, 0.90, 0.19, 0.0, 0.0),
                  _sleeve(body, "l", "shirt left sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0),
                  _sleeve(body, "r", "shirt right sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0)],
        "vest": [_torso_piece("vest", 1.27, 0.98, 0.19, _LAYER, 0.10)],
    }


def kungfu(scale: float) -> Scene:
    """Andy stand-in: a body in trousers, a shirt and a vest practising kung-fu (127K triangles at scale 1).

    Garments (7 pieces, one object id each, 13 pattern panels, all anchored at their top edge):

    * trousers: a hip piece (front and back panels sewn at the sides, stadium cylinder 0.125 m radius
      around the pelvis, z 1.00 -> 0.66, anchored to the pelvis) over two tapered legs (front and back
      panels sewn at the inseam and outseam; thigh radius + 1.5 cm -> shin radius + 1.5 cm, z 0.70 ->
      0.14, anchored to the thighs 9 cm below the hip pivot so a 90 degree kick keeps the anchor clear
      of the pelvis);
    * shirt: a torso cone (front and back panels sewn at the sides; 1.5 cm off the torso at the armpit,
      z 1.29 -> 0.90, flaring so its hem covers the hip piece 5 mm outside it) and two short sleeves
      (one panel each sewn at the underarm; upper arm radius + 1.5 cm, 4 -> 22 cm past the shoulder
      pivot);
    * vest: a torso cone 8 mm outside the shirt, z 1.27 -> 0.98: a back panel and two front panels
      sewn at the sides, open in front (10 cm).

    Motion: :func:`kungfu_body` (3.4 s). Time: 25 frames/s, 8 steps per frame (dt = 1/200 s, the
    step I-Cloth reports for Andy; the paper's "1/25" is the character's frame rate).
    """
    body = kungfu_body()
    garments = kungfu_garments(body)
    return _garment_scene("kungfu", "kung-fu kicks and twists in trousers, shirt and vest (paper: Andy)", body,
                          garments, scale, frame_time=1.0 / 25.0, steps_per_frame=8)


# ---------------------------------------------------------------------------------------------- falling

FALLING_DURATION: float = 1.6
"""Length of the falling animation [s]."""


def falling_body() -> Body:
    """The falling animation: struck at 0.15 s, the body doubles over, then falls 1.2 m backwards.

    Root translation: 1.2 m down and 0.3 m back between 0.15 s and 0.95 s (eased; peak downward
    acceleration 11 m/s^2, a little more than gravity, so the robe lifts off the body). Root
    rotation: tipping 70 degrees backwards over 0.15 -> 1.2 s. Keyframes (s) of the limbs: 0 rest;
    0.3 doubled over (torso 25 deg forward, arms forward 50 deg); 0.7 flailing (arms up 100 deg
    sideways, hips 45 deg forward, knees 40 deg); 1.1 landing pose (arms 70 deg sideways, hips
    70 deg, knees 60 deg); 1.6 relaxed.
    """
    joints = ("spine", "hip_l", "knee_l", "hip_r", "knee_r", "shoulder_l", "elbow_l", "shoulder_r", "elbow_r")
    rest: dict[str, np.ndarray] = {}
    doubled = {"spine": _x(-25.0), "shoulder_l": _x(50.0), "shoulder_r": _x(50.0), "elbow_l": _elbow("l", 40.0),
               "elbow_r": _elbow("r", 40.0), "hip_l": _x(15.0), "hip_r": _x(15.0), "knee_l": _x(-15.0),
               "knee_r": _x(-15.0)}
    flailing = {"spine": _x(5.0), "shoulder_l": _abduct("l", 55.0) + _x(20.0),
                "shoulder_r": _abduct("r", 55.0) + _x(20.0), "elbow_l": _elbow("l", 20.0),
                "elbow_r": _elbow("r", 20.0), "hip_l": _x(45.0), "hip_r": _x(40.0), "knee_l": _x(-40.0),
                "knee_r": _x(-35.0)}
    landing = {"spine": _x(-10.0), "shoulder_l": _abduct("l", 25.0), "shoulder_r": _abduct("r", 25.0),
               "elbow_l": _elbow("l", 30.0), "elbow_r": _elbow("r", 30.0), "hip_l": _x(70.0), "hip_r": _x(65.0),
               "knee_l": _x(-60.0), "knee_r": _x(-55.0)}
    relaxed = {"spine": _x(-5.0), "shoulder_l": _abduct("l", 10.0), "shoulder_r": _abduct("r", 10.0),
               "elbow_l": _elbow("l", 15.0), "elbow_r": _elbow("r", 15.0), "hip_l": _x(50.0), "hip_r": _x(45.0),
               "knee_l": _x(-30.0), "knee_r": _x(-30.0)}
    tracks = _keys([0.0, 0.3, 0.7, 1.1, 1.6], [rest, doubled, flailing, landing, relaxed], joints)
    tracks["pelvis"] = EasedMotion([0.0, 0.15, 1.2], rotations=np.stack([_x(0.0), _x(0.0), _x(70.0)])).rotation
    drop = EasedMotion([0.0, 0.15, 0.95], translations=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0],
                                                                  [0.0, -0.3, -1.2]])).translation
    return humanoid(tracks, drop)


def falling_garments(body: Body) -> dict[str, list[GarmentPiece]]:
    """The pieces of the robe of ``falling``, fitted to the body's rest pose, by garment."""
    return {
        "robe": [_torso_piece("robe body", 1.29, 0.25, 0.7 * 0.37 / 1.04, 0.005, 0.06),
                 _sleeve(body, "l", "robe left sleeve", 0.045 + 0.025, 0.04, 0.30, 1.5),
                 _sleeve(body, "r", "robe right sleeve", 0.045 + 0.025, 0.04, 0.30, 1.5)],
    }


def falling(scale: float) -> Scene:
    """Falling stand-in: a man in a robe falls fast under strikes (172K triangles at scale 1).

    Robe (3 pieces, 5 pattern panels, anchored at their top edge): a body cone (a back panel and two
    front panels sewn at the sides, open in front over 6 cm) from the chest (z 1.29, 1.5 cm off the
    torso, anchored to it) flaring 1.7 times to the shins (z 0.25), and two bell sleeves (one panel
    each sewn at the underarm; upper arm radius + 2.5 cm, 4 -> 30 cm past the shoulder pivot, flaring
    1.5 times, so the forearm moves freely inside).

    Motion: :func:`falling_body` (1.6 s; 1.2 m drop in the first second). Time: 30 frames/s (the
    paper's "1/30"), 6 steps per frame (dt = 1/180 s: the body moves up to 2.3 cm per step).
    """
    body = falling_body()
    garments = falling_garments(body)
    return _garment_scene("falling", "a man in a robe falls fast under strikes (paper: Falling)", body, garments,
                          scale, frame_time=1.0 / 30.0, steps_per_frame=6)


# ---------------------------------------------------------------------------------------------- dance

DANCE_DURATION: float = 2.4
"""Length of the dance animation [s]."""


def dance_body() -> Body:
    """The swing-dance animation: a step, then a full turn under the raised right arm.

    The root turns once about the vertical axis between 0.6 s and 1.8 s (eased: peak 7.9 rad/s).
    Keyframes (s) of the limbs: 0 rest; 0.6 right arm raised (110 deg sideways, elbow 30 deg), left
    hand on the hip side (arm 30 deg sideways, elbow 60 deg), right leg stepping (hip 20 deg
    forward, knee 25 deg); 1.2 legs crossed a little (left hip 15 deg forward, knee 20 deg, torso
    leaning 8 deg left); 1.8 arm still raised, legs back; 2.4 rest.
    """
    joints = ("spine", "hip_l", "knee_l", "hip_r", "knee_r", "shoulder_l", "elbow_l", "shoulder_r", "elbow_r")
    rest: dict[str, np.ndarray] = {}
    raised = {"shoulder_r": _abduct("r", 65.0), "elbow_r": _elbow("r", 30.0), "shoulder_l": _abduct("l", -15.0)
              + _x(10.0), "elbow_l": _elbow("l", 60.0), "hip_r": _x(20.0), "knee_r": _x(-25.0)}
    crossed = {**raised, "hip_r": _x(0.0), "knee_r": _x(0.0), "hip_l": _x(15.0), "knee_l": _x(-20.0),
               "spine": _y(-8.0)}
    back = {**raised, "hip_r": _x(0.0), "knee_r": _x(0.0)}
    tracks = _keys([0.0, 0.6, 1.2, 1.8, 2.4], [rest, raised, crossed, back, rest], joints)
    tracks["pelvis"] = spin(_UP, 1.0, 0.6, 1.2)
    return humanoid(tracks)


def dance_garments(body: Body) -> dict[str, list[GarmentPiece]]:
    """The pieces of skirt, shirt and bolero of ``dance``, fitted to the body's rest pose, by garment."""
    return {
        "skirt": [_pelvis_piece("skirt", 1.00, 0.45, 0.125, 1.8)],
        "shirt": [_torso_piece("shirt body", 1.29, 1.04, 0.0, 0.0, 0.0),
                  _sleeve(body, "l", "shirt left sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0),
                  _sleeve(body, "r", "shirt right sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0)],
        "bolero": [_torso_piece("bolero", 1.27, 1.12, 0.0, _LAYER, 0.12)],
    }


def dance(scale: float) -> Scene:
    """Bishop stand-in: a swing dancer in a skirt, a shirt and a bolero spins (124K triangles at scale 1).

    Garments (5 pieces, 9 pattern panels, anchored at their top edge): a flared skirt (front and back
    panels, pieces of an annulus, sewn at the sides; stadium cone from the pelvis, z 1.00, radius
    0.125, to z 0.45, scale 1.8); a shirt (front and back panels, torso cylinder 1.5 cm off the
    torso, z 1.29 -> 1.04, ending above the skirt; short sleeves as in ``kungfu``); a bolero (torso
    cylinder 8 mm outside the shirt, z 1.27 -> 1.12, a back panel and two front panels, open in
    front over 12 cm).

    Motion: :func:`dance_body` (2.4 s). Time: 30 frames/s (the paper's "1/30"), 4 steps per frame
    (dt = 1/120 s, close to I-Cloth's 1/100 s for Bishop and a whole number of steps per frame).
    """
    body = dance_body()
    garments = dance_garments(body)
    return _garment_scene("dance", "a swing dancer spins in skirt, shirt and bolero (paper: Bishop)", body, garments,
                          scale, frame_time=1.0 / 30.0, steps_per_frame=4)


GARMENT_BODIES: dict[str, Callable[[], Body]] = {"kungfu": kungfu_body, "falling": falling_body, "dance": dance_body}
"""The animated body of each garment scene."""

GARMENT_PIECES: dict[str, Callable[[Body], list[GarmentPiece]]] = {
    name: (lambda body, fn=fn: [p for group in fn(body).values() for p in group])
    for name, fn in (("kungfu", kungfu_garments), ("falling", falling_garments), ("dance", dance_garments))}
"""Every garment piece of each garment scene, in the scene's order, for a body (its rest pose)."""

GARMENT_DURATIONS: dict[str, float] = {"kungfu": KUNGFU_DURATION, "falling": FALLING_DURATION,
                                       "dance": DANCE_DURATION}
"""Length of each garment scene's animation [s]."""
