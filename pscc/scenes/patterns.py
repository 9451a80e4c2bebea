"""Sewing patterns for the garment scenes: flat panels, wrapped around the body and sewn at their seams.

A garment here is made as a pattern-making program would make it. Each **wrap** is a generalised cone
around a body part: a stadium cross-section (a circle when its half-length is 0) scaled linearly
along an axis. Its **panels** are regions of the cone's exact development into the plane, bounded by
two seam lines (generators of the cone) and two cross-sections (its top and bottom edges: arcs on a
cone, so a flared skirt's panel is a piece of an annulus). A panel's flat shape is its sewing
pattern and its rest shape; wrapping it around the cone is an isometry, so every panel starts
unstrained (up to the chord of a curved triangle edge, ``1 - chord / arc`` about
``(cell / radius)^2 / 24``: below 0.5 % for cells under a third of the radius of curvature), and two
panels that share a seam line meet along it vertex for vertex: each such pair is a stitch
``(i, j, j, 0)`` (vertex i sewn to vertex j).

Meshing: the panel's outline is sampled at about ``cell`` spacing (a shared seam is sampled the same
way by both of its panels), an equilateral lattice of spacing ``cell`` fills the inside (points closer
than 0.6 ``cell`` to the outline are dropped), and the points are triangulated (Delaunay, triangles
outside the outline removed). Every outline segment is checked to be a mesh edge.

Coordinates as in :mod:`pscc.scenes.body`; metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pscc.errors import InputError, PsccError

__all__ = ["Panel", "PanelMesh", "Wrap", "mesh_panel", "seam_stitches"]


def _stadium(half_length: float, radius: float, s: np.ndarray) -> np.ndarray:
    """Points (n, 2) at arc lengths ``s`` on a stadium (scale 1), from (0, radius) counter-clockwise."""
    a, r = half_length, radius
    total = 4.0 * a + 2.0 * math.pi * r
    s = np.mod(np.asarray(s, dtype=np.float64), total)
    bounds = np.cumsum([a, math.pi * r, 2.0 * a, math.pi * r])
    out = np.zeros((s.shape[0], 2))
    seg = np.minimum(np.searchsorted(bounds, s, side="right"), 4)
    m = seg == 0
    out[m] = np.stack([-s[m], np.full(m.sum(), r)], axis=1)
    m = seg == 1
    angle = math.pi / 2.0 + (s[m] - bounds[0]) / r
    out[m] = np.stack([-a + r * np.cos(angle), r * np.sin(angle)], axis=1)
    m = seg == 2
    out[m] = np.stack([-a + (s[m] - bounds[1]), np.full(m.sum(), -r)], axis=1)
    m = seg == 3
    angle = -math.pi / 2.0 + (s[m] - bounds[2]) / r
    out[m] = np.stack([a + r * np.cos(angle), r * np.sin(angle)], axis=1)
    m = seg == 4
    out[m] = np.stack([a - (s[m] - bounds[3]), np.full(m.sum(), r)], axis=1)
    return out


@dataclass(frozen=True)
class Wrap:
    """A generalised cone around a body part, and its development into the plane.

    The cross-section at ``start`` is the stadium of half-length ``half_length`` along ``long_axis``
    and radius ``radius``; it scales linearly to ``end_scale`` times that at ``end``. A point is
    named by ``(s, f)``: arc length ``s`` around the scale-1 stadium (from the point farthest along
    ``ey = axis x ex``, counter-clockwise about the axis) and the fraction ``f`` in [0, 1] from
    ``start`` to ``end``.

    Attributes:
        start: (3,) axis point of the first cross-section [m].
        end: (3,) axis point of the last cross-section [m].
        half_length: stadium half-length at ``start`` [m].
        radius: stadium radius at ``start`` [m].
        end_scale: cross-section scale at ``end`` (> 0; 1 is a cylinder).
        long_axis: direction of the stadium's flat sides (projected perpendicular to the axis).
    """

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    half_length: float
    radius: float
    end_scale: float = 1.0
    long_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    _table: dict = field(default_factory=dict, compare=False, repr=False)

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """``(start, ex, ey, ez, length)``: the axis frame (ez from start to end) and the axis length [m]."""
        start = np.asarray(self.start, np.float64)
        axis = np.asarray(self.end, np.float64) - start
        length = float(np.linalg.norm(axis))
        ez = axis / length
        ex = np.asarray(self.long_axis, np.float64)
        ex = ex - (ex @ ez) * ez
        ex = ex / np.linalg.norm(ex)
        return start, ex, np.cross(ez, ex), ez, length

    @property
    def perimeter(self) -> float:
        """Perimeter of the scale-1 cross-section [m]."""
        return 4.0 * self.half_length + 2.0 * math.pi * self.radius

    @property
    def conical(self) -> bool:
        """Whether the cross-section changes along the axis (a cone, not a cylinder)."""
        return abs(self.end_scale - 1.0) > 1e-9

    def scale(self, f: np.ndarray) -> np.ndarray:
        """Cross-section scale at axis fractions ``f``."""
        return 1.0 + (self.end_scale - 1.0) * np.asarray(f, np.float64)

    def arc_toward(self, direction: tuple[float, float, float]) -> float:
        """Arc length ``s`` of the cross-section point farthest along a 3-D ``direction``."""
        _, ex, ey, _, _ = self.frame()
        probe = np.linspace(0.0, self.perimeter, 2880, endpoint=False)
        points = _stadium(self.half_length, self.radius, probe)
        d = np.asarray(direction, np.float64)
        return float(probe[int(np.argmax(points @ np.array([d @ ex, d @ ey])))])

    def _apex_distance(self) -> float:
        """Signed distance along the axis from the cone's apex to ``start`` [m]."""
        *_, length = self.frame()
        return length / (self.end_scale - 1.0)

    def _angles(self) -> tuple[np.ndarray, np.ndarray]:
        """Table (s, developed angle) over [-perimeter, 2 perimeter] for a cone (the cumulative angle between
        neighbouring generators)."""
        if "angles" not in self._table:
            s = np.linspace(-self.perimeter, 2.0 * self.perimeter, 6 * 2048 + 1)
            curve = _stadium(self.half_length, self.radius, s)
            generators = np.concatenate([curve, np.full((s.shape[0], 1), self._apex_distance())], axis=1)
            norms = np.linalg.norm(generators, axis=1)
            cosine = np.einsum("ij,ij->i", generators[:-1], generators[1:]) / (norms[:-1] * norms[1:])
            angle = np.concatenate([[0.0], np.cumsum(np.arccos(np.clip(cosine, -1.0, 1.0)))])
            angle -= np.interp(0.0, s, angle)
            self._table["angles"] = (s, angle)
        return self._table["angles"]

    def position(self, s: np.ndarray, f: np.ndarray) -> np.ndarray:
        """(n, 3) points of the cone at ``(s, f)``."""
        start, ex, ey, ez, length = self.frame()
        curve = _stadium(self.half_length, self.radius, np.asarray(s, np.float64).reshape(-1))
        sigma = self.scale(np.asarray(f, np.float64).reshape(-1))[:, None]
        return start + sigma * (curve[:, :1] * ex + curve[:, 1:] * ey) + (np.asarray(f).reshape(-1, 1) * length) * ez

    def develop(self, s: np.ndarray, f: np.ndarray) -> np.ndarray:
        """(n, 2) flat pattern coordinates of ``(s, f)`` (an isometry of the cone onto the plane)."""
        s = np.asarray(s, np.float64).reshape(-1)
        f = np.asarray(f, np.float64).reshape(-1)
        *_, length = self.frame()
        if not self.conical:
            return np.stack([s, -f * length], axis=1)
        table_s, table_angle = self._angles()
        angle = np.interp(s, table_s, table_angle)
        curve = _stadium(self.half_length, self.radius, s)
        generator = np.sqrt((curve * curve).sum(axis=1) + self._apex_distance() ** 2)
        rho = self.scale(f) * generator
        direction = -1.0 if self.end_scale > 1.0 else 1.0  # the pattern's top towards +y
        return np.stack([rho * np.sin(angle), direction * rho * np.cos(angle)], axis=1)

    def undevelop(self, points: np.ndarray, near_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``(s, f)`` of flat pattern points (n, 2): the inverse of :meth:`develop` (on a cone, the
        developed angle is taken within half a turn of the angle of ``near_s``)."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        *_, length = self.frame()
        if not self.conical:
            return points[:, 0].copy(), -points[:, 1] / length
        direction = -1.0 if self.end_scale > 1.0 else 1.0
        angle = np.arctan2(points[:, 0], direction * points[:, 1])
        rho = np.hypot(points[:, 0], points[:, 1])
        table_s, table_angle = self._angles()
        middle = float(np.interp(near_s, table_s, table_angle))
        angle += 2.0 * math.pi * np.round((middle - angle) / (2.0 * math.pi))
        s = np.interp(angle, table_angle, table_s)
        curve = _stadium(self.half_length, self.radius, s)
        generator = np.sqrt((curve * curve).sum(axis=1) + self._apex_distance() ** 2)
        f = (rho / generator - 1.0) / (self.end_scale - 1.0)
        return s, f


@dataclass(frozen=True)
class Panel:
    """One pattern piece: the region of a wrap between two seam lines and a top and bottom curve.

    The region is ``s_left <= s <= s_right`` (arc lengths; ``s_right - s_left`` at most the perimeter)
    and ``top_f <= f <= bottom_f`` (fractions of the wrap's axis). On a cone the top and bottom
    edges are arcs in the pattern.

    Attributes:
        name: label (also the cloth piece's name).
        wrap: the cone the panel is cut from.
        s_left: arc length of the left seam line [m].
        s_right: arc length of the right seam line [m].
        top_f: axis fraction of the top edge.
        bottom_f: axis fraction of the bottom edge.
    """

    name: str
    wrap: Wrap
    s_left: float
    s_right: float
    top_f: float = 0.0
    bottom_f: float = 1.0

    def top(self, s: np.ndarray) -> np.ndarray:
        """Axis fraction of the top edge at arc lengths ``s``."""
        return np.full(np.asarray(s).shape, self.top_f)

    def bottom(self, s: np.ndarray) -> np.ndarray:
        """Axis fraction of the bottom edge at arc lengths ``s``."""
        return np.full(np.asarray(s).shape, self.bottom_f)


@dataclass
class PanelMesh:
    """A meshed panel.

    Attributes:
        vertices: (n, 3) float32 positions on the wrap [m].
        faces: (m, 3) int32 triangles (outward: their normals point away from the wrap's axis).
        rest: (n, 2) float32 flat pattern coordinates [m] (the development).
        left_seam: vertex ids along the left seam line, top to bottom.
        right_seam: vertex ids along the right seam line, top to bottom.
        top_edge: vertex ids along the top edge, left to right (corners included).
    """

    vertices: np.ndarray
    faces: np.ndarray
    rest: np.ndarray
    left_seam: np.ndarray
    right_seam: np.ndarray
    top_edge: np.ndarray


def _samples(length: float, cell: float) -> np.ndarray:
    """Fractions in [0, 1] cutting a length into about ``cell``-long pieces (at least one piece)."""
    n = max(1, round(length / cell))
    return np.arange(n + 1) / n


def _seam_line(panel: Panel, s: float, cell: float) -> np.ndarray:
    """(k, 2) ``(s, f)`` samples of the seam line at ``s``, top to bottom; a function of ``s`` only,
    so the two panels that share the line sample it identically."""
    wrap = panel.wrap
    f0, f1 = float(panel.top(np.array([s]))[0]), float(panel.bottom(np.array([s]))[0])
    ends = wrap.develop(np.array([s, s]), np.array([f0, f1]))
    fraction = _samples(float(np.linalg.norm(ends[1] - ends[0])), cell)
    return np.stack([np.full(fraction.shape, s), f0 + (f1 - f0) * fraction], axis=1)


def _curve(panel: Panel, cell: float, top: bool) -> np.ndarray:
    """(k, 2) ``(s, f)`` samples of the top or bottom edge, left to right, spaced about ``cell`` in the pattern."""
    fine = np.linspace(panel.s_left, panel.s_right, 4097)
    f = panel.top(fine) if top else panel.bottom(fine)
    flat = panel.wrap.develop(fine, f)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(flat, axis=0), axis=1))])
    targets = _samples(float(arc[-1]), cell) * arc[-1]
    s = np.interp(targets, arc, fine)
    s[0], s[-1] = panel.s_left, panel.s_right
    return np.stack([s, panel.top(s) if top else panel.bottom(s)], axis=1)


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) distance from points (n, 2) to the polyline of segments a -> b (k, 2)."""
    d = b - a
    rel = points[:, None, :] - a[None, :, :]
    t = np.clip((rel * d[None]).sum(-1) / np.maximum((d * d).sum(-1), 1e-30)[None], 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * d[None], axis=-1).min(axis=1)


def _inside(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """(n,) bool: points strictly inside a closed polygon (k, 2) (even-odd rule)."""
    x, y = points[:, 0:1], points[:, 1:2]
    a, b = polygon, np.roll(polygon, -1, axis=0)
    crosses = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    x_at = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / np.where(
        b[None, :, 1] == a[None, :, 1], 1.0, b[None, :, 1] - a[None, :, 1])
    return ((crosses & (x < x_at)).sum(axis=1) % 2) == 1


def mesh_panel(panel: Panel, cell: float) -> PanelMesh:
    """Mesh a panel with triangles of side about ``cell`` [m] (see the module docstring).

    Raises:
        InputError: a bad size, or a panel narrower than two cells.
        PsccError: the triangulation lost an outline segment (should not happen for these shapes).
    """
    from scipy.spatial import Delaunay

    wrap = panel.wrap
    if not (cell > 0.0 and panel.s_right > panel.s_left and panel.s_right - panel.s_left <= wrap.perimeter + 1e-9):
        raise InputError(panel.name, "s_left/s_right", f"[{panel.s_left}, {panel.s_right}] with cell {cell}",
                         "give 0 < s_right - s_left <= the perimeter and cell > 0")
    top = _curve(panel, cell, top=True)
    right = _seam_line(panel, panel.s_right, cell)
    bottom = _curve(panel, cell, top=False)[::-1]
    left = _seam_line(panel, panel.s_left, cell)[::-1]
    outline_sf = np.concatenate([top[:-1], right[:-1], bottom[:-1], left[:-1]])
    outline = wrap.develop(outline_sf[:, 0], outline_sf[:, 1])
    if outline.shape[0] < 6:
        raise InputError(panel.name, "size", "the panel is less than two cells across", "use a smaller cell")
    lower, upper = outline.min(axis=0), outline.max(axis=0)
    row = cell * math.sqrt(3.0) / 2.0
    ys = np.arange(lower[1], upper[1] + row, row)
    xs_even = np.arange(lower[0], upper[0] + cell, cell)
    grid = []
    for i, y in enumerate(ys):
        xs = xs_even + (0.5 * cell if i % 2 else 0.0)
        grid.append(np.stack([xs, np.full(xs.shape, y)], axis=1))
    interior = np.concatenate(grid)
    closed = np.concatenate([outline, outline[:1]])
    keep = _inside(interior, outline)
    interior = interior[keep]
    interior = interior[_segment_distance(interior, closed[:-1], closed[1:]) > 0.6 * cell]
    points = np.concatenate([outline, interior])
    triangles = Delaunay(points).simplices
    centroids = points[triangles].mean(axis=1)
    triangles = triangles[_inside(centroids, outline)]
    # Orientation: counter-clockwise in the pattern; checked outward on the wrap below.
    p = points[triangles]
    u, v = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    triangles = np.where((area < 0.0)[:, None], triangles[:, ::-1], triangles)
    triangles = triangles[np.abs(area) > 1e-4 * cell * cell]  # Qhull's flat triangles along straight outline parts
    if np.unique(triangles).shape[0] != points.shape[0]:
        raise PsccError(f"{panel.name}: the triangulation left out a point (cell {cell})")
    count = outline.shape[0]
    edges = {tuple(sorted(e)) for t in triangles.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    missing = [i for i in range(count) if tuple(sorted((i, (i + 1) % count))) not in edges]
    if missing:
        raise PsccError(f"{panel.name}: the triangulation lost {len(missing)} outline segments (cell {cell})")
    s, f = wrap.undevelop(points, near_s=0.5 * (panel.s_left + panel.s_right))
    s[:count], f[:count] = outline_sf[:, 0], outline_sf[:, 1]  # exact on the outline (seams match)
    vertices = wrap.position(s, f)
    start, _, _, ez, _ = wrap.frame()
    tri = vertices[triangles]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = tri.mean(axis=1)
    radial = centre - start - ((centre - start) @ ez)[:, None] * ez
    if np.einsum("ij,ij->", normals, radial) < 0.0:
        triangles = triangles[:, ::-1]
    n_top, n_right, n_bottom = top.shape[0] - 1, right.shape[0] - 1, bottom.shape[0] - 1
    ids = np.arange(count)
    top_ids = ids[:n_top + 1]
    right_ids = ids[n_top:n_top + n_right + 1]
    left_ids = np.concatenate([ids[n_top + n_right + n_bottom:], ids[:1]])[::-1]
    rest = wrap.develop(s, f)
    return PanelMesh(vertices.astype(np.float32), np.ascontiguousarray(triangles, dtype=np.int32),
                     rest.astype(np.float32), left_ids, right_ids, top_ids)


def seam_stitches(first: np.ndarray, second: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Stitch rows ``(i, j, j, 0)`` sewing two seam lines vertex for vertex.

    Args:
        first, second: vertex ids along the two lines (global ids), in the same order.
        positions: (n, 3) positions, to check that the lines coincide.

    Raises:
        PsccError: the lines have different vertex counts or do not coincide (within 1e-5 m).
    """
    if first.shape != second.shape:
        raise PsccError(f"seam lines with {first.shape[0]} and {second.shape[0]} vertices")
    gap = np.linalg.norm(positions[first] - positions[second], axis=1).max()
    if gap > 1e-5:
        raise PsccError(f"seam lines {gap:.3g} m apart")
    rows = np.zeros((first.shape[0], 4))
    rows[:, 0], rows[:, 1], rows[:, 2] = first, second, second
    return rows
