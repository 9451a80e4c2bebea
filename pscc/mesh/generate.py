"""Procedural cloth-like meshes for the demo, the tests and the benchmarks.

All generators are deterministic (a ``seed`` drives the noise), vectorised, and return meshes
whose triangle count is within a few percent of the request:

* :func:`grid_sheet`: a flat rectangular grid in the z = 0 plane.
* :func:`folded_sheet`: a sheet folded like an accordion into stacked layers, with an end-of-step
  state in which the layers are pressed together and locally pushed through each other.
* :func:`twisted_sheet`: a long strip twisted about its long axis, with an end state twisted a
  little further.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pscc.errors import InputError
from pscc.mesh.mesh_data import MeshData, validate_mesh

_MIN_TRIANGLES = 50


def _check_count(value: int, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise InputError("argument", name, f"{value!r} is not an integer >= {minimum}",
                         f"pass an integer {name} >= {minimum}")
    return int(value)


def _check_positive(value: float, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", name, f"{value!r} is not a number", "pass a float > 0") from exc
    if not math.isfinite(number) or number <= 0.0:
        raise InputError("argument", name, f"{value!r} is not a finite number > 0", "pass a float > 0")
    return number


def grid_sheet(
    nx: int, ny: int, width: float = 1.0, height: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat rectangular triangle grid in the z = 0 plane.

    Vertex ``j * (nx + 1) + i`` sits at ``(i * width / nx, j * height / ny, 0)``. Each of the
    ``nx * ny`` cells is split into two counter-clockwise triangles (normal +z); the diagonal
    alternates in a checkerboard pattern so the mesh has no preferred shear direction.

    Args:
        nx: Cells along x (>= 1).
        ny: Cells along y (>= 1).
        width: Extent along x (> 0).
        height: Extent along y (> 0).

    Returns:
        ``(vertices, faces, rest)``: (n, 3) float32 positions with n = (nx + 1)(ny + 1),
        (2 nx ny, 3) int32 faces, and (n, 2) float32 material coordinates, equal to the (x, y)
        positions (so rest lengths are in the same units as the positions).

    Raises:
        InputError: a non-positive count or size.
    """
    nx = _check_count(nx, "nx", 1)
    ny = _check_count(ny, "ny", 1)
    width = _check_positive(width, "width")
    height = _check_positive(height, "height")
    xs = np.linspace(0.0, width, nx + 1)
    ys = np.linspace(0.0, height, ny + 1)
    grid_x, grid_y = np.meshgrid(xs, ys)  # (ny + 1, nx + 1), row j = y index
    rest = np.stack([grid_x.reshape(-1), grid_y.reshape(-1)], axis=1).astype(np.float32)
    vertices = np.zeros((rest.shape[0], 3), dtype=np.float32)
    vertices[:, :2] = rest

    ii, jj = np.meshgrid(np.arange(nx, dtype=np.int64), np.arange(ny, dtype=np.int64))
    ii, jj = ii.reshape(-1), jj.reshape(-1)
    a = jj * (nx + 1) + ii  # (i, j)
    b = a + 1  # (i + 1, j)
    d = a + (nx + 1)  # (i, j + 1)
    c = d + 1  # (i + 1, j + 1)
    even = ((ii + jj) % 2 == 0)[:, None]
    first = np.where(even, np.stack([a, b, c], axis=1), np.stack([a, b, d], axis=1))
    second = np.where(even, np.stack([a, c, d], axis=1), np.stack([b, c, d], axis=1))
    faces = np.stack([first, second], axis=1).reshape(-1, 3).astype(np.int32)
    return vertices, faces, rest


def _best_rows(
    triangle_count: int, ny_guess: float, columns_for: Callable[[int], list[int]]
) -> tuple[int, int]:
    """Pick ``(ny, nx)`` near ``ny_guess`` so that ``2 * nx * ny`` is closest to the request.

    ``columns_for(ny)`` returns the candidate column counts for a row count.
    """
    best: tuple[float, int, int] | None = None
    center = max(1, round(ny_guess))
    for ny in range(max(1, center - 3), center + 4):
        for nx in columns_for(ny):
            if nx < 1:
                continue
            error = abs(2 * nx * ny - triangle_count) + 1e-3 * abs(ny - ny_guess)
            if best is None or error < best[0]:
                best = (error, ny, nx)
    assert best is not None
    return best[1], best[2]


