"""Normal cones as direction bit masks, and the unprojected contour test (PSCC section 3.2).

A surface patch cannot intersect itself when (1) some direction l has l . n > 0 for every triangle
normal n of the patch, and (2) the patch's single closed contour, projected along l, is a simple
polygon (Volino and Magnenat-Thalmann 1994). PSCC tests this per BVH node with the unprojected
normal-cone test of Wang et al. 2017.

**Normal test (1) as a direction mask.** Instead of a cone (axis, half-angle) merged with
trigonometry, each face keeps a bit mask over ``DIRECTION_COUNT`` fixed sample directions d_k
(a spherical Fibonacci set): bit k is set when d_k . n > margin |n| for the face normal n (for CCD:
for all three Bernstein control normals n0, nX, n1 of the normal over the step, whose non-negative
combination is n(t)). A node's mask is the AND of its children's masks; the node passes test (1)
iff its mask is non-zero, and any set d_k is a valid l. With 128 directions the covering radius is
about 13.7 degrees, so every patch whose normals fit in a cone of half-angle below about 76 degrees
still has a witness direction. The test is exact up to the rounding of one dot product, which the
margin covers, so it never certifies a patch that fails (1). Degenerate faces get an empty mask.

**Contour test (2), unprojected.** With S(a, b, c; l) = ((a - c) x (b - c)) . l, a loop v_0..v_{m-1}
and a reference point o: every S(o, v_i, v_{i+1}; l) must have one strict sign s0 (the projected
loop turns monotonically around o), and the loop must wind exactly once around o: with a ray r
orthogonal to l (through the midpoint of the first edge), sigma_i = sign(l . (r x (v_i - o))) must be
non-zero and the number of sign changes from -s0 to s0 along the loop must be 1. For CCD the same
conditions are checked on the Bernstein coefficients over the step (quadratic for S, linear for
sigma), so they hold at every time. Values within a relative rounding margin of zero count as a
failure, so the test is conservative. A loop that no point o sees turn one way can still be simple:
:mod:`pscc.geometry.simple_contour` checks that directly, and the node test falls back to it.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

DIRECTION_COUNT: int = 128
"""Sample directions of a normal-cone mask (4 words of 32 bits)."""

mask_type = wp.types.vector(length=4, dtype=wp.uint32)
"""A direction mask: bit k of word k // 32 is direction k."""


