"""The paper's garment benchmarks on a procedural, articulated body: ``kungfu``, ``falling``, ``dance``.

The paper's Andy (kung-fu, 127K triangles), Falling (172K) and Bishop (swing dance, 124K) use
artist-made garments and motion-captured characters that are not public. These are procedural
stand-ins with the same cloth resolution and the same kind of collision work (several garments,
several pieces each, layered, on a body moving fast): the body is
:func:`pscc.scenes.body.humanoid` (11 rigid parts, forward kinematics) and every garment piece is
an open tube or frustum around it.

**Garment pieces** (:class:`TubePiece`): the cross-section is a stadium (a circle when its
half-length is 0) scaled linearly along the piece's axis (a generalised cone; a cylinder when the
scale is constant). The tube is cut open along one line (an opening at least one cell wide: a seam
slit, or a wide front opening for vests and robes) and its rest (material) coordinates are its
exact development into the plane (arc length around and length along for a cylinder, polar
coordinates about the apex for a cone), so each piece starts at rest with zero strain. Pieces are
not stitched to each other: sleeves and legs are separate tubes. Each piece's first row is
**anchored** to one body part (a :class:`pscc.sim.obstacles.Handle` moving rigidly with the part):
it stands in for the shoulder seams, waistbands and cuffs that hold real garments on a body and
that open tubes lack. All pieces start at least 1.2 cm from the body and 5 mm from each other.

Units: metres, seconds. See ``docs/scenes.md`` for every parameter and why it was chosen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pscc.errors import InputError
from pscc.scenes.body import Body, EasedMotion, arm_direction, elbow_axis, humanoid, spin
from pscc.sim.config import ClothMaterial, SolverConfig
from pscc.sim.obstacles import Handle
from pscc.sim.scene import Scene

# ---------------------------------------------------------------------------------------------- pieces


@dataclass(frozen=True)
class TubePiece:
    """One garment piece: an open generalised cone around an axis.

    The cross-section at the axis point ``start`` is a stadium: the points within ``radius`` of a
    segment of half-length ``half_length`` along ``long_axis`` (a circle when the half-length is 0).
    Along the axis it scales linearly to ``end_scale`` times that at ``end``. The tube is open along
    a gap of ``opening`` metres (at least one cell) centred in the direction ``opening_toward``.

    Attributes:
        name: label of the piece.
        start: (3,) axis point of the first row [m].
        end: (3,) axis point of the last row [m].
        half_length: stadium half-length at ``start`` [m] (0 for a circle).
        radius: stadium radius at ``start`` [m].
        end_scale: cross-section scale at ``end`` relative to ``start`` (> 0; 1 = cylinder).
        long_axis: direction of the stadium's segment (projected perpendicular to the axis).
        opening_toward: direction from the axis to the middle of the opening.
        opening: width of the opening at ``start`` [m]; widened to one cell if narrower.
        anchor: body part that carries the first row (``None``: the piece is free).
    """

    name: str
    start: tuple[float, float, float]
    end: tuple[float, float, float]
    half_length: float
    radius: float
    end_scale: float = 1.0
    long_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    opening_toward: tuple[float, float, float] = (0.0, 1.0, 0.0)
    opening: float = 0.0
    anchor: str | None = None

    def _frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        start = np.asarray(self.start, np.float64)
        axis = np.asarray(self.end, np.float64) - start
        length = float(np.linalg.norm(axis))
        ez = axis / length
        ex = np.asarray(self.long_axis, np.float64)
        ex = ex - (ex @ ez) * ez
        if np.linalg.norm(ex) < 1e-9:
            raise InputError(self.name, "long_axis", "is parallel to the tube's axis", "give a transverse direction")
        ex = ex / np.linalg.norm(ex)
        return start, ex, np.cross(ez, ex), ez, length

    def perimeter(self) -> float:
        """Perimeter of the cross-section at ``start`` [m]."""
        return 4.0 * self.half_length + 2.0 * math.pi * self.radius

    def area(self) -> float:
        """Approximate surface area [m^2] (mean perimeter times slant length)."""
        *_, length = self._frame()
        mean_scale = 0.5 * (1.0 + self.end_scale)
        flare = (self.end_scale - 1.0) * (self.radius + self.half_length)
        return mean_scale * self.perimeter() * math.hypot(length, flare)


def _stadium(half_length: float, radius: float, s: np.ndarray) -> np.ndarray:
    """Points (n, 2) at arc lengths ``s`` on a stadium, starting at (0, radius), counter-clockwise."""
    a, r = half_length, radius
    total = 4.0 * a + 2.0 * math.pi * r
    s = np.mod(s, total)
    out = np.zeros((s.shape[0], 2))
    bounds = np.cumsum([a, math.pi * r, 2.0 * a, math.pi * r, a])
    seg = np.searchsorted(bounds, s, side="right")
    seg = np.minimum(seg, 4)
    # 0: top flat (0, r) -> (-a, r); 1: left arc; 2: bottom flat (-a, -r) -> (a, -r); 3: right arc; 4: top flat.
    m = seg == 0
    out[m] = np.stack([-s[m], np.full(m.sum(), r)], axis=1)
    m = seg == 1
    angle = math.pi / 2.0 + (s[m] - bounds[0]) / max(r, 1e-12)
    out[m] = np.stack([-a + r * np.cos(angle), r * np.sin(angle)], axis=1)
    m = seg == 2
    out[m] = np.stack([-a + (s[m] - bounds[1]), np.full(m.sum(), -r)], axis=1)
    m = seg == 3
    angle = -math.pi / 2.0 + (s[m] - bounds[2]) / max(r, 1e-12)
    out[m] = np.stack([a + r * np.cos(angle), r * np.sin(angle)], axis=1)
    m = seg == 4
    out[m] = np.stack([a - (s[m] - bounds[3]), np.full(m.sum(), r)], axis=1)
    return out


def tube_mesh(piece: TubePiece, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mesh a piece with square-ish cells of side about ``cell`` [m].

    Returns:
        ``(vertices, faces, rest, first_row)``: (n, 3) float32 positions, (m, 3) int32 faces (checkerboard
        diagonals as :func:`pscc.mesh.generate.grid_sheet`), (n, 2) float32 rest coordinates (the exact
        development, centred on 0) and the vertex ids of the first row (the anchored end).

    Raises:
        InputError: a non-positive size or scale.
    """
    if not (cell > 0.0 and piece.radius > 0.0 and piece.half_length >= 0.0 and piece.end_scale > 0.0):
        raise InputError(piece.name, "size", "cell, radius and end_scale must be > 0, half_length >= 0",
                         "fix the piece's dimensions")
    start, ex, ey, ez, length = piece._frame()
    perimeter = piece.perimeter()
    mean_scale = 0.5 * (1.0 + piece.end_scale)
    gap = max(piece.opening, cell / mean_scale)
    if gap >= perimeter * 0.9:
        raise InputError(piece.name, "opening", f"{piece.opening} m leaves almost nothing of the {perimeter:.3f} m "
                         "perimeter", "narrow the opening")
    nu = max(6, round(mean_scale * (perimeter - gap) / cell))
    flare = (piece.end_scale - 1.0) * (piece.radius + piece.half_length)
    nv = max(1, round(math.hypot(length, flare) / cell))
    # Arc-length position of the opening's middle: the stadium point farthest along opening_toward.
    probe_s = np.linspace(0.0, perimeter, 720, endpoint=False)
    probe = _stadium(piece.half_length, piece.radius, probe_s)
    toward = np.asarray(piece.opening_toward, np.float64)
    middle = probe_s[int(np.argmax(probe @ np.array([toward @ ex, toward @ ey])))]
    s = middle + gap / 2.0 + (perimeter - gap) * np.arange(nu + 1) / nu
    curve = _stadium(piece.half_length, piece.radius, s)  # (nu + 1, 2) at scale 1
    fraction = np.arange(nv + 1) / nv
    scales = 1.0 + (piece.end_scale - 1.0) * fraction
    heights = length * fraction
    # vertex (i, j) = column i around, row j along; id j * (nu + 1) + i
    local = scales[:, None, None] * curve[None, :, :]  # (nv + 1, nu + 1, 2)
    vertices = (start + local[..., :1] * ex + local[..., 1:] * ey + heights[:, None, None] * ez).reshape(-1, 3)
    slope = (piece.end_scale - 1.0) / length
    if abs(slope) < 1e-9:
        chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
        rest = np.stack(np.broadcast_arrays(chord[None, :], heights[:, None]), axis=-1).reshape(-1, 2)
    else:
        generators = np.concatenate([curve, np.full((nu + 1, 1), 1.0 / slope)], axis=1)  # apex -> row of scale 1
        norms = np.linalg.norm(generators, axis=1)
        cosine = np.einsum("ij,ij->i", generators[:-1], generators[1:]) / (norms[:-1] * norms[1:])
        angles = np.concatenate([[0.0], np.cumsum(np.arccos(np.clip(cosine, -1.0, 1.0)))])
        angles -= 0.5 * angles[-1]
        radial = scales[:, None] * norms[None, :]
        rest = np.stack([radial * np.cos(angles)[None, :], radial * np.sin(angles)[None, :]], axis=-1).reshape(-1, 2)
    rest = rest - rest.mean(axis=0)
    ii, jj = np.meshgrid(np.arange(nu), np.arange(nv))
    ii, jj = ii.reshape(-1), jj.reshape(-1)
    a = jj * (nu + 1) + ii
    b, d = a + 1, a + nu + 1
    c = d + 1
    even = ((ii + jj) % 2 == 0)[:, None]
    first = np.where(even, np.stack([a, b, c], axis=1), np.stack([a, b, d], axis=1))
    second = np.where(even, np.stack([a, c, d], axis=1), np.stack([b, c, d], axis=1))
    faces = np.stack([first, second], axis=1).reshape(-1, 3).astype(np.int32)
    return vertices.astype(np.float32), faces, rest.astype(np.float32), np.arange(nu + 1)


