"""Write the example garment: a two-panel skirt (front and back, cut as flat patterns with their UV layout
and sewn at both sides by OBJ ``stitch`` lines) around a static body (a closed cylinder), as
``skirt.obj`` and ``body.obj`` next to this script. ``skirt.toml`` simulates them; see docs/garments.md.

Run it with:  .venv/bin/python examples/garment/make_skirt.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

RADIUS = 0.16  # the body [m]
PANEL_WIDTH = 0.62  # each panel's pattern width [m]: 2 x 0.62 m of cloth around a 1.0 m body
PANEL_HEIGHT = 0.45  # [m]
CELLS = (16, 12)  # per panel, along the width and the height
GAP = 0.02  # the side seams start open by about this much [m]
WAIST = 0.95  # height of the waistband [m]


def _panel(front: bool, cells: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One panel: 3-D start positions (half a cylinder around the body, a little wider), its pattern (u, v)
    in metres, and its triangles."""
    nu, nv = cells
    u = np.linspace(0.0, PANEL_WIDTH, nu + 1)
    v = np.linspace(0.0, PANEL_HEIGHT, nv + 1)
    uu, vv = np.meshgrid(u, v)  # row j = height v[j]
    pattern = np.stack([uu.ravel(), vv.ravel()], axis=1)
    # Wrapped on a cylinder slightly larger than the panel's half circumference, leaving GAP at each side.
    radius = (PANEL_WIDTH + GAP) / np.pi
    angle = (uu.ravel() + 0.5 * GAP) / radius + (0.0 if front else np.pi)
    positions = np.stack([radius * np.cos(angle), radius * np.sin(angle), WAIST - PANEL_HEIGHT + vv.ravel()], axis=1)
    faces = []
    for j in range(nv):
        for i in range(nu):
            a = j * (nu + 1) + i
            faces += [(a, a + 1, a + nu + 2), (a, a + nu + 2, a + nu + 1)]
    return positions, pattern, np.asarray(faces)


def _side(offset: int, column: int, cells: tuple[int, int]) -> list[int]:
    nu, nv = cells
    return [offset + j * (nu + 1) + column for j in range(nv + 1)]


def main(folder: Path | None = None, cells: tuple[int, int] = CELLS) -> None:
    """Write ``skirt.obj`` and ``body.obj`` into ``folder`` (default: this script's folder), each panel cut
    into ``cells`` (along the width, along the height) grid cells of two triangles."""
    folder = Path(__file__).resolve().parent if folder is None else Path(folder)
    front, front_uv, faces = _panel(True, cells)
    back, back_uv, _ = _panel(False, cells)
    n = len(front)
    vertices = np.concatenate([front, back])
    # Each panel has its own place in the UV layout (one vertex per (u, v), as sewn patterns are stored).
    uv = np.concatenate([front_uv, back_uv + [PANEL_WIDTH + 0.1, 0.0]])
    nu = cells[0]
    # Side seams: the front's end column sewn to the back's start column and the other way round, each
    # vertex to the same height of the other panel (stitch i j k r: vertex i to (1 - r) x_j + r x_k, 0-based).
    stitches = []
    for a, b in ((_side(0, nu, cells), _side(n, 0, cells)), (_side(n, nu, cells), _side(0, 0, cells))):
        for row, (i, j) in enumerate(zip(a, b, strict=True)):
            k = b[row + 1] if row + 1 < len(b) else b[row - 1]
            stitches.append((i, j, k, 0.0))
    lines = ["# Example garment: a two-panel skirt (make_skirt.py). Units: metres."]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"vt {s:.6f} {t:.6f}" for s, t in uv]
    lines += ["o front"] + [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    lines += ["o back"] + [f"f {a + n + 1}/{a + n + 1} {b + n + 1}/{b + n + 1} {c + n + 1}/{c + n + 1}"
                           for a, b, c in faces]
    lines += [f"stitch {i} {j} {k} {r:g}" for i, j, k, r in stitches]
    (folder / "skirt.obj").write_text("\n".join(lines) + "\n")
    # The body: a closed cylinder (24 sides), from the floor to above the waist.
    sides = 24
    ring = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    heights = (0.2, 1.1)
    body = [(RADIUS * np.cos(a), RADIUS * np.sin(a), z) for z in heights for a in ring]
    body += [(0.0, 0.0, heights[0]), (0.0, 0.0, heights[1])]
    tris = []
    for s in range(sides):
        t = (s + 1) % sides
        tris += [(s, t, sides + t), (s, sides + t, sides + s)]
        tris += [(2 * sides, t, s), (2 * sides + 1, sides + s, sides + t)]
    body_lines = ["# Example body: a closed cylinder (make_skirt.py). Units: metres."]
    body_lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in body]
    body_lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tris]
    (folder / "body.obj").write_text("\n".join(body_lines) + "\n")


if __name__ == "__main__":
    main()
