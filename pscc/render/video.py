"""PNG and MP4 output of rendered frames (imageio v3; ffmpeg from the ``imageio-ffmpeg`` wheel), and
:func:`render_run`, which turns a ``pscc simulate`` run folder into ``preview.png`` and ``animation.mp4``.

Every file is written atomically (:mod:`pscc._atomic`): to a temporary file in the destination folder,
then renamed with ``os.replace``, so a reader never sees half a file and a failed write leaves nothing behind.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pscc._atomic import atomic_output
from pscc.errors import InputError
from pscc.io.frames import read_frame
from pscc.render.raycast import Camera, Renderer, fit_camera, scene_bounds

_BOUNDS_SAMPLES = 5
"""Frames (evenly spaced, always the first and the last) whose union box fixes an animation's camera."""


def _check_image(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Validate an (height, width, 3) uint8 image."""
    array = np.asarray(image)
    if array.dtype != np.uint8 or array.ndim != 3 or array.shape[2] != 3 or array.shape[0] < 1 or array.shape[1] < 1:
        raise InputError("argument", name, f"dtype {array.dtype}, shape {array.shape} is not (height, width, 3) uint8",
                         "pass an image from Renderer.render")
    return np.ascontiguousarray(array)


def _write_atomic(path: Path, write: Callable[[str], None]) -> Path:
    """Call ``write(temporary_path)`` for a sibling of ``path`` with the same suffix, then rename it to ``path``."""
    with atomic_output(path) as temporary:
        write(str(temporary))
    return Path(path)


def write_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (height, width, 3) uint8 RGB image as a PNG, atomically; return the path.

    Raises:
        InputError: the image is not (height, width, 3) uint8.
    """
    import imageio.v3 as iio

    image = _check_image(image)
    return _write_atomic(Path(path), lambda temporary: iio.imwrite(temporary, image, extension=".png"))


def write_mp4(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float, *, quality: float = 8.0) -> int:
    """Encode (height, width, 3) uint8 frames as an H.264 MP4 (yuv420p), streaming, atomically.

    Frames are consumed one at a time (never all in memory). H.264 in yuv420p needs even sizes:
    an odd width or height is padded by repeating the last column or row.

    Args:
        path: destination, normally ``*.mp4``.
        frames: iterable of images of one size.
        fps: frames per second (> 0).
        quality: imageio-ffmpeg's variable-bitrate quality, 0 (worst) to 10 (best).

    Returns:
        The number of frames written.

    Raises:
        InputError: bad fps, no frames, a frame that is not uint8 RGB or changes size.
    """
    import imageio.v3 as iio

    fps = float(fps)
    if not np.isfinite(fps) or fps <= 0.0:
        raise InputError("argument", "fps", f"{fps!r} is not a positive number", "pass frames per second, e.g. 30")
    count = 0
    first_shape: tuple[int, ...] | None = None

    def checked() -> Iterator[np.ndarray]:
        nonlocal count, first_shape
        for frame in frames:
            frame = _check_image(frame, f"frames[{count}]")
            if first_shape is None:
                first_shape = frame.shape
            elif frame.shape != first_shape:
                raise InputError("argument", f"frames[{count}]", f"shape {frame.shape} differs from the first "
                                 f"frame's {first_shape}", "render every frame at one size")
            pad = ((0, frame.shape[0] % 2), (0, frame.shape[1] % 2), (0, 0))
            count += 1
            yield np.pad(frame, pad, mode="edge") if any(p[1] for p in pad[:2]) else frame

    stream = checked()
    try:
        first = next(stream)
    except StopIteration:
        raise InputError("argument", "frames", "no frames to encode", "pass at least one frame") from None

    failure: list[BaseException] = []

    def guarded() -> Iterator[np.ndarray]:
        # imageio leaves ffmpeg running when the frame iterable raises (it closes its writer only on
        # success), and ffmpeg would then re-create the temporary file after it is removed. So a
        # failing stream just ends here, the video is closed normally, and the error is re-raised.
        try:
            yield first
            yield from stream
        except (Exception, KeyboardInterrupt) as exc:
            failure.append(exc)

    def encode(temporary: str) -> None:
        iio.imwrite(temporary, guarded(), plugin="FFMPEG", is_batch=True, fps=fps, codec="libx264",
                    quality=quality, macro_block_size=1, pixelformat="yuv420p")
        if failure:
            raise failure[0]

    _write_atomic(Path(path), encode)
    return count


def _frame_paths(out_dir: Path) -> list[Path]:
    """Sorted ``out_dir/frames/frame_*.npz``; InputError naming the folder when there are none."""
    folder = Path(out_dir) / "frames"
    paths = sorted(folder.glob("frame_*.npz")) if folder.is_dir() else []
    if not paths:
        raise InputError(str(folder), "frame_*.npz", "no frame files found",
                         "pass the --out-dir of a finished `pscc simulate` run (it holds frames/frame_00000.npz, ...)")
    return paths


def _read(path: Path) -> dict[str, np.ndarray]:
    """One frame, with unreadable files turned into an InputError naming the file."""
    try:
        return read_frame(path)
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(str(path), "npz", f"unreadable frame file ({type(exc).__name__}: {exc})",
                         "re-run the simulation or delete the damaged frame") from exc


def animation_bounds(paths: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) box of the cloth and obstacles over a few evenly spaced frames (first and last included).

    Used to fix one camera and one ground plane for a whole animation.
    """
    picks = sorted({round(i * (len(paths) - 1) / max(_BOUNDS_SAMPLES - 1, 1)) for i in range(_BOUNDS_SAMPLES)})
    lowers, uppers = [], []
    for index in picks:
        frame = _read(paths[index])
        lower, upper = scene_bounds(frame["vertices"], frame["obstacle_vertices"])
        lowers.append(lower)
        uppers.append(upper)
    return np.min(lowers, axis=0), np.max(uppers, axis=0)


def render_run(out_dir: str | os.PathLike, *, width: int = 640, height: int = 480, fps: float = 30.0,
               antialias: int = 2, camera: Camera | None = None, view: str = "three-quarter",
               device: str | None = None, progress: bool = True) -> tuple[Path, Path]:
    """Render a simulation run folder: ``out_dir/preview.png`` (the last frame) and ``out_dir/animation.mp4``.

    Reads ``out_dir/frames/frame_*.npz`` in name order. One camera and one ground plane serve
    every frame (fitted to the union box of the first, last and a few frames between, unless
    ``camera`` is given), so the video does not jitter.

    Args:
        out_dir: the run folder (``pscc simulate --out-dir``).
        width: image width [pixels].
        height: image height [pixels].
        fps: video frame rate [1/s].
        antialias: samples per pixel side (1 = off, 2 = 2x2).
        camera: a fixed camera; default :func:`fit_camera` of the animation's box from ``view``.
        view: named view for the default camera (see :data:`pscc.render.raycast.VIEWS`).
        device: Warp device to render on.
        progress: show a tqdm progress bar on stderr.

    Returns:
        (preview path, animation path).

    Raises:
        InputError: no frame files (the message names the frames folder), an unreadable or
            malformed frame (names the file), or bad options.
    """
    out_dir = Path(out_dir)
    paths = _frame_paths(out_dir)
    renderer = Renderer(width, height, device, antialias=antialias)
    bounds = animation_bounds(paths)
    if camera is None:
        camera = fit_camera(*bounds, view=view, aspect=width / height)
    last: list[np.ndarray] = []

    def frames() -> Iterator[np.ndarray]:
        for path in tqdm(paths, desc="render", unit="frame", disable=not progress):
            frame = _read(path)
            try:
                image = renderer.render(frame["vertices"], frame["faces"], frame["object_ids"],
                                        frame["obstacle_vertices"], frame["obstacle_faces"], camera=camera,
                                        bounds=bounds)
            except InputError as exc:
                raise InputError(str(path), exc.field, exc.problem, exc.fix) from exc
            last[:] = [image]
            yield image

    animation = out_dir / "animation.mp4"
    write_mp4(animation, frames(), fps)
    preview = write_png(out_dir / "preview.png", last[0])
    return preview, animation