def _cell_for(pieces: list[TubePiece], triangles: int) -> float:
    """Cell size giving about ``triangles`` triangles over all pieces (within 2 % when feasible)."""
    area = sum(p.area() for p in pieces)
    cell = math.sqrt(2.0 * area / triangles)
    for _ in range(4):
        count = sum(tube_mesh(p, cell)[1].shape[0] for p in pieces)
        cell *= math.sqrt(count / triangles)
    return cell


def _garment_scene(name: str, description: str, body: Body, garments: dict[str, list[TubePiece]], scale: float,
                   frame_time: float, steps_per_frame: int, material: ClothMaterial | None = None) -> Scene:
    """Mesh every piece (one object id each), anchor the first rows and add the body's obstacles."""
    from pscc.scenes.paper import PAPER_TRIANGLES, check_scale

    scale = check_scale(name, scale)
    for joint, (rotation, translation) in body.pose(0.0).items():
        if not (np.allclose(rotation, np.eye(3), atol=1e-9) and np.allclose(translation, 0.0, atol=1e-9)):
            raise InputError(name, f"animation[{joint}]", "the pose at t = 0 is not the rest pose",
                             "start every track at the identity (garments are fitted to the rest pose)")
    pieces = [p for group in garments.values() for p in group]
    cell = _cell_for(pieces, round(scale * PAPER_TRIANGLES[name]))
    vertices, faces, rest, object_ids, handles = [], [], [], [], []
    offset = 0
    for index, piece in enumerate(pieces):
        v, f, r, first_row = tube_mesh(piece, cell)
        vertices.append(v)
        faces.append(f + offset)
        rest.append(r)
        object_ids.append(np.full(f.shape[0], index, dtype=np.int32))
        if piece.anchor is not None:
            handles.append(Handle(first_row + offset, motion=body.motion(piece.anchor), name=f"{piece.name} anchor"))
        offset += v.shape[0]
    fine = scale >= 0.25
    return Scene(
        name=name, description=description,
        vertices=np.concatenate(vertices), faces=np.concatenate(faces).astype(np.int32),
        rest=np.concatenate(rest), object_ids=np.concatenate(object_ids),
        material=material if material is not None else ClothMaterial(),
        solver=SolverConfig(),
        handles=handles,
        obstacles=body.obstacles(around=48 if fine else 24, rings=16 if fine else 8),
        frame_time=frame_time, steps_per_frame=steps_per_frame,
    )