def folded_sheet(
    triangle_count: int,
    layers: int = 3,
    gap: float | None = None,
    seed: int = 0,
) -> MeshData:
    """A sheet folded like an accordion into stacked layers, with a colliding end state.

    The flat sheet (rest coordinates) is a strip of ``layers`` unit squares joined by fold
    sections. In 3-D, layer k is a unit square in the plane z = k * gap (layers alternate
    direction along x) and consecutive layers are joined by half-cylinders of radius gap / 2
    bulging out past x = 1 or x = 0. Small deterministic noise (about 2 % of the smaller of
    gap and the edge length) is added; at t = 0 the layers are separated by about ``gap`` and
    nothing intersects.

    ``vertices_end`` presses the layers towards the middle layer by 15 % of ``gap`` per layer,
    and a Gaussian bump (random centre inside the layers, width 0.12) pushes adjacent layers
    1.3 ``gap`` towards each other, so during the step some vertex-face and edge-edge pairs
    near the bump collide, while the rest of the layers stay apart.

    Args:
        triangle_count: Requested number of triangles (>= 50); the result is within 5 %.
        layers: Number of stacked layers (>= 2).
        gap: Distance between layers; default twice the mean edge length.
        seed: Seed of the noise and of the bump position.

    Returns:
        The mesh, with ``vertices_end`` and ``rest`` (the flat sheet coordinates) set and all
        object ids 0.

    Raises:
        InputError: invalid arguments.
    """
    triangle_count = _check_count(triangle_count, "triangle_count", _MIN_TRIANGLES)
    layers = _check_count(layers, "layers", 2)
    width = 1.0  # along y
    layer_length = 1.0  # along x
    # Mean edge length of a grid with square cells of side h: (h + h + sqrt(2) h) / 3.
    edge_factor = (2.0 + math.sqrt(2.0)) / 3.0
    if gap is None:
        # Solve T h^2 = 2 W (layers L + (layers - 1) pi r) with r = gap / 2 = edge_factor h.
        b = 2.0 * width * (layers - 1) * math.pi * edge_factor
        c = 2.0 * width * layers * layer_length
        h = (b + math.sqrt(b * b + 4.0 * triangle_count * c)) / (2.0 * triangle_count)
        gap_value = 2.0 * edge_factor * h
    else:
        gap_value = _check_positive(gap, "gap")
        total = layers * layer_length + (layers - 1) * math.pi * gap_value / 2.0
        h = math.sqrt(2.0 * width * total / triangle_count)
    radius = gap_value / 2.0
    fold_length = math.pi * radius
    seed = int(seed)

    def columns_for(ny: int) -> list[int]:
        nf_ = max(2, round(fold_length / h))
        target = triangle_count / (2.0 * ny)
        guess = (target - (layers - 1) * nf_) / layers
        options = {max(1, math.floor(guess)), max(1, math.ceil(guess))}
        return [layers * nl + (layers - 1) * nf_ for nl in sorted(options)]

    ny, nx = _best_rows(triangle_count, width / h, columns_for)
    nf = max(2, round(fold_length / h))
    nl = (nx - (layers - 1) * nf) // layers

    # Per-column arc length u, 3-D (x, z), outward normal (nx_, nz_) and press factor p.
    u_cols: list[np.ndarray] = []
    x_cols: list[np.ndarray] = []
    z_cols: list[np.ndarray] = []
    press_cols: list[np.ndarray] = []
    center = (layers - 1) / 2.0
    u0 = 0.0
    for k in range(layers):
        t = np.arange(0, nl + 1) / nl  # folds hold only their interior columns
        s = t * layer_length
        u_cols.append(u0 + s)
        x_cols.append(s if k % 2 == 0 else layer_length - s)
        z_cols.append(np.full_like(s, k * gap_value))
        press_cols.append(np.full_like(s, center - k))
        u0 += layer_length
        if k == layers - 1:
            break
        theta = np.arange(1, nf) / nf * math.pi
        u_cols.append(u0 + theta * radius)
        side = layer_length + radius * np.sin(theta) if k % 2 == 0 else -radius * np.sin(theta)
        x_cols.append(side)
        z_cols.append(k * gap_value + radius * (1.0 - np.cos(theta)))
        press_cols.append((center - k) - theta / math.pi)
        u0 += fold_length
    u_col = np.concatenate(u_cols)
    x_col = np.concatenate(x_cols)
    z_col = np.concatenate(z_cols)
    press_col = np.concatenate(press_cols)
    assert u_col.shape[0] == nx + 1

    # Grid connectivity from grid_sheet, then map its columns onto the folded shape.
    _, faces, _ = grid_sheet(nx, ny, width=1.0, height=width)
    y_row = np.linspace(0.0, width, ny + 1)
    col = np.tile(np.arange(nx + 1), ny + 1)
    y = np.repeat(y_row, nx + 1)
    rest = np.stack([u_col[col], y], axis=1)
    vertices = np.stack([x_col[col], y, z_col[col]], axis=1)

    rng = np.random.default_rng(seed)
    noise = 0.02 * min(gap_value, h)
    vertices = vertices + rng.uniform(-noise, noise, size=vertices.shape)

    cx = rng.uniform(0.35, 0.65) * layer_length
    cy = rng.uniform(0.35, 0.65) * width
    sigma = 0.12
    bump = np.exp(-((vertices[:, 0] - cx) ** 2 + (vertices[:, 1] - cy) ** 2) / (2.0 * sigma**2))
    dz = press_col[col] * gap_value * (0.15 + 1.15 * bump)
    vertices_end = vertices.copy()
    vertices_end[:, 2] += dz
    vertices_end += rng.uniform(-0.5 * noise, 0.5 * noise, size=vertices.shape)

    return validate_mesh(vertices, faces, vertices_end=vertices_end, rest=rest,
                         source=f"folded_sheet(triangle_count={triangle_count}, layers={layers}, "
                                f"seed={seed})")


