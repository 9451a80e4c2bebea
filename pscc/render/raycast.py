"""Headless ray-cast renderer of cloth frames on Warp: one thread per pixel, ``wp.mesh_query_ray``.

:class:`Renderer` owns the output image and a ``wp.Mesh`` of the cloth and obstacle triangles
(rebuilt when the topology changes, refit otherwise) and launches :func:`_render_pixels`. The
same kernel runs on the CPU and on CUDA; see ``docs/rendering.md`` for the shading model.

Shading (linear RGB, written as 8-bit sRGB): two-sided Lambert with a directional key light and
hard shadows (a shadow ray toward the light), a camera-side fill light and ambient; a colour per
cloth piece from :data:`PALETTE` and grey obstacles; a ground plane at the scene's lowest z
(checker or plain) that receives shadows and fades into a vertical background gradient.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from pscc._checks import as_numpy, check_points
from pscc.errors import InputError

wp.set_module_options({"enable_backward": False})

PALETTE: np.ndarray = np.array([
    [0.26, 0.52, 0.85],  # blue
    [0.93, 0.52, 0.18],  # orange
    [0.33, 0.68, 0.35],  # green
    [0.84, 0.29, 0.31],  # red
    [0.58, 0.44, 0.78],  # purple
    [0.22, 0.68, 0.68],  # teal
    [0.90, 0.76, 0.22],  # yellow
    [0.88, 0.48, 0.68],  # pink
], dtype=np.float32)
"""(8, 3) sRGB albedo of cloth piece ``object_id % 8``."""

OBSTACLE_COLOR: np.ndarray = np.array([0.62, 0.62, 0.64], dtype=np.float32)
"""sRGB albedo of every obstacle triangle."""

GROUND_COLORS: np.ndarray = np.array([[0.88, 0.88, 0.86], [0.77, 0.77, 0.75]], dtype=np.float32)
"""(2, 3) sRGB albedos of the ground's checker tiles (a plain ground uses the first)."""

BACKGROUND_COLORS: np.ndarray = np.array([[0.93, 0.94, 0.96], [0.70, 0.78, 0.88]], dtype=np.float32)
"""(2, 3) sRGB background at the image's bottom and top rows (a vertical gradient)."""

VIEWS: dict[str, tuple[float, float]] = {
    "three-quarter": (-60.0, 28.0),
    "front": (-90.0, 10.0),
    "side": (0.0, 10.0),
    "top": (-90.0, 90.0),
}
"""Named views of :func:`fit_camera`: (azimuth, elevation) of the camera seen from the target [deg].
Azimuth is measured from +x towards +y; -90 looks along +y."""

_RAY_OFFSET = 1.0e-4
"""Shadow-ray start offset along the surface normal, relative to the scene diagonal (against acne)."""

_GAMMA = 2.2
"""Display gamma: albedos are converted to linear RGB with it, pixels back to sRGB."""

_KEY, _FILL, _AMBIENT = 0.68, 0.10, 0.22
"""Light intensities; they sum to 1, so a fully lit surface shows its albedo and nothing clips."""


# --- camera ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Attributes:
        position: (3,) eye position [m].
        target: (3,) point looked at [m].
        up: (3,) approximate up direction (need not be unit or orthogonal to the view).
        fov_degrees: vertical field of view [deg], in (0, 180).
    """

    position: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov_degrees: float = 35.0

    def __post_init__(self) -> None:
        for name in ("position", "target", "up"):
            value = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise InputError("camera", name, f"{getattr(self, name)!r} is not a finite 3-vector",
                                 "pass three finite numbers")
            object.__setattr__(self, name, tuple(float(v) for v in value))
        fov = float(self.fov_degrees)
        if not 0.0 < fov < 180.0:
            raise InputError("camera", "fov_degrees", f"{self.fov_degrees!r} is outside (0, 180)",
                             "pass a vertical field of view in degrees, e.g. 35")
        object.__setattr__(self, "fov_degrees", fov)
        forward = np.subtract(self.target, self.position)
        if np.linalg.norm(forward) == 0.0:
            raise InputError("camera", "target", "target equals position", "look at a point away from the eye")
        if np.linalg.norm(np.cross(forward, self.up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(self.up):
            raise InputError("camera", "up", "up is zero or parallel to the view direction",
                             "pass an up vector across the view, e.g. (0, 0, 1), or (0, 1, 0) looking down")

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit (forward, right, up) vectors of the image frame, float64 (3,) each."""
        forward = np.subtract(self.target, self.position)
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right = right / np.linalg.norm(right)
        return forward, right, np.cross(right, forward)

    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """Pixel coordinates (column, row) of world points, float64 (n, 2); row 0 is the top of the image.

        Pixel (c, r) covers [c, c+1) x [r, r+1); ``np.floor`` gives its index. Points behind the
        camera get NaN.
        """
        forward, right, up = self.basis()
        relative = np.atleast_2d(np.asarray(points, dtype=np.float64)) - np.asarray(self.position)
        depth = relative @ forward
        tan_v = math.tan(math.radians(self.fov_degrees) / 2.0)
        tan_h = tan_v * width / height
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(depth > 0.0, (relative @ right) / (depth * tan_h), np.nan)
            y = np.where(depth > 0.0, (relative @ up) / (depth * tan_v), np.nan)
        return np.stack([(x + 1.0) * 0.5 * width, (1.0 - y) * 0.5 * height], axis=1)


