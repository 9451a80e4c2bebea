"""A corpus of cloth frames that were not designed for pscc, for the broad-phase comparison (issue 14).

The broad-phase section (:mod:`pscc.bench.broad_phase`) measures generated three-layer folded and
twisted sheets, which suit PSCC's culling. This corpus holds frames that other code produced:

* ``paper``: pscc's paper scenes (:mod:`pscc.scenes.paper`) at their smallest scale, simulated to a
  tangled moment: ``twisting`` after the ball has turned past 100 degrees, and the garment scenes
  (``kungfu``, ``falling``, ``dance``) mid-motion (half their default frame count). Their rest
  coordinates are the scene's ``rest`` (flat pattern or sheet coordinates); object ids are the
  scene's cloth pieces.
* ``newton``: Newton's stock cloth examples (``newton.examples.cloth``), built as shipped with a
  headless ``ViewerNull`` and stepped on the benchmark's device. The frame is the example model's
  whole triangle mesh (every cloth mesh it added) at a late frame; the rest coordinates are the
  positions the example built its model from (``model.particle_q``: the stress-free shape Newton's
  triangles keep), which for ``cloth_rollers`` is the rolled cloth and its rollers.
* ``usd``: Newton's shipped ``unisex_shirt.usd`` as shipped (read with ``pxr``); it has no rest.

Each frame runs DCD at its own contact radius (:func:`own_contact_radius`): a paper scene's cloth
thickness, a Newton example's self-contact margin; a shipped file, which has none, at half the median
edge length of its positions (:func:`half_median_edge`; the generated sheets of
:mod:`pscc.bench.broad_phase` use half the mean, which equals it there but which a few long edges would
dominate). Simulated frames are cached as ``.npz`` files under a
cache folder (``bench-output/corpus`` by default), keyed by source, frame and :data:`CACHE_VERSION`,
so later runs only read them.
"""

from __future__ import annotations

import importlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

__all__ = [
    "CACHE_VERSION", "DEFAULT_CACHE_DIR", "FULL_CORPUS", "QUICK_CORPUS", "SKIPPED_EXAMPLES", "CorpusFrame",
    "FrameSpec", "NEWTON_CONTACT_MARGINS", "USD_TIME_NOTE", "fan_triangles", "half_mean_edge", "half_median_edge",
    "load_corpus", "load_frame", "own_contact_radius", "read_usd_meshes",
]

CACHE_VERSION: int = 1
"""Bumped when a frame recipe changes, so stale cached frames are not reused."""

DEFAULT_CACHE_DIR: Path = Path("bench-output") / "corpus"
"""Where simulated frames are cached (``make clean`` removes ``bench-output``)."""


def half_mean_edge(positions: np.ndarray, faces: np.ndarray) -> float:
    """Half the mean length of the first edge of every face (the benchmark's DCD contact radius)."""
    a = positions[faces[:, 0]].astype(np.float64)
    b = positions[faces[:, 1]].astype(np.float64)
    return float(0.5 * np.linalg.norm(a - b, axis=1).mean())


def half_median_edge(positions: np.ndarray, faces: np.ndarray) -> float:
    """Half the median length of the mesh's edges (each edge once): the corpus frames' DCD contact radius.

    The median, unlike :func:`half_mean_edge`, ignores a few long edges, such as the 120 cm walls of
    ``cloth_rollers``' rollers next to its 2.7 x 7 cm cloth cells.
    """
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges = np.unique(edges, axis=0)
    lengths = np.linalg.norm(positions[edges[:, 0]].astype(np.float64) - positions[edges[:, 1]], axis=1)
    return float(0.5 * np.median(lengths))


