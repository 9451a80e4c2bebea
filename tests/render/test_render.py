"""Ray-cast renderer, camera fitting and PNG/MP4 output on tiny scenes."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from pscc.errors import InputError
from pscc.io.frames import write_frame
from pscc.render import Camera, Renderer, fit_camera, render_run, write_mp4, write_png
from pscc.render.raycast import BACKGROUND_COLORS, OBSTACLE_COLOR, PALETTE

WIDTH, HEIGHT = 96, 72
FRONT = Camera(position=(0.0, -6.0, 1.0), target=(0.0, 0.0, 1.0), fov_degrees=35.0)
"""Looks along +y at the middle of the upright square of :func:`_upright_square`."""


def _quad(corner: np.ndarray, edge_u: np.ndarray, edge_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two triangles spanning corner, corner + edge_u, corner + edge_v (float32 vertices, int32 faces)."""
    corner, edge_u, edge_v = (np.asarray(a, dtype=np.float32) for a in (corner, edge_u, edge_v))
    vertices = np.stack([corner, corner + edge_u, corner + edge_u + edge_v, corner + edge_v])
    return vertices, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def _upright_square(x0: float = -1.0, width: float = 2.0, y: float = 0.0, z0: float = 0.0,
                    height: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A square in the plane y = const, facing the FRONT camera."""
    return _quad((x0, y, z0), (width, 0.0, 0.0), (0.0, 0.0, height))


def _pixel(image: np.ndarray, camera: Camera, point: tuple[float, float, float]) -> np.ndarray:
    column, row = np.floor(camera.project(np.array([point]), image.shape[1], image.shape[0])[0]).astype(int)
    return image[row, column].astype(np.float64)


def _cosine(a: np.ndarray, b: np.ndarray) -> float:
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_image_shape_cloth_colour_and_background(device: str) -> None:
    vertices, faces = _upright_square()
    image = Renderer(WIDTH, HEIGHT, device).render(vertices, faces, np.zeros(2, np.int32), camera=FRONT)
    assert image.shape == (HEIGHT, WIDTH, 3) and image.dtype == np.uint8
    centre = image[HEIGHT // 2, WIDTH // 2].astype(np.float64)
    # Shading scales the linear albedo, so the sRGB pixel stays parallel to the palette colour.
    assert _cosine(centre, PALETTE[0].astype(np.float64)) > 0.995
    corner = image[0, 0].astype(np.float64)
    np.testing.assert_allclose(corner, 255.0 * BACKGROUND_COLORS[1], atol=4.0)
    assert np.abs(centre - corner).max() > 40.0


def test_object_ids_get_palette_colours(device: str) -> None:
    left, faces = _upright_square(x0=-1.0, width=1.0)
    right, _ = _upright_square(x0=0.0, width=1.0)
    vertices = np.concatenate([left, right])
    faces = np.concatenate([faces, faces + 4])
    image = Renderer(WIDTH, HEIGHT, device).render(vertices, faces, np.array([0, 0, 1, 1], np.int32), camera=FRONT)
    left_pixel = _pixel(image, FRONT, (-0.5, 0.0, 1.0))
    right_pixel = _pixel(image, FRONT, (0.5, 0.0, 1.0))
    assert _cosine(left_pixel, PALETTE[0].astype(np.float64)) > 0.995
    assert _cosine(right_pixel, PALETTE[1].astype(np.float64)) > 0.995
    assert np.abs(left_pixel - right_pixel).max() > 40.0


def test_obstacle_in_front_hides_cloth(device: str) -> None:
    vertices, faces = _upright_square()
    obstacle_vertices, obstacle_faces = _upright_square(x0=-0.3, width=0.6, y=-1.0, z0=0.7, height=0.6)
    image = Renderer(WIDTH, HEIGHT, device).render(vertices, faces, np.zeros(2, np.int32), obstacle_vertices,
                                                   obstacle_faces, camera=FRONT)
    centre = image[HEIGHT // 2, WIDTH // 2].astype(np.float64)
    assert _cosine(centre, OBSTACLE_COLOR.astype(np.float64)) > 0.9995  # grey, not the cloth's blue
    assert centre.max() - centre.min() < 8.0
    beside = _pixel(image, FRONT, (0.7, 0.0, 1.0))  # the cloth still shows around the obstacle
    assert _cosine(beside, PALETTE[0].astype(np.float64)) > 0.995


def test_shadow_darkens_ground_under_cloth(device: str) -> None:
    vertices, faces = _quad((-0.5, -0.5, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # a roof at z = 1
    bounds = (np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0]))  # ground at z = 0
    camera = Camera(position=(0.0, -4.0, 0.5), target=(0.0, 0.0, 0.3))
    images = {}
    for shadows in (True, False):
        renderer = Renderer(WIDTH, HEIGHT, device, ground="plain", shadows=shadows, light_direction=(0.0, 0.0, 1.0))
        images[shadows] = renderer.render(vertices, faces, np.zeros(2, np.int32), camera=camera, bounds=bounds)
    under = _pixel(images[True], camera, (0.0, 0.0, 0.0))
    beside = _pixel(images[True], camera, (1.2, 0.0, 0.0))
    assert under.sum() < 0.7 * beside.sum()
    np.testing.assert_array_equal(_pixel(images[False], camera, (1.2, 0.0, 0.0)), beside)
    assert _pixel(images[False], camera, (0.0, 0.0, 0.0)).sum() > 1.3 * under.sum()


def test_rendering_is_deterministic_and_refit_matches_rebuild() -> None:
    vertices, faces = _upright_square()
    ids = np.zeros(2, np.int32)
    renderer = Renderer(WIDTH, HEIGHT, "cpu", antialias=2)
    first = renderer.render(vertices, faces, ids)
    np.testing.assert_array_equal(renderer.render(vertices, faces, ids), first)
    np.testing.assert_array_equal(Renderer(WIDTH, HEIGHT, "cpu", antialias=2).render(vertices, faces, ids), first)
    # Same faces, moved vertices: the refitted mesh must render like a fresh one.
    moved = vertices + np.float32([0.3, 0.2, 0.1])
    bounds = (np.array([-1.0, 0.0, 0.0]), np.array([1.3, 0.2, 2.1]))
    refit = renderer.render(moved, faces, ids, camera=FRONT, bounds=bounds)
    fresh = Renderer(WIDTH, HEIGHT, "cpu", antialias=2).render(moved, faces, ids, camera=FRONT, bounds=bounds)
    np.testing.assert_array_equal(refit, fresh)


def test_empty_scene_and_bad_input(device: str) -> None:
    renderer = Renderer(32, 24, device)
    image = renderer.render(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32))
    assert image.shape == (24, 32, 3)
    vertices, faces = _upright_square()
    with pytest.raises(InputError, match="cloth_faces"):
        renderer.render(vertices, faces + 3, np.zeros(2, np.int32))
    with pytest.raises(InputError, match="object_ids"):
        renderer.render(vertices, faces, np.zeros(3, np.int32))
    with pytest.raises(InputError, match="up"):
        Camera(position=(0.0, 0.0, 5.0), target=(0.0, 0.0, 0.0))


@pytest.mark.parametrize("view", ["three-quarter", "front", "side", "top"])
def test_fit_camera_frames_the_box(view: str) -> None:
    lower, upper = np.array([-1.0, -0.5, 0.0]), np.array([1.0, 0.5, 0.2])
    camera = fit_camera(lower, upper, view, aspect=WIDTH / HEIGHT)
    corners = np.array([[(lower, upper)[(i >> k) & 1][k] for k in range(3)] for i in range(8)])
    pixels = camera.project(corners, WIDTH, HEIGHT)
    assert np.all(np.isfinite(pixels))
    assert np.all((pixels >= 0.0) & (pixels <= [WIDTH, HEIGHT]))
    np.testing.assert_allclose(camera.project(np.array([camera.target]), WIDTH, HEIGHT)[0],
                               [WIDTH / 2, HEIGHT / 2], atol=1e-9)


def test_render_run_writes_png_and_mp4(tmp_path) -> None:
    vertices, faces = _quad((-0.5, -0.5, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    box_vertices, box_faces = _quad((-0.2, -0.2, 0.0), (0.4, 0.0, 0.0), (0.0, 0.0, 0.4))
    for index in range(3):
        write_frame(tmp_path, index, vertices + np.float32([0.0, 0.0, 1.0 - 0.3 * index]), faces,
                    np.array([0, 1], np.int32), box_vertices, box_faces)
    preview, animation = render_run(tmp_path, width=64, height=48, fps=5, progress=False)
    assert preview == tmp_path / "preview.png" and animation == tmp_path / "animation.mp4"
    image = iio.imread(preview)
    assert image.shape == (48, 64, 3) and image.dtype == np.uint8
    frames = iio.imread(animation, plugin="FFMPEG", index=None)
    assert frames.shape == (3, 48, 64, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["animation.mp4", "frames", "preview.png"]  # no temps


def test_writers_validate_and_pad_odd_sizes(tmp_path) -> None:
    frame = np.full((11, 13, 3), 200, np.uint8)
    assert write_mp4(tmp_path / "odd.mp4", (frame for _ in range(2)), fps=4) == 2
    assert iio.imread(tmp_path / "odd.mp4", plugin="FFMPEG", index=None).shape == (2, 12, 14, 3)
    with pytest.raises(InputError, match="no frames"):
        write_mp4(tmp_path / "none.mp4", [], fps=4)
    with pytest.raises(InputError, match="image"):
        write_png(tmp_path / "bad.png", np.zeros((4, 4), np.float32))
    with pytest.raises(InputError, match="differs from the first"):  # fails mid-stream: the temp file goes
        write_mp4(tmp_path / "mixed.mp4", [frame, frame[:5]], fps=4)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["odd.mp4"]


def test_render_run_without_frames_names_the_folder(tmp_path) -> None:
    with pytest.raises(InputError) as caught:
        render_run(tmp_path, progress=False)
    assert str(tmp_path / "frames") in str(caught.value)
    (tmp_path / "frames").mkdir()
    with pytest.raises(InputError, match="no frame files"):
        render_run(tmp_path, progress=False)


def test_render_run_bad_frame_names_the_file_and_leaves_no_video(tmp_path) -> None:
    vertices, faces = _quad((-0.5, -0.5, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    write_frame(tmp_path, 0, vertices, faces, np.zeros(2, np.int32))
    bad = write_frame(tmp_path, 1, vertices, faces, np.zeros(3, np.int32))  # one id too many
    with pytest.raises(InputError, match="object_ids") as caught:
        render_run(tmp_path, width=32, height=24, progress=False)
    assert caught.value.source == str(bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames"]