def fit_camera(bounds_min: np.ndarray, bounds_max: np.ndarray, view: str = "three-quarter", *,
               aspect: float = 4.0 / 3.0, fov_degrees: float = 35.0, margin: float = 1.1) -> Camera:
    """A camera that frames an axis-aligned box from a named view.

    The camera looks at the box centre from the direction of ``VIEWS[view]`` and backs off until
    all eight corners lie inside the image, with ``margin`` of room on each side. Fit it once to
    the box of a whole animation (see :func:`pscc.render.video.render_run`) so videos do not jitter.

    Args:
        bounds_min: (3,) lower box corner [m].
        bounds_max: (3,) upper box corner [m].
        view: one of :data:`VIEWS` ("three-quarter", "front", "side", "top").
        aspect: image width / height.
        fov_degrees: vertical field of view [deg].
        margin: factor >= 1 on the half-extents the image must hold.

    Raises:
        InputError: non-finite or inverted bounds, an unknown view, a bad aspect, fov or margin.
    """
    lower = np.asarray(bounds_min, dtype=np.float64).reshape(-1)
    upper = np.asarray(bounds_max, dtype=np.float64).reshape(-1)
    if lower.shape != (3,) or upper.shape != (3,) or not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise InputError("argument", "bounds", "bounds_min and bounds_max must be finite 3-vectors",
                         "pass the scene's lower and upper corners")
    if np.any(upper < lower):
        raise InputError("argument", "bounds", f"bounds_max {upper} is below bounds_min {lower}",
                         "swap the corners")
    if view not in VIEWS:
        raise InputError("argument", "view", f"unknown view {view!r}", f"use one of {', '.join(VIEWS)}")
    if not (math.isfinite(aspect) and aspect > 0.0 and math.isfinite(margin) and margin >= 1.0):
        raise InputError("argument", "aspect/margin", f"aspect {aspect!r} must be > 0 and margin {margin!r} >= 1",
                         "pass width / height and a margin such as 1.1")
    if not 0.0 < fov_degrees < 180.0:
        raise InputError("argument", "fov_degrees", f"{fov_degrees!r} is outside (0, 180)", "pass e.g. 35")
    azimuth, elevation = (math.radians(a) for a in VIEWS[view])
    toward_eye = np.array([math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                           math.sin(elevation)])
    up = (0.0, 1.0, 0.0) if abs(toward_eye[2]) > 0.999 else (0.0, 0.0, 1.0)
    center = 0.5 * (lower + upper)
    radius = 0.5 * float(np.linalg.norm(upper - lower))
    if radius <= 0.0:
        radius = 1.0  # a single point: frame a unit ball around it
    corners = np.array([[(lower, upper)[(i >> k) & 1][k] for k in range(3)] for i in range(8)]) - center
    right = np.cross(-toward_eye, up)
    right /= np.linalg.norm(right)
    image_up = np.cross(right, -toward_eye)
    tan_v = math.tan(math.radians(fov_degrees) / 2.0)
    tan_h = tan_v * aspect
    # Eye at center + d * toward_eye; a corner p is inside when |p.right| <= tan_h * (d - p.toward_eye).
    along = corners @ toward_eye
    needed = np.maximum(margin * np.abs(corners @ right) / tan_h, margin * np.abs(corners @ image_up) / tan_v) + along
    distance = max(float(needed.max()), float(along.max()) + 0.1 * radius, 0.5 * radius)
    position = center + distance * toward_eye
    return Camera(tuple(position), tuple(center), up, fov_degrees)


# --- kernels --------------------------------------------------------------------------------------