# ---------------------------------------------------------------------------------------------- shared garments

_UP = (0.0, 0.0, 1.0)
_DOWN = (0.0, 0.0, -1.0)
_FRONT = (0.0, 1.0, 0.0)
_TORSO_HALF, _TORSO_RADIUS = 0.08, 0.10  # the humanoid's torso slab (stadium cross-section)
_CLEARANCE = 0.015  # body to first layer
_LAYER = 0.008  # between layers


def _torso_piece(name: str, top: float, bottom: float, flare: float, offset: float, opening: float,
                 reference_top: float = 1.29) -> TubePiece:
    """A stadium cone around the torso, anchored to it at ``top``.

    All torso layers share one cone: at height z the cross-section is stadium(0.08 l, (0.115 + offset) l)
    with l = 1 + flare (reference_top - z) / 0.37, so a layer with a larger ``offset`` stays outside one
    with a smaller offset by at least the difference.
    """

    def scale(z: float) -> float:
        return 1.0 + flare * (reference_top - z) / 0.37

    base = _TORSO_RADIUS + _CLEARANCE + offset
    return TubePiece(name, (0.0, 0.0, top), (0.0, 0.0, bottom), half_length=_TORSO_HALF * scale(top),
                     radius=base * scale(top), end_scale=scale(bottom) / scale(top), opening_toward=_FRONT,
                     opening=opening, anchor="torso")