def sample_directions(count: int = DIRECTION_COUNT) -> np.ndarray:
    """``count`` unit directions on a spherical Fibonacci lattice, (count, 3) float32."""
    i = np.arange(count, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / count
    radius = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([radius * np.cos(phi), radius * np.sin(phi), z], axis=1).astype(np.float32)


@wp.func
def mask_and(a: mask_type, b: mask_type) -> mask_type:
    """Directions in both masks."""
    return mask_type(a[0] & b[0], a[1] & b[1], a[2] & b[2], a[3] & b[3])


@wp.func
def mask_is_empty(a: mask_type) -> bool:
    """True when no direction is set."""
    return (a[0] | a[1] | a[2] | a[3]) == wp.uint32(0)


@wp.func
def _mask_with(n: wp.vec3, directions: wp.array(dtype=wp.vec3), margin: float, allow_zero: bool) -> mask_type:
    """Bits of directions d with d . n > margin |n| (or >= when ``allow_zero``)."""
    words = mask_type(wp.uint32(0), wp.uint32(0), wp.uint32(0), wp.uint32(0))
    threshold = margin * wp.length(n)
    for k in range(directions.shape[0]):
        d = wp.dot(directions[k], n)
        ok = d > threshold
        if allow_zero:
            ok = d >= threshold
        if ok:
            words[k // 32] = words[k // 32] | (wp.uint32(1) << wp.uint32(k % 32))
    return words


@wp.func
def _degenerate(e1: wp.vec3, e2: wp.vec3, n: wp.vec3, degenerate_ratio: float) -> bool:
    return wp.dot(n, n) <= degenerate_ratio * wp.dot(e1, e1) * wp.dot(e2, e2)


@wp.func
def face_mask(
    a: wp.vec3, b: wp.vec3, c: wp.vec3, directions: wp.array(dtype=wp.vec3), margin: float, degenerate_ratio: float
) -> mask_type:
    """Directions that see the front of triangle (a, b, c); empty for a degenerate triangle."""
    e1 = b - a
    e2 = c - a
    n = wp.cross(e1, e2)
    if _degenerate(e1, e2, n, degenerate_ratio):
        return mask_type(wp.uint32(0), wp.uint32(0), wp.uint32(0), wp.uint32(0))
    return _mask_with(n, directions, margin, False)


@wp.func
def face_mask_swept(
    a0: wp.vec3,
    b0: wp.vec3,
    c0: wp.vec3,
    a1: wp.vec3,
    b1: wp.vec3,
    c1: wp.vec3,
    directions: wp.array(dtype=wp.vec3),
    margin: float,
    degenerate_ratio: float,
) -> mask_type:
    """Directions d with d . n(t) > 0 for every t in [0, 1] of a linearly moving triangle.

    n(t) = (1-t)^2 n0 + 2 t (1-t) nX + t^2 n1 with nX = (n0 + n1 - dn) / 2 and
    dn = (db - da) x (dc - da): requiring d . n0 > 0, d . n1 > 0 and d . nX >= 0 suffices.
    """
    e10 = b0 - a0
    e20 = c0 - a0
    e11 = b1 - a1
    e21 = c1 - a1
    n0 = wp.cross(e10, e20)
    n1 = wp.cross(e11, e21)
    empty = mask_type(wp.uint32(0), wp.uint32(0), wp.uint32(0), wp.uint32(0))
    if _degenerate(e10, e20, n0, degenerate_ratio) or _degenerate(e11, e21, n1, degenerate_ratio):
        return empty
    dn = wp.cross(e11 - e10, e21 - e20)
    nx = 0.5 * (n0 + n1 - dn)
    m = mask_and(_mask_with(n0, directions, margin, False), _mask_with(n1, directions, margin, False))
    return mask_and(m, _mask_with(nx, directions, margin, True))


@wp.func
def pick_axis(m: mask_type, mean_normal: wp.vec3, directions: wp.array(dtype=wp.vec3)) -> int:
    """Index of the set direction closest to ``mean_normal``; -1 for an empty mask."""
    best = int(-1)
    best_dot = float(-2.0)
    for k in range(directions.shape[0]):
        if (m[k // 32] >> wp.uint32(k % 32)) & wp.uint32(1):
            d = wp.dot(directions[k], mean_normal)
            if d > best_dot:
                best_dot = d
                best = k
    return best


@wp.func
def signed_area(o: wp.vec3, a: wp.vec3, b: wp.vec3, l: wp.vec3, margin: float) -> float:
    """S(o, a, b; l) = ((o - b) x (a - b)) . l, or 0 when within the rounding margin of 0."""
    p = o - b
    q = a - b
    s = wp.dot(wp.cross(p, q), l)
    if wp.abs(s) <= margin * wp.length(p) * wp.length(q):
        return 0.0
    return s


@wp.func
def _side(o: wp.vec3, r: wp.vec3, v: wp.vec3, l: wp.vec3, margin: float) -> float:
    """sign of l . (r x (v - o)), or 0 within the rounding margin."""
    w = v - o
    s = wp.dot(l, wp.cross(r, w))
    if wp.abs(s) <= margin * wp.length(r) * wp.length(w):
        return 0.0
    return wp.sign(s)


@wp.func
def contour_test(
    loop: wp.array(dtype=wp.int32),
    begin: int,
    end: int,
    positions: wp.array(dtype=wp.vec3),
    o: wp.vec3,
    l: wp.vec3,
    margin: float,
) -> bool:
    """Unprojected contour test of the loop ``loop[begin:end]`` (vertex ids) at one instant."""
    count = end - begin
    if count < 3:
        return False
    v0 = positions[loop[begin]]
    v1 = positions[loop[begin + 1]]
    s0 = wp.sign(signed_area(o, v0, v1, l, margin))
    if s0 == 0.0:
        return False
    for i in range(count):
        a = positions[loop[begin + i]]
        b = positions[loop[begin + (i + 1) % count]]
        if wp.sign(signed_area(o, a, b, l, margin)) != s0:
            return False
    # Ray through the midpoint of the first edge, projected onto the plane orthogonal to l.
    r = 0.5 * (v0 + v1) - o
    r = r - wp.dot(r, l) * l
    crossings = int(0)
    previous = _side(o, r, positions[loop[end - 1]], l, margin)
    if previous == 0.0:
        return False
    for i in range(count):
        current = _side(o, r, positions[loop[begin + i]], l, margin)
        if current == 0.0:
            return False
        if current != previous and current == s0:
            crossings += 1
        previous = current
    return crossings == 1


@wp.func
def _bernstein_sign(b0: float, b1: float, b2: float, scale0: float, scale1: float, margin: float) -> float:
    """Common strict sign of three Bernstein coefficients, or 0 when they disagree or are near 0."""
    if b0 > margin * scale0 and b1 > margin * scale1 and b2 > margin * scale1:
        return 1.0
    if b0 < -margin * scale0 and b1 < -margin * scale1 and b2 < -margin * scale1:
        return -1.0
    return 0.0


@wp.func
def swept_signed_area_sign(
    o0: wp.vec3, a0: wp.vec3, b0: wp.vec3, o1: wp.vec3, a1: wp.vec3, b1: wp.vec3, l: wp.vec3, margin: float
) -> float:
    """Strict sign of S(o(t), a(t), b(t); l) over t in [0, 1] from its quadratic Bernstein form."""
    p0 = o0 - b0
    q0 = a0 - b0
    p1 = o1 - b1
    q1 = a1 - b1
    c0 = wp.dot(wp.cross(p0, q0), l)
    c1 = 0.5 * (wp.dot(wp.cross(p0, q1), l) + wp.dot(wp.cross(p1, q0), l))
    c2 = wp.dot(wp.cross(p1, q1), l)
    scale_p = wp.max(wp.max(wp.length(p0), wp.length(p1)), 1.0e-30)
    scale = scale_p * wp.max(wp.max(wp.length(q0), wp.length(q1)), 1.0e-30)
    return _bernstein_sign(c0, c1, c2, scale, scale, margin)


@wp.func
def contour_test_swept(
    loop: wp.array(dtype=wp.int32),
    begin: int,
    end: int,
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    o0: wp.vec3,
    o1: wp.vec3,
    l: wp.vec3,
    margin: float,
) -> bool:
    """Unprojected contour test holding at every t of a linear motion from t0 to t1 (CCD)."""
    count = end - begin
    if count < 3:
        return False
    s0 = swept_signed_area_sign(o0, positions_t0[loop[begin]], positions_t0[loop[begin + 1]],
                                o1, positions_t1[loop[begin]], positions_t1[loop[begin + 1]], l, margin)
    if s0 == 0.0:
        return False
    for i in range(count):
        ia = loop[begin + i]
        ib = loop[begin + (i + 1) % count]
        s = swept_signed_area_sign(o0, positions_t0[ia], positions_t0[ib], o1, positions_t1[ia],
                                   positions_t1[ib], l, margin)
        if s != s0:
            return False
    # Fixed ray chosen at t0; sigma_i(t) is linear, so equal strict signs at both ends hold throughout.
    r = 0.5 * (positions_t0[loop[begin]] + positions_t0[loop[begin + 1]]) - o0
    r = r - wp.dot(r, l) * l
    crossings = int(0)
    last = loop[end - 1]
    previous = _side(o0, r, positions_t0[last], l, margin)
    if previous == 0.0 or _side(o1, r, positions_t1[last], l, margin) != previous:
        return False
    for i in range(count):
        v = loop[begin + i]
        current = _side(o0, r, positions_t0[v], l, margin)
        if current == 0.0 or _side(o1, r, positions_t1[v], l, margin) != current:
            return False
        if current != previous and current == s0:
            crossings += 1
        previous = current
    return crossings == 1


TABLE_RESOLUTION: int = 32
"""Cells per cube-face side of the direction-mask lookup table (6 x 32 x 32 cells)."""


@functools.lru_cache(maxsize=4)
def direction_mask_table(resolution: int = TABLE_RESOLUTION, margin: float = 1.0e-5,
                         slack: float = 1.0e-2) -> np.ndarray:
    """Conservative direction masks per cube-map cell, (6 * resolution^2, 4) uint32.

    A normal n is mapped to the cell of the cube face of its largest |component|. The cell's mask
    holds the sample directions d whose angle to the cell's centre is below 90 degrees minus the
    cell's angular radius (the largest angle from its centre to a corner, since a cube-face cell is
    a convex spherical quadrilateral), minus ``slack`` radians (cells adjacent through rounding of
    the lookup), minus asin(``margin``). Every d in the mask then has d . n > margin |n| for every
    n of the cell: the table mask is a subset of the exact :func:`face_mask` bits.
    """
    directions = sample_directions().astype(np.float64)
    r = resolution
    edges = np.linspace(-1.0, 1.0, r + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    table = np.zeros((6, r, r, 4), dtype=np.uint32)
    for face in range(6):
        axis, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
        others = [k for k in range(3) if k != axis]
        for i in range(r):
            for j in range(r):
                def direction(u: float, v: float, axis=axis, sign=sign, others=others) -> np.ndarray:
                    p = np.zeros(3)
                    p[axis] = sign
                    p[others[0]] = u
                    p[others[1]] = v
                    return p / np.linalg.norm(p)
                centre = direction(centres[i], centres[j])
                corners = [direction(edges[i + a], edges[j + b]) for a in (0, 1) for b in (0, 1)]
                radius = max(np.arccos(np.clip(centre @ c, -1.0, 1.0)) for c in corners)
                limit = np.pi / 2 - radius - slack - np.arcsin(margin)
                ok = np.arccos(np.clip(directions @ centre, -1.0, 1.0)) < limit
                for k in np.flatnonzero(ok):
                    table[face, i, j, k // 32] |= np.uint32(1) << np.uint32(k % 32)
    return table.reshape(-1, 4)


@wp.func
def lookup_mask(n: wp.vec3, table: wp.array(dtype=mask_type), resolution: int) -> mask_type:
    """Table mask of the cube-map cell of direction ``n`` (a subset of the exact mask); n != 0."""
    ax = wp.abs(n[0])
    ay = wp.abs(n[1])
    az = wp.abs(n[2])
    face = int(0)
    major = n[0]
    u = n[1]
    v = n[2]
    if ay >= ax and ay >= az:
        face = 2
        major = n[1]
        u = n[0]
        v = n[2]
    elif az >= ax and az >= ay:
        face = 4
        major = n[2]
        u = n[0]
        v = n[1]
    if major < 0.0:
        face += 1
    scale = 1.0 / wp.abs(major)
    i = wp.clamp(int((u * scale + 1.0) * 0.5 * float(resolution)), 0, resolution - 1)
    j = wp.clamp(int((v * scale + 1.0) * 0.5 * float(resolution)), 0, resolution - 1)
    return table[(face * resolution + i) * resolution + j]


@wp.func
def face_mask_fast(
    a: wp.vec3, b: wp.vec3, c: wp.vec3, table: wp.array(dtype=mask_type), resolution: int, degenerate_ratio: float
) -> mask_type:
    """:func:`face_mask` through the lookup table (a subset of its bits); empty when degenerate."""
    e1 = b - a
    e2 = c - a
    n = wp.cross(e1, e2)
    if _degenerate(e1, e2, n, degenerate_ratio):
        return mask_type(wp.uint32(0), wp.uint32(0), wp.uint32(0), wp.uint32(0))
    return lookup_mask(n, table, resolution)


@wp.func
def face_mask_swept_fast(
    a0: wp.vec3,
    b0: wp.vec3,
    c0: wp.vec3,
    a1: wp.vec3,
    b1: wp.vec3,
    c1: wp.vec3,
    table: wp.array(dtype=mask_type),
    resolution: int,
    directions: wp.array(dtype=wp.vec3),
    margin: float,
    degenerate_ratio: float,
) -> mask_type:
    """:func:`face_mask_swept` with table lookups for n0 and n1 (nX, which may be tiny and so has
    an unreliable direction, keeps the exact test)."""
    e10 = b0 - a0
    e20 = c0 - a0
    e11 = b1 - a1
    e21 = c1 - a1
    n0 = wp.cross(e10, e20)
    n1 = wp.cross(e11, e21)
    empty = mask_type(wp.uint32(0), wp.uint32(0), wp.uint32(0), wp.uint32(0))
    if _degenerate(e10, e20, n0, degenerate_ratio) or _degenerate(e11, e21, n1, degenerate_ratio):
        return empty
    m = mask_and(lookup_mask(n0, table, resolution), lookup_mask(n1, table, resolution))
    if mask_is_empty(m):
        return empty
    dn = wp.cross(e11 - e10, e21 - e20)
    nx = 0.5 * (n0 + n1 - dn)
    return mask_and(m, _mask_with(nx, directions, margin, True))