@wp.struct
class CameraArgs:
    """A camera in kernel form: a ray through normalised image coordinates (x, y) in [-1, 1]^2 has the
    direction ``forward + x * right + y * up`` (``right`` and ``up`` scaled by the field of view)."""

    origin: wp.vec3
    forward: wp.vec3
    right: wp.vec3
    up: wp.vec3


@wp.struct
class ShadingArgs:
    """Lights, ground and background of one frame; colours are linear RGB, lengths in metres."""

    light_direction: wp.vec3  # unit, from the surface toward the key light
    key_intensity: float
    fill_intensity: float
    ambient_intensity: float
    shadows: wp.int32  # 0/1
    ground: wp.int32  # 0 none, 1 plain, 2 checker
    ground_z: float
    ground_center: wp.vec3
    ground_fade_begin: float  # horizontal distance from ground_center where the ground starts fading
    ground_fade_end: float  # ... and where only the background is left
    checker_size: float
    ground_color_a: wp.vec3
    ground_color_b: wp.vec3
    background_bottom: wp.vec3
    background_top: wp.vec3
    ray_offset: float  # shadow-ray start offset along the normal
    max_distance: float  # rays end here


@wp.func
def _light_visibility(mesh: wp.uint64, has_mesh: wp.int32, point: wp.vec3, shading: ShadingArgs) -> float:
    """1 when the key light reaches ``point`` (already offset off its surface), 0 in shadow."""
    if has_mesh == 0 or shading.shadows == 0:
        return 1.0
    query = wp.mesh_query_ray(mesh, point, shading.light_direction, shading.max_distance)
    if query.result:
        return 0.0
    return 1.0


@wp.func
def _trace_ray(mesh: wp.uint64, has_mesh: wp.int32, face_color: wp.array(dtype=wp.vec3), origin: wp.vec3,
               direction: wp.vec3, background: wp.vec3, shading: ShadingArgs) -> wp.vec3:
    """Linear colour seen along a unit ray: the nearest of mesh and ground, shaded, else the background."""
    hit_t = shading.max_distance
    face = int(-1)
    normal = wp.vec3(0.0, 0.0, 1.0)
    if has_mesh != 0:
        query = wp.mesh_query_ray(mesh, origin, direction, shading.max_distance)
        if query.result:
            hit_t = query.t
            face = query.face
            normal = query.normal
    on_ground = int(0)
    if shading.ground != 0 and direction[2] < 0.0 and origin[2] > shading.ground_z:
        ground_t = (shading.ground_z - origin[2]) / direction[2]
        if ground_t < hit_t:
            hit_t = ground_t
            on_ground = 1
    if on_ground == 0 and face < 0:
        return background
    point = origin + hit_t * direction
    if on_ground == 1:
        albedo = shading.ground_color_a
        if shading.ground == 2:
            ix = int(wp.floor(point[0] / shading.checker_size))
            iy = int(wp.floor(point[1] / shading.checker_size))
            if ((ix + iy) & 1) == 1:
                albedo = shading.ground_color_b
        light = shading.ambient_intensity - shading.fill_intensity * direction[2]
        up_dot_light = shading.light_direction[2]
        if up_dot_light > 0.0:
            start = point + wp.vec3(0.0, 0.0, shading.ray_offset)
            light += shading.key_intensity * up_dot_light * _light_visibility(mesh, has_mesh, start, shading)
        dx = point[0] - shading.ground_center[0]
        dy = point[1] - shading.ground_center[1]
        fade = wp.smoothstep(shading.ground_fade_begin, shading.ground_fade_end, wp.sqrt(dx * dx + dy * dy))
        return wp.lerp(albedo * light, background, fade)
    # Two-sided: light the side that faces the camera.
    if wp.dot(normal, direction) > 0.0:
        normal = -normal
    light = shading.ambient_intensity - shading.fill_intensity * wp.dot(normal, direction)
    normal_dot_light = wp.dot(normal, shading.light_direction)
    if normal_dot_light > 0.0:
        start = point + shading.ray_offset * normal
        light += shading.key_intensity * normal_dot_light * _light_visibility(mesh, has_mesh, start, shading)
    return face_color[face] * light


@wp.func
def _encode_srgb(value: float, inverse_gamma: float) -> wp.uint8:
    """Linear [0, 1] -> rounded 8-bit gamma-encoded value."""
    return wp.uint8(int(wp.pow(wp.clamp(value, 0.0, 1.0), inverse_gamma) * 255.0 + 0.5))