def twisted_sheet(
    triangle_count: int,
    turns: float = 1.0,
    seed: int = 0,
    extra_turns: float | None = 0.05,
) -> MeshData:
    """A 4 x 1 strip twisted about its long (x) axis.

    The cross-section at x is rotated by ``2 pi turns x / 4`` about the x axis (a helicoid,
    which does not intersect itself). Small deterministic noise (1 % of the edge length) is added.

    Args:
        triangle_count: Requested number of triangles (>= 50); the result is within 5 %.
        turns: Full turns of twist over the strip's length at t = 0.
        seed: Seed of the noise.
        extra_turns: Additional twist of the end-of-step state; None gives no ``vertices_end``.

    Returns:
        The mesh, with ``rest`` (the flat strip coordinates) set, ``vertices_end`` set unless
        ``extra_turns`` is None, and all object ids 0.

    Raises:
        InputError: invalid arguments.
    """
    triangle_count = _check_count(triangle_count, "triangle_count", _MIN_TRIANGLES)
    try:
        turns = float(turns)
        extra = None if extra_turns is None else float(extra_turns)
    except (TypeError, ValueError) as exc:
        raise InputError("argument", "turns", "turns and extra_turns must be numbers",
                         "pass floats") from exc
    if not math.isfinite(turns) or (extra is not None and not math.isfinite(extra)):
        raise InputError("argument", "turns", "turns and extra_turns must be finite",
                         "pass finite floats")
    length, width = 4.0, 1.0
    h = math.sqrt(2.0 * length * width / triangle_count)

    def columns_for(ny: int) -> list[int]:
        target = triangle_count / (2.0 * ny)
        return sorted({max(1, math.floor(target)), max(1, math.ceil(target))})

    ny, nx = _best_rows(triangle_count, width / h, columns_for)
    flat, faces, rest = grid_sheet(nx, ny, width=length, height=width)
    x = flat[:, 0].astype(np.float64)
    y = flat[:, 1].astype(np.float64) - width / 2.0
    rng = np.random.default_rng(int(seed))
    noise = 0.01 * min(length / nx, width / ny)

    def twist(total_turns: float) -> np.ndarray:
        phi = 2.0 * math.pi * total_turns * x / length
        return np.stack([x, y * np.cos(phi), y * np.sin(phi)], axis=1)

    vertices = twist(turns) + rng.uniform(-noise, noise, size=flat.shape)
    vertices_end = None
    if extra is not None:
        vertices_end = twist(turns + extra) + rng.uniform(-noise, noise, size=flat.shape)
    return validate_mesh(vertices, faces, vertices_end=vertices_end, rest=rest,
                         source=f"twisted_sheet(triangle_count={triangle_count}, turns={turns}, "
                                f"seed={int(seed)})")


def icosphere(radius: float = 1.0, subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A closed sphere mesh centred at the origin: an icosahedron split ``subdivisions`` times.

    Each split cuts every triangle into four and pushes the new vertices onto the sphere, so the
    mesh has 20 * 4**subdivisions faces, outward-facing (counter-clockwise seen from outside).

    Args:
        radius: Sphere radius (> 0).
        subdivisions: Number of 1-to-4 splits (0 to 7).

    Returns:
        ``(vertices, faces)``: (n, 3) float32 and (m, 3) int32.

    Raises:
        InputError: a non-positive radius or a subdivision count outside [0, 7].
    """
    radius = _check_positive(radius, "radius")
    if isinstance(subdivisions, bool) or not isinstance(subdivisions, int | np.integer) or not 0 <= subdivisions <= 7:
        raise InputError("argument", "subdivisions", f"{subdivisions!r} is not an integer in [0, 7]",
                         "pass 0 to 7 (20 * 4**s faces)")
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    points = [(-1, phi, 0), (1, phi, 0), (-1, -phi, 0), (1, -phi, 0), (0, -1, phi), (0, 1, phi),
              (0, -1, -phi), (0, 1, -phi), (phi, 0, -1), (phi, 0, 1), (-phi, 0, -1), (-phi, 0, 1)]
    vertices = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in points]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
             (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(int(subdivisions)):
        midpoint: dict[tuple[int, int], int] = {}

        def middle(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in midpoint:
                point = vertices[a] + vertices[b]
                vertices.append(point / np.linalg.norm(point))
                midpoint[key] = len(vertices) - 1
            return midpoint[key]

        split = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            split += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = split
    return (np.asarray(vertices) * radius).astype(np.float32), np.asarray(faces, dtype=np.int32)