@dataclass(frozen=True, eq=False)
class CorpusFrame:
    """One frame of the corpus.

    Attributes:
        name: short label, e.g. ``"twisting f48"``.
        source: where the frame came from, in words (scene, frames, scale, turn angle, file).
        positions: (n, 3) float32 vertex positions.
        faces: (m, 3) int32 triangles.
        rest: (n, 2) or (n, 3) float32 rest (material) coordinates, or None where the source has none.
        object_ids: (m,) int32 piece of each face, or None for one object.
        radius: DCD contact radius (:func:`own_contact_radius`, else :func:`half_median_edge` of the positions).
        check: the frame was added to the corpus as a check after the other frames had been tuned on
            (:attr:`FrameSpec.check`; not stored in the cached file).
    """

    name: str
    source: str
    positions: np.ndarray
    faces: np.ndarray
    rest: np.ndarray | None
    object_ids: np.ndarray | None
    radius: float
    check: bool = False

    @property
    def face_count(self) -> int:
        """Number of triangles."""
        return int(self.faces.shape[0])

    def save(self, path: Path) -> None:
        """Write the frame to an ``.npz`` file (:func:`CorpusFrame.load` reads it back)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        extra = {} if self.rest is None else {"rest": self.rest}
        if self.object_ids is not None:
            extra["object_ids"] = self.object_ids
        np.savez_compressed(path, positions=self.positions, faces=self.faces, name=np.array(self.name),
                            source=np.array(self.source), **extra)

    @classmethod
    def load(cls, path: Path) -> CorpusFrame:
        """Read a frame written by :meth:`save`."""
        with np.load(path) as data:
            positions = np.ascontiguousarray(data["positions"], dtype=np.float32)
            faces = np.ascontiguousarray(data["faces"], dtype=np.int32)
            rest = np.ascontiguousarray(data["rest"], dtype=np.float32) if "rest" in data else None
            ids = np.ascontiguousarray(data["object_ids"], dtype=np.int32) if "object_ids" in data else None
            return cls(str(data["name"]), str(data["source"]), positions, faces, rest, ids,
                       half_median_edge(positions, faces))

    def without_rest(self) -> CorpusFrame:
        """The same frame with no rest coordinates."""
        return CorpusFrame(self.name, self.source, self.positions, self.faces, None, self.object_ids, self.radius)

    def moved(self, offset: float = 1000.0) -> CorpusFrame:
        """The frame moved by ``offset`` length units along each axis (rest coordinates kept as they are):
        how a frame exported from a scene whose cloth is not at the origin looks. The positions are rounded
        to float32 after the move, as an exporter would write them. Not an exported frame: a check that the
        float32 rounding bounds of the detector scale with the frame's extent, not its distance from the
        origin."""
        moved = (self.positions.astype(np.float64) + float(offset)).astype(np.float32)
        return CorpusFrame(f"{self.name} moved {offset:g}", f"{self.source}; moved {offset:g} along each axis",
                           moved, self.faces, self.rest, self.object_ids, self.radius)

    def with_ground(self, scale: float = 50.0) -> CorpusFrame:
        """The frame without rest coordinates plus a ground quad (two triangles, a piece of its own)
        ``scale`` times the frame's extent, two contact radii below its lowest point on the y axis (so it adds
        no contact): how frames exported with a ground mesh look. Not an exported frame: a check of the grid
        against very large faces."""
        lower = self.positions.min(axis=0)
        upper = self.positions.max(axis=0)
        centre = 0.5 * (lower + upper)
        half = scale * float((upper - lower).max())
        below = float(lower[1]) - 2.0 * self.radius
        corners = np.array([[centre[0] - half, below, centre[2] - half], [centre[0] + half, below, centre[2] - half],
                            [centre[0] + half, below, centre[2] + half], [centre[0] - half, below, centre[2] + half]],
                           dtype=np.float32)
        n = self.positions.shape[0]
        faces = np.concatenate([self.faces, np.array([[n, n + 1, n + 2], [n, n + 2, n + 3]], dtype=np.int32)])
        ids = np.zeros(self.face_count, dtype=np.int32) if self.object_ids is None else self.object_ids
        ids = np.concatenate([ids, np.full(2, int(ids.max()) + 1, dtype=np.int32)])
        return CorpusFrame(f"{self.name} + ground", f"{self.source}; plus a ground quad {scale:g} times its extent",
                           np.concatenate([self.positions, corners]), faces, None, ids, self.radius)


@dataclass(frozen=True)
class FrameSpec:
    """A recipe for one corpus frame.

    Attributes:
        kind: ``"paper"`` (a pscc paper scene), ``"newton"`` (a Newton cloth example) or ``"usd"`` (a
            shipped USD mesh).
        name: the paper scene, the example (``twist`` for ``example_cloth_twist``) or the asset file.
        frames: frames simulated before the frame is taken (0 for a file).
        check: added after the other frames had been tuned on, as a check of their choice (the bench
            tallies its targets separately).
    """

    kind: str
    name: str
    frames: int = 0
    check: bool = False

    @property
    def cache_name(self) -> str:
        """The file name of the cached frame."""
        return f"{self.kind}-{self.name.replace('.', '_')}-f{self.frames}-v{CACHE_VERSION}.npz"


FULL_CORPUS: tuple[FrameSpec, ...] = (
    # twisting: the ball turns from 1.0 s (frame 25) to 2.5 s; at frame 48 (1.92 s) it has turned 120 degrees.
    FrameSpec("paper", "twisting", 48),
    FrameSpec("paper", "kungfu", 42),
    FrameSpec("paper", "falling", 24),
    FrameSpec("paper", "dance", 36),
    # cloth_twist: both ends turn at 60 degrees/s against each other; frame 180 (3 s) is a full turn.
    FrameSpec("newton", "twist", 180),
    # cloth_hanging: a sheet pinned along one side swings down and folds.
    FrameSpec("newton", "hanging", 90),
    # cloth_rollers: a cloth rolled on one roller (many layers 0.4 cm apart) starts to unroll onto the
    # other (about 13 s a frame on 2 CPU cores, so only its first frames).
    FrameSpec("newton", "rollers", 3),
    # cloth_poker_cards: 52 stiff cards (48 triangles each) falling into a stack on a cube (about 4 s a
    # frame on 2 CPU cores).
    FrameSpec("newton", "poker_cards", 15),
    FrameSpec("usd", "unisex_shirt.usd"),
    # Added after the frames above had been tuned on (2026-11-29), as a check of that choice: later moments
    # of the two twisting scenes (denser tangles than any frame above) and two more of Newton's shipped
    # meshes, closed surfaces rather than cloth.
    # twisting f56 (2.24 s): the ball has turned further than at frame 48.
    FrameSpec("paper", "twisting", 56, check=True),
    # cloth_twist f300 (5 s): one and two thirds of a turn.
    FrameSpec("newton", "twist", 300, check=True),
    FrameSpec("usd", "bunny.usd", check=True),
    FrameSpec("usd", "bear.usd", check=True),
    # Added later the same day (2026-11-29, evening), again as a check: Newton's two shipped CAD assemblies,
    # several rigid parts each (one object per mesh), slivers and thin walls. At half their median edge they
    # hold many true contacts (walls thinner than the radius, parts that touch): a dense-contact case that is
    # not cloth.
    FrameSpec("usd", "rj45_plug.usd", check=True),
    FrameSpec("usd", "crazyflie.usd", check=True),
    # Added the next session (2026-11-29, night), found while benching other shipped files with --frames:
    # Newton's axis_cube.usda, a cube of long slivers (its radius a third of their thin-face band), whose
    # detection once spent 8 of its 14 ms in the thin-face search.
    FrameSpec("usd", "axis_cube.usda", check=True),
)
"""The ``--corpus full`` frames (16; about 17 minutes to simulate the first time on 2 CPU cores, most of it
`cloth_twist` f180 and f300; then cached)."""

QUICK_CORPUS: tuple[FrameSpec, ...] = (
    FrameSpec("paper", "dance", 6),
    FrameSpec("newton", "hanging", 10),
    FrameSpec("usd", "unisex_shirt.usd"),
)
"""The ``--corpus quick`` frames: one of each kind, early frames (under a minute the first time)."""

SKIPPED_EXAMPLES: dict[str, str] = {
    "style3d": "downloads its garment and avatar assets (newton.utils.download_asset), which needs the network",
    "franka": "downloads the Franka robot (newton.utils.download_asset), which needs the network",
    "h1": "downloads the Unitree H1 robot and style3d garments (newton.utils.download_asset), which needs the "
          "network",
    "bending": "its cloth (curvedSurface.usd) is 12 triangles: a bending test with nothing to cull",
}
"""Newton cloth examples left out of the corpus, and why."""


def _paper_frame(spec: FrameSpec, device: str) -> CorpusFrame:
    from pscc.scenes import paper
    from pscc.sim.simulation import Simulation

    scale = paper.min_scale(spec.name)
    scene = paper.PAPER_SCENES[spec.name](scale)
    sim = Simulation(scene, device=device)
    for _ in range(spec.frames):
        sim.step_frame()
    positions = sim.state.positions.numpy()[: sim.solver.cloth_vertex_count].astype(np.float32)
    t = spec.frames * scene.frame_time
    source = f"pscc paper scene `{spec.name}` at scale {scale:.3g}, frame {spec.frames} ({t:.2f} s)"
    if spec.name == "twisting":
        rotation, _ = paper._ball_turn(t)
        source += f", ball turned {math.degrees(math.atan2(rotation[1, 0], rotation[0, 0])):.0f} degrees"
    faces = np.ascontiguousarray(scene.faces, dtype=np.int32)
    return CorpusFrame(f"{spec.name} f{spec.frames}", source, positions, faces,
                       np.ascontiguousarray(scene.rest, dtype=np.float32),
                       np.ascontiguousarray(scene.object_ids, dtype=np.int32), half_median_edge(positions, faces))


def _newton_frame(spec: FrameSpec, device: str) -> CorpusFrame:
    if spec.name in SKIPPED_EXAMPLES:
        raise RuntimeError(SKIPPED_EXAMPLES[spec.name])
    import newton.examples
    import newton.viewer

    module = importlib.import_module(f"newton.examples.cloth.example_cloth_{spec.name}")
    example_class = module.Example
    parser = example_class.create_parser() if hasattr(example_class, "create_parser") else (
        newton.examples.create_parser())
    args = parser.parse_args([])
    with wp.ScopedDevice(device):
        example = example_class(newton.viewer.ViewerNull(num_frames=spec.frames), args)
        rest = example.model.particle_q.numpy().astype(np.float32)
        for _ in range(spec.frames):
            example.step()
        positions = example.state_0.particle_q.numpy().astype(np.float32)
    faces = np.ascontiguousarray(example.model.tri_indices.numpy(), dtype=np.int32)
    if not np.all(np.isfinite(positions)):
        raise RuntimeError(f"Newton's cloth_{spec.name} gave non-finite positions after {spec.frames} frames")
    source = (f"Newton {_newton_version()} example `cloth_{spec.name}` (default arguments, headless), "
              f"frame {spec.frames}")
    return CorpusFrame(f"cloth_{spec.name} f{spec.frames}", source, positions, faces, rest, None,
                       half_median_edge(positions, faces))


def _newton_version() -> str:
    import newton

    return str(getattr(newton, "__version__", "?"))


USD_TIME_NOTE: str = "the default time when its points have a default value, else their first time sample"
"""Which time of a USD stage :func:`read_usd_meshes` reads when it is not given one."""


def read_usd_meshes(path: Path, usd_time: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, str]:
    """Every ``UsdGeom.Mesh`` of a USD stage as one triangle mesh: each mesh's points at ``usd_time`` (None:
    :data:`USD_TIME_NOTE`), moved by its local-to-world transform at that time, its polygons fan-triangulated
    (:func:`fan_triangles`), one object id per mesh. A polygon that visits a corner twice fans into
    triangles that repeat a vertex id, and two polygons over the same corners give a triangle twice; those
    are left out (the first of a repeated triangle kept), and ``what`` says how many.

    Returns:
        ``(positions (n, 3) float32, faces (m, 3) int32, object_ids (m,) int32 or None for one mesh, what)``,
        ``what`` saying in words which meshes and which time were read.

    Raises:
        InputError: the stage cannot be opened, holds no mesh, a mesh has no points or faces at that time or
            inconsistent face arrays, ``usd_time`` is outside a mesh's time samples, or the result fails
            :func:`pscc.mesh.mesh_data.validate_mesh`.
    """
    from pxr import Usd, UsdGeom

    from pscc.errors import InputError
    from pscc.mesh.io import open_usd_stage
    from pscc.mesh.mesh_data import validate_mesh

    source = str(path)
    stage = open_usd_stage(path, "export the frame again as USD (.usda, .usdc or .usdz)")
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise InputError(source, "file", "holds no UsdGeom.Mesh", "export the cloth as a polygon mesh")
    cache = UsdGeom.XformCache()
    blocks, face_blocks, ids = [], [], []
    offset = 0
    repeated = duplicated = 0
    for k, prim in enumerate(meshes):
        mesh = UsdGeom.Mesh(prim)
        points = mesh.GetPointsAttr()
        time = Usd.TimeCode.Default() if usd_time is None else Usd.TimeCode(usd_time)
        samples = points.GetTimeSamples()
        if usd_time is None and points.Get(time) is None and samples:
            time = Usd.TimeCode(samples[0])
        if usd_time is not None and samples and not samples[0] <= usd_time <= samples[-1]:
            raise InputError(source, f"{prim.GetPath()}.points", f"has time samples from {samples[0]:g} to "
                             f"{samples[-1]:g}, not at --usd-time {usd_time:g}", "give a time code in that range")
        values = points.Get(time)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int32)
        if values is None or counts.size == 0:
            raise InputError(source, str(prim.GetPath()), "has no points or no faces", "export the mesh's points "
                             "and faces, or leave the prim out")
        if np.any(counts < 3) or counts.sum() != indices.size:
            raise InputError(source, f"{prim.GetPath()}.faceVertexCounts", "does not match faceVertexIndices "
                             "(or a face has fewer than 3 corners)", "re-export the mesh")
        local = np.asarray(values, dtype=np.float64).reshape(-1, 3)
        cache.SetTime(time)
        matrix = np.asarray(cache.GetLocalToWorldTransform(prim), dtype=np.float64).reshape(4, 4)
        blocks.append(local @ matrix[:3, :3] + matrix[3, :3])  # USD matrices act on row vectors
        faces = fan_triangles(counts, indices)
        # A polygon that visits a corner twice fans into triangles that repeat a vertex id: no area, and
        # topology the detector refuses. They are left out (and counted in the description).
        repeats = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
        if np.all(repeats):
            raise InputError(source, f"{prim.GetPath()}.faceVertexIndices", "every polygon repeats a corner, so "
                             "no triangle is left", "re-export the mesh with simple polygons")
        repeated += int(np.count_nonzero(repeats))
        faces = faces[~repeats]
        # Two polygons over the same corners (or one fanned into the same triangle twice) give a triangle
        # twice: the first is kept.
        _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
        duplicated += faces.shape[0] - first.size
        faces = faces[np.sort(first)]
        face_blocks.append(faces + offset)
        ids.append(np.full(faces.shape[0], k, dtype=np.int32))
        offset += local.shape[0]
    mesh_data = validate_mesh(np.concatenate(blocks).astype(np.float32), np.concatenate(face_blocks), source=source,
                              object_ids=np.concatenate(ids))
    names = ", ".join(f"`{p.GetPath()}`" for p in meshes[:4]) + (" ..." if len(meshes) > 4 else "")
    when = USD_TIME_NOTE if usd_time is None else f"time code {usd_time:g}"
    what = f"{len(meshes)} mesh{'es' if len(meshes) > 1 else ''} ({names}) at {when}"
    if repeated:
        what += (f"; {repeated} fan triangle{'s' if repeated > 1 else ''} that repeat a vertex (polygons that visit "
                 "a corner twice) left out")
    if duplicated:
        what += (f"; {duplicated} triangle{'s' if duplicated > 1 else ''} over the same three corners as another "
                 "left out")
    return (mesh_data.vertices, mesh_data.faces, mesh_data.object_ids if len(meshes) > 1 else None, what)


def _usd_frame(spec: FrameSpec) -> CorpusFrame:
    import newton.examples

    path = Path(newton.examples.get_asset(spec.name))
    positions, faces, object_ids, what = read_usd_meshes(path)
    source = f"Newton's shipped `{spec.name}` ({what}), as shipped"
    return CorpusFrame(Path(spec.name).stem, source, positions, faces, None, object_ids,
                       half_median_edge(positions, faces))


def fan_triangles(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Triangles of USD polygons (fan from each polygon's first corner)."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    if np.all(counts == 3):
        return np.ascontiguousarray(indices.reshape(-1, 3))
    rows = [(indices[s], indices[s + k], indices[s + k + 1])
            for s, c in zip(starts, counts, strict=True) for k in range(1, c - 1)]
    return np.asarray(rows, dtype=np.int32).reshape(-1, 3)


def load_frame(spec: FrameSpec, device: str, cache_dir: Path | None = DEFAULT_CACHE_DIR) -> CorpusFrame:
    """The frame of ``spec``: read from ``cache_dir`` when cached, else produced (and cached).

    Raises:
        ImportError: ``newton`` (or ``pxr``) is missing for a Newton or USD frame.
        RuntimeError: the source cannot give the frame (the message says why).
        ValueError: an unknown ``spec.kind``.
    """
    path = None if cache_dir is None else Path(cache_dir) / spec.cache_name
    if path is not None and path.exists():
        return _with_own_radius(spec, CorpusFrame.load(path))
    if spec.kind == "paper":
        frame = _paper_frame(spec, device)
    elif spec.kind == "newton":
        frame = _newton_frame(spec, device)
    elif spec.kind == "usd":
        frame = _usd_frame(spec)
    else:
        raise ValueError(f"unknown corpus frame kind {spec.kind!r}; use paper, newton or usd")
    if path is not None:
        frame.save(path)
    return _with_own_radius(spec, frame)


NEWTON_CONTACT_MARGINS: dict[str, float] = {"twist": 0.002, "hanging": 0.02, "rollers": 0.3, "poker_cards": 0.001}
"""Each Newton example's own self-contact radius: the ``particle_self_contact_margin`` it gives its VBD
solver (in the example's units; ``cloth_rollers`` works in centimetres)."""


def own_contact_radius(spec: FrameSpec) -> tuple[float | None, str]:
    """The contact radius the frame's own simulator uses, and where it comes from; ``None`` when it has none.

    A paper scene's is its solver thickness (the DCD radius of pscc's own contact springs); a Newton
    example's is its self-contact margin (:data:`NEWTON_CONTACT_MARGINS`); a shipped file has none.
    """
    if spec.kind == "paper":
        from pscc.scenes import paper

        scene = paper.PAPER_SCENES[spec.name](paper.min_scale(spec.name))
        materials = scene.material if isinstance(scene.material, list) else [scene.material]
        return float(max(m.thickness for m in materials)), "the scene's cloth thickness"
    if spec.kind == "newton" and spec.name in NEWTON_CONTACT_MARGINS:
        return NEWTON_CONTACT_MARGINS[spec.name], "the example's particle_self_contact_margin"
    return None, "half its median edge length (it has no contact radius of its own)"


def _with_own_radius(spec: FrameSpec, frame: CorpusFrame) -> CorpusFrame:
    """``frame`` with its own contact radius where its source has one (:func:`own_contact_radius`), marked
    as a check frame when ``spec`` is one."""
    radius, origin = own_contact_radius(spec)
    if radius is None:
        return replace(frame, source=f"{frame.source}; contact radius: {origin}", check=spec.check)
    return replace(frame, radius=radius, source=f"{frame.source}; contact radius: {origin}", check=spec.check)


def load_corpus(specs: tuple[FrameSpec, ...], device: str, cache_dir: Path | None = DEFAULT_CACHE_DIR,
                progress: Callable[[str], None] = lambda _: None) -> tuple[list[CorpusFrame], list[dict[str, Any]]]:
    """Every frame of ``specs`` that its source can give.

    Returns:
        The frames, and one ``{"spec", "reason"}`` entry per frame left out (a missing package or a
        source that failed), plus one per example in :data:`SKIPPED_EXAMPLES`.
    """
    frames, skipped = [], []
    for spec in specs:
        started = time.perf_counter()
        try:
            frames.append(load_frame(spec, device, cache_dir))
        except (ImportError, RuntimeError) as exc:
            skipped.append({"spec": f"{spec.kind} {spec.name}", "reason": f"{type(exc).__name__}: {exc}"})
            continue
        progress(f"{frames[-1].name}: {frames[-1].face_count:,} faces ({time.perf_counter() - started:.1f} s)")
    for name, reason in SKIPPED_EXAMPLES.items():
        skipped.append({"spec": f"newton {name}", "reason": reason})
    return frames, skipped