@wp.kernel
def _render_pixels(
    # in:
    mesh: wp.uint64,
    has_mesh: wp.int32,
    face_color: wp.array(dtype=wp.vec3),
    camera: CameraArgs,
    shading: ShadingArgs,
    samples_per_axis: wp.int32,
    seed: wp.int32,
    inverse_gamma: float,
    # out:
    image: wp.array3d(dtype=wp.uint8),
):
    """One thread per pixel: trace samples_per_axis^2 jittered primary rays, average, write sRGB bytes."""
    row, column = wp.tid()
    height = image.shape[0]
    width = image.shape[1]
    state = wp.rand_init(seed, row * width + column)
    n = samples_per_axis
    total = wp.vec3(0.0)
    for sample in range(n * n):
        jitter_x = 0.5
        jitter_y = 0.5
        if n > 1:
            jitter_x = wp.randf(state)
            jitter_y = wp.randf(state)
        sx = (float(sample % n) + jitter_x) / float(n)
        sy = (float(sample // n) + jitter_y) / float(n)
        x = 2.0 * (float(column) + sx) / float(width) - 1.0
        y = 1.0 - 2.0 * (float(row) + sy) / float(height)
        direction = wp.normalize(camera.forward + x * camera.right + y * camera.up)
        background = wp.lerp(shading.background_bottom, shading.background_top, 0.5 * (y + 1.0))
        total += _trace_ray(mesh, has_mesh, face_color, camera.origin, direction, background, shading)
    color = total / float(n * n)
    image[row, column, 0] = _encode_srgb(color[0], inverse_gamma)
    image[row, column, 1] = _encode_srgb(color[1], inverse_gamma)
    image[row, column, 2] = _encode_srgb(color[2], inverse_gamma)


# --- host -----------------------------------------------------------------------------------------


def _nice_length(length: float) -> float:
    """The number of the form {1, 2, 5} x 10^k nearest below ``length`` (> 0)."""
    exponent = math.floor(math.log10(length))
    for step in (5.0, 2.0, 1.0):
        if step * 10.0**exponent <= length:
            return step * 10.0**exponent
    return 10.0**exponent


def _check_faces(value: object, name: str, vertex_count: int) -> np.ndarray:
    """Validate (m, 3) integer triangles indexing ``vertex_count`` vertices; return int32."""
    array = as_numpy(value)
    if array.size == 0:
        return np.zeros((0, 3), np.int32)
    if array.dtype.kind not in "iu" or array.ndim != 2 or array.shape[1] != 3:
        raise InputError("argument", name, f"dtype {array.dtype}, shape {array.shape} is not integer (m, 3)",
                         "pass triangle vertex ids as an (m, 3) integer array")
    if array.min() < 0 or array.max() >= vertex_count:
        raise InputError("argument", name, f"vertex ids span [{array.min()}, {array.max()}], "
                         f"outside [0, {vertex_count})", "pass faces that index the vertex array given with them")
    return np.ascontiguousarray(array, dtype=np.int32)


def _check_vertices(value: object, name: str) -> np.ndarray:
    """Validate (n, 3) finite points (empty allowed); return float32."""
    array = as_numpy(value)
    if array.size == 0:
        return np.zeros((0, 3), np.float32)
    return check_points(array, name, shape_tail=(3,))


class Renderer:
    """Ray-casts cloth frames to 8-bit RGB images, one thread per pixel.

    Buffers (on ``self.device``)::

        image         (height, width, 3) uint8   sRGB output, row 0 at the top
        points        (n + k,) vec3              cloth vertices, then obstacle vertices [m]
        indices       (3 (m + l),) int32         cloth faces, then obstacle faces (offset by n)
        face_color    (m + l,) vec3              linear albedo per face: PALETTE[object_id % 8] / grey
        mesh          wp.Mesh over points/indices, rebuilt when the faces change, refit otherwise

    Args:
        width: image width [pixels].
        height: image height [pixels].
        device: Warp device (default: Warp's default device).
        antialias: samples per pixel side: 1 = one ray through the pixel centre, 2 = 2x2
            jittered samples (fixed seed: deterministic), ...
        ground: "checker", "plain" or "none".
        shadows: cast shadow rays toward the key light.
        light_direction: (3,) direction from the scene toward the key light (normalised here).
        seed: seed of the anti-aliasing jitter.
    """

    def __init__(self, width: int, height: int, device: wp.Device | str | None = None, *, antialias: int = 1,
                 ground: str = "checker", shadows: bool = True,
                 light_direction: tuple[float, float, float] = (-0.35, -0.45, 1.0), seed: int = 0) -> None:
        for name, value in (("width", width), ("height", height), ("antialias", antialias)):
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise InputError("argument", name, f"{value!r} is not a positive integer", "pass an integer >= 1")
        if antialias > 8:
            raise InputError("argument", "antialias", f"{antialias} samples per pixel side is too many",
                             "pass 1 (off) to 4")
        if ground not in ("checker", "plain", "none"):
            raise InputError("argument", "ground", f"unknown ground {ground!r}", "use checker, plain or none")
        light = np.asarray(light_direction, dtype=np.float64).reshape(-1)
        if light.shape != (3,) or not np.all(np.isfinite(light)) or np.linalg.norm(light) == 0.0:
            raise InputError("argument", "light_direction", f"{light_direction!r} is not a non-zero 3-vector",
                             "pass a direction toward the light, e.g. (-0.35, -0.45, 1)")
        self.width = int(width)
        self.height = int(height)
        self.device = wp.get_device(device)
        self.antialias = int(antialias)
        self.ground = ground
        self.shadows = bool(shadows)
        self.light_direction = light / np.linalg.norm(light)
        self.seed = int(seed)
        self.image = wp.zeros((self.height, self.width, 3), dtype=wp.uint8, device=self.device)
        self.mesh: wp.Mesh | None = None
        self.points: wp.array | None = None
        self.indices: wp.array | None = None
        self.face_color: wp.array | None = None
        self._faces = np.zeros((0, 3), np.int32)
        self._object_ids = np.zeros(0, np.int32)
        self._empty_colors = wp.zeros(1, dtype=wp.vec3, device=self.device)

    def render(self, cloth_vertices: np.ndarray, cloth_faces: np.ndarray, object_ids: np.ndarray,
               obstacle_vertices: np.ndarray | None = None, obstacle_faces: np.ndarray | None = None,
               camera: Camera | None = None, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Render one frame.

        Args:
            cloth_vertices: (vertex_count, 3) float positions [m].
            cloth_faces: (face_count, 3) int triangles.
            object_ids: (face_count,) int cloth piece of each triangle (picks its colour).
            obstacle_vertices: (k, 3) float positions [m], or None / empty.
            obstacle_faces: (l, 3) int triangles into obstacle_vertices, or None / empty.
            camera: the view; default ``fit_camera`` of ``bounds`` from the three-quarter view.
            bounds: (lower, upper) scene box [m] that fixes the default camera, the ground plane
                (at the lower z), the checker size and the ray offsets; default: this frame's
                box. Pass one box for every frame of an animation.

        Returns:
            (height, width, 3) uint8 sRGB image, row 0 at the top. A host copy: a sync point.

        Raises:
            InputError: malformed arrays (shapes, dtypes, indices out of range, NaN) or bounds.

        Allocates: yes (device copies of the frame; the mesh when the faces change). Capture-safe: no.
        """
        cloth_vertices = _check_vertices(cloth_vertices, "cloth_vertices")
        cloth_faces = _check_faces(cloth_faces, "cloth_faces", cloth_vertices.shape[0])
        object_ids = as_numpy(object_ids).reshape(-1) if object_ids is not None else np.zeros(0, np.int32)
        if object_ids.shape != (cloth_faces.shape[0],) or (object_ids.size and object_ids.dtype.kind not in "iu"):
            raise InputError("argument", "object_ids", f"shape {object_ids.shape}, dtype {object_ids.dtype} is not "
                             f"({cloth_faces.shape[0]},) integers", "pass one integer object id per cloth face")
        obstacle_vertices = _check_vertices(obstacle_vertices if obstacle_vertices is not None else (),
                                            "obstacle_vertices")
        obstacle_faces = _check_faces(obstacle_faces if obstacle_faces is not None else (), "obstacle_faces",
                                      obstacle_vertices.shape[0])
        points = np.concatenate([cloth_vertices, obstacle_vertices])
        faces = np.concatenate([cloth_faces, obstacle_faces + cloth_vertices.shape[0]])
        if bounds is None:
            bounds = scene_bounds(points)
        lower, upper = (np.asarray(b, dtype=np.float64).reshape(-1) for b in bounds)
        if lower.shape != (3,) or upper.shape != (3,) or not np.all(np.isfinite(np.concatenate([lower, upper]))):
            raise InputError("argument", "bounds", "bounds must be two finite 3-vectors", "pass (lower, upper)")
        if camera is None:
            camera = fit_camera(lower, upper, aspect=self.width / self.height)
        self._upload(points, faces, object_ids.astype(np.int32), obstacle_faces.shape[0])
        has_mesh = 1 if self.mesh is not None else 0
        wp.launch(_render_pixels, dim=(self.height, self.width),
                  inputs=[self.mesh.id if has_mesh else wp.uint64(0), has_mesh,
                          self.face_color if has_mesh else self._empty_colors,
                          self._camera_args(camera), self._shading_args(lower, upper, camera), self.antialias,
                          self.seed, 1.0 / _GAMMA],
                  outputs=[self.image], device=self.device)
        return self.image.numpy()

    def _upload(self, points: np.ndarray, faces: np.ndarray, object_ids: np.ndarray, obstacle_face_count: int) -> None:
        """Copy the frame to the device: refit the mesh when the faces are unchanged, else rebuild it."""
        if faces.shape[0] == 0:
            self.mesh = self.points = self.indices = self.face_color = None
            self._faces = faces
            return
        same_faces = self.mesh is not None and np.array_equal(faces, self._faces)
        if same_faces and self.points is not None and self.points.shape[0] == points.shape[0]:
            self.points.assign(points)
            self.mesh.refit()
        else:
            self.points = wp.array(points, dtype=wp.vec3, device=self.device)
            self.indices = wp.array(faces.reshape(-1), dtype=wp.int32, device=self.device)
            self.mesh = wp.Mesh(points=self.points, indices=self.indices)
            self._faces = faces.copy()
            self._object_ids = None  # colours must be uploaded for the new faces
        if self._object_ids is None or not np.array_equal(object_ids, self._object_ids):
            srgb = np.concatenate([PALETTE[np.mod(object_ids, PALETTE.shape[0])],
                                   np.broadcast_to(OBSTACLE_COLOR, (obstacle_face_count, 3))])
            self.face_color = wp.array(np.power(srgb, _GAMMA).astype(np.float32), dtype=wp.vec3, device=self.device)
            self._object_ids = object_ids.copy()

    def _camera_args(self, camera: Camera) -> CameraArgs:
        forward, right, up = camera.basis()
        tan_v = math.tan(math.radians(camera.fov_degrees) / 2.0)
        args = CameraArgs()
        args.origin = wp.vec3(*camera.position)
        args.forward = wp.vec3(*forward)
        args.right = wp.vec3(*(right * tan_v * self.width / self.height))
        args.up = wp.vec3(*(up * tan_v))
        return args

    def _shading_args(self, lower: np.ndarray, upper: np.ndarray, camera: Camera) -> ShadingArgs:
        diagonal = float(np.linalg.norm(upper - lower))
        scale = diagonal if diagonal > 0.0 else 1.0
        radius = 0.5 * scale
        center = 0.5 * (lower + upper)
        linear = np.power(np.concatenate([GROUND_COLORS, BACKGROUND_COLORS]), _GAMMA)
        args = ShadingArgs()
        args.light_direction = wp.vec3(*self.light_direction)
        args.key_intensity = _KEY
        args.fill_intensity = _FILL
        args.ambient_intensity = _AMBIENT
        args.shadows = int(self.shadows)
        args.ground = {"none": 0, "plain": 1, "checker": 2}[self.ground]
        args.ground_z = float(lower[2]) - _RAY_OFFSET * scale  # just below: cloth lying on it does not flicker
        args.ground_center = wp.vec3(float(center[0]), float(center[1]), float(lower[2]))
        args.ground_fade_begin = 1.5 * radius
        args.ground_fade_end = 4.0 * radius
        args.checker_size = _nice_length(scale / 6.0)
        args.ground_color_a = wp.vec3(*linear[0])
        args.ground_color_b = wp.vec3(*linear[1])
        args.background_bottom = wp.vec3(*linear[2])
        args.background_top = wp.vec3(*linear[3])
        args.ray_offset = _RAY_OFFSET * scale
        eye_distance = float(np.linalg.norm(np.asarray(camera.position) - center))
        args.max_distance = 100.0 * (scale + eye_distance)
        return args


def scene_bounds(*point_sets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) float64 corners of the box of all given (n, 3) point sets; a unit box at 0 if none."""
    stacked = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in point_sets]
    stacked = [p for p in stacked if p.shape[0]]
    if not stacked:
        return np.full(3, -0.5), np.full(3, 0.5)
    points = np.concatenate(stacked)
    return points.min(axis=0), points.max(axis=0)