def _sleeve(body: Body, side: str, name: str, radius: float, begin: float, end: float, flare: float) -> TubePiece:
    """A tube around the upper arm from ``begin`` to ``end`` metres past the shoulder pivot."""
    shoulder = np.asarray(next(j.pivot for j in body.joints if j.name == f"shoulder_{side}"))
    direction = arm_direction(side)
    return TubePiece(name, tuple(shoulder + begin * direction), tuple(shoulder + end * direction), half_length=0.0,
                     radius=radius, end_scale=flare, long_axis=(0.0, 1.0, 0.0), opening_toward=_DOWN,
                     anchor=f"upper_arm_{side}")


def _leg(body: Body, side: str, name: str, top: float, bottom: float) -> TubePiece:
    """A trouser leg: a cone around thigh and shin from height ``top`` to ``bottom``, anchored to the thigh."""
    thigh, shin = body.parts[f"thigh_{side}"], body.parts[f"shin_{side}"]
    hip = np.asarray(thigh.core[0])
    ankle = np.asarray(shin.core[1])

    def axis_at(z: float) -> np.ndarray:
        return hip + (z - hip[2]) / (ankle[2] - hip[2]) * (ankle - hip)

    top_radius = thigh.radius + _CLEARANCE
    bottom_radius = shin.radius + _CLEARANCE
    inner = (-1.0 if side == "l" else 1.0, 0.0, 0.0)
    return TubePiece(name, tuple(axis_at(top)), tuple(axis_at(bottom)), half_length=0.0, radius=top_radius,
                     end_scale=bottom_radius / top_radius, long_axis=(0.0, 1.0, 0.0), opening_toward=inner,
                     anchor=f"thigh_{side}")


def _pelvis_piece(name: str, top: float, bottom: float, radius: float, flare: float, opening: float = 0.0) -> TubePiece:
    """A stadium tube or cone around the pelvis and hips, anchored to the pelvis at ``top``."""
    return TubePiece(name, (0.0, 0.0, top), (0.0, 0.0, bottom), half_length=0.06, radius=radius, end_scale=flare,
                     opening_toward=_FRONT, opening=opening, anchor="pelvis")


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


def kungfu(scale: float) -> Scene:
    """Andy stand-in: a body in trousers, a shirt and a vest practising kung-fu (127K triangles at scale 1).

    Garments (8 pieces, one object id each, all anchored at their first row):

    * trousers: a hip piece (stadium cylinder 0.125 m radius around the pelvis, z 1.00 -> 0.66,
      anchored to the pelvis) over two tapered legs (thigh radius + 1.5 cm -> shin radius + 1.5 cm,
      z 0.70 -> 0.14, anchored to the thighs 9 cm below the hip pivot so a 90 degree kick keeps the
      anchor clear of the pelvis; inner-seam slit one cell wide);
    * shirt: a torso cone (1.5 cm off the torso at the armpit, z 1.29 -> 0.90, flaring so its hem
      covers the hip piece 5 mm outside it; front slit one cell wide) and two short sleeves (upper
      arm radius + 1.5 cm, 4 -> 22 cm past the shoulder pivot);
    * vest: a torso cone 8 mm outside the shirt, z 1.27 -> 0.98, open in front (10 cm).

    Motion: :func:`kungfu_body` (3.4 s). Time: 25 frames/s, 8 steps per frame (dt = 1/200 s, the
    step I-Cloth reports for Andy; the paper's "1/25" is the character's frame rate).
    """
    body = kungfu_body()
    garments = {
        "trousers": [_pelvis_piece("trousers hips", 1.00, 0.66, 0.125, 1.0),
                     _leg(body, "l", "trousers left leg", 0.70, 0.14),
                     _leg(body, "r", "trousers right leg", 0.70, 0.14)],
        "shirt": [_torso_piece("shirt body", 1.29, 0.90, 0.19, 0.0, 0.0),
                  _sleeve(body, "l", "shirt left sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0),
                  _sleeve(body, "r", "shirt right sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0)],
        "vest": [_torso_piece("vest", 1.27, 0.98, 0.19, _LAYER, 0.10)],
    }
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


def falling(scale: float) -> Scene:
    """Falling stand-in: a man in a robe falls fast under strikes (172K triangles at scale 1).

    Robe (3 pieces, anchored at their first row): a body cone open in front (6 cm), from the chest
    (z 1.29, 1.5 cm off the torso, anchored to it) flaring 1.7 times to the shins (z 0.25), and two
    bell sleeves (upper arm radius + 2.5 cm, 4 -> 30 cm past the shoulder pivot, flaring 1.5 times,
    so the forearm moves freely inside).

    Motion: :func:`falling_body` (1.6 s; 1.2 m drop in the first second). Time: 30 frames/s (the
    paper's "1/30"), 6 steps per frame (dt = 1/180 s: the body moves up to 2.3 cm per step).
    """
    body = falling_body()
    garments = {
        "robe": [_torso_piece("robe body", 1.29, 0.25, 0.7 * 0.37 / 1.04, 0.005, 0.06),
                 _sleeve(body, "l", "robe left sleeve", 0.045 + 0.025, 0.04, 0.30, 1.5),
                 _sleeve(body, "r", "robe right sleeve", 0.045 + 0.025, 0.04, 0.30, 1.5)],
    }
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


def dance(scale: float) -> Scene:
    """Bishop stand-in: a swing dancer in a skirt, a shirt and a bolero spins (124K triangles at scale 1).

    Garments (5 pieces, anchored at their first row): a flared skirt (stadium cone from the pelvis,
    z 1.00, radius 0.125, to z 0.45, scale 1.8, front slit one cell wide); a shirt (torso cylinder
    1.5 cm off the torso, z 1.29 -> 1.04, ending above the skirt; short sleeves as in ``kungfu``); a
    bolero (torso cylinder 8 mm outside the shirt, z 1.27 -> 1.12, open in front over 12 cm).

    Motion: :func:`dance_body` (2.4 s). Time: 30 frames/s (the paper's "1/30"), 4 steps per frame
    (dt = 1/120 s, close to I-Cloth's 1/100 s for Bishop and a whole number of steps per frame).
    """
    body = dance_body()
    garments = {
        "skirt": [_pelvis_piece("skirt", 1.00, 0.45, 0.125, 1.8)],
        "shirt": [_torso_piece("shirt body", 1.29, 1.04, 0.0, 0.0, 0.0),
                  _sleeve(body, "l", "shirt left sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0),
                  _sleeve(body, "r", "shirt right sleeve", 0.045 + _CLEARANCE, 0.04, 0.22, 1.0)],
        "bolero": [_torso_piece("bolero", 1.27, 1.12, 0.0, _LAYER, 0.12)],
    }
    return _garment_scene("dance", "a swing dancer spins in skirt, shirt and bolero (paper: Bishop)", body, garments,
                          scale, frame_time=1.0 / 30.0, steps_per_frame=4)


GARMENT_BODIES: dict[str, Callable[[], Body]] = {"kungfu": kungfu_body, "falling": falling_body, "dance": dance_body}
"""The animated body of each garment scene."""

GARMENT_DURATIONS: dict[str, float] = {"kungfu": KUNGFU_DURATION, "falling": FALLING_DURATION,
                                       "dance": DANCE_DURATION}
"""Length of each garment scene's animation [s]."""
