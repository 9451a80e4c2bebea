"""Broad phase on the realistic corpus: pscc, spatial hashing, Newton's detector and ipctk's LBVH side by side.

Issue 14: on frames that other systems produced, pscc's culling and speed were weaker than on the
generated sheets of :mod:`pscc.bench.broad_phase`. For every frame of :mod:`pscc.bench.corpus` this
section runs DCD at the frame's contact radius with:

* ``pscc`` with the frame's rest coordinates (where it has them) and ``pscc`` without (its BVH is then
  built over the frame's own shape, embedded by distance along the surface:
  :mod:`pscc.collision.intrinsic`);
* ``spatial-hash``: the same hash with cell-only keys (no normal-cone culling);
* ``newton``: Newton's ``TriMeshCollisionDetector`` (refit + vertex-triangle + edge-edge queries at
  the same radius; :class:`pscc.bench.broad_phase.NewtonDetection`), and ``newton-rebuild``, the same
  with its BVHs rebuilt instead of refit: the detector as issue 14 defines it (a rebuild is a host call
  Warp does not record, so this row has eager calls only);
* ``ipctk-lbvh-1`` and ``ipctk-lbvh-2``: ipctk's ``Candidates.build`` with its ``LBVH`` broad phase on
  one and on two threads (``ipctk.set_num_threads``), boxes inflated by half the radius (two inflated
  boxes overlap when the features may be closer than the radius, like pscc's boxes grown by h/2).

The methods alternate within each repeat (the order rotates by one every repeat) in one process,
so all of them see the same machine load; a time ratio is the median of the per-repeat ratios of
two calls made in the same repeat.

The Warp detectors are timed two ways. *Call*: pscc's host ``detect()`` (upload, broad and narrow
phase, the sorted host rows) and Newton's eager launches. *Graph*: the device-array ``detect()``
recorded once (pscc: :class:`~pscc.collision.recorded.RecordedDetection`, which fits the hash's tables to
the call before recording; Newton: ``wp.ScopedCapture``) and replayed (pscc's replay is followed by
``check_capacity()``, the counter read a caller needs before trusting the result; Newton's by a sync),
which is how pscc's simulator runs detection: device arrays in and out, one recorded graph. pscc's
replay is checked to give the host call's rows. The target ratios compare pscc's replay with the
faster of the other method's call and replay; ipctk's rows are its broad phase only (no distance
tests) in C++, with nothing to replay.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from pscc.bench.broad_phase import NewtonDetection
from pscc.bench.corpus import DEFAULT_CACHE_DIR, CorpusFrame, FrameSpec, load_corpus
from pscc.collision.detector import CollisionDetector
from pscc.collision.recorded import RecordedDetection

__all__ = ["CORPUS_ABOUT", "CORPUS_REPEATS", "CORPUS_TITLE", "GROUND_FRAMES", "QUICK_REPEATS", "TARGETS",
           "USER_FRAMES_ABOUT", "USER_FRAMES_TITLE", "IpctkLbvh", "bench_frame", "plot_corpus", "report", "run",
           "run_frames"]

CORPUS_REPEATS: int = 15
"""Repeats of each method per frame with ``--corpus full`` (after one warm-up call each)."""

QUICK_REPEATS: int = 3
"""Repeats per frame with ``--corpus quick``."""

TARGETS: dict[str, float] = {
    "pairs_rest": 0.4,
    "pairs_no_rest": 0.6,
    "time_vs_newton": 1.0 / 3.0,
    "time_vs_newton_refit": 1.0 / 3.0,
    "time_vs_ipctk_1": 1.0,
    "time_vs_spatial_hash": 1.0,
}
"""Issue 14's targets: pscc triangle pairs over spatial-hash's with and without rest coordinates, and
pscc's DCD time over Newton's detector, ipctk's one-thread LBVH and spatial-hash (at most these)."""

GROUND_FRAMES: tuple[str, ...] = ("twisting f48", "unisex_shirt", "cloth_twist f180")
"""Corpus frames benched again with a ground quad 50 times their extent (:meth:`CorpusFrame.with_ground`):
the check that a few very large faces neither enter the grid nor set its cell size."""


MOVED_FRAMES: tuple[str, ...] = ("twisting f48", "unisex_shirt")
"""Corpus frames benched again moved :data:`MOVED_OFFSET` units along each axis (:meth:`CorpusFrame.moved`):
the check that pscc's culling does not depend on where the frame sits."""

MOVED_OFFSET: float = 1000.0
"""How far the moved frames are moved along each axis (length units)."""


class _PsccRunner:
    """A :class:`CollisionDetector` (``pscc`` or ``spatial-hash``) doing DCD on one frame."""

    def __init__(self, frame: CorpusFrame, method: str, rest: np.ndarray | None, device: str,
                 face_diagonals: bool | None = None) -> None:
        self.frame = frame
        self.detector = CollisionDetector(frame.faces, method=method, rest=rest, object_ids=frame.object_ids,
                                          device=device, face_diagonals=face_diagonals)

    def run(self) -> Any:
        """One ``detect()`` call at the frame's contact radius (host arrays in, sorted host rows out)."""
        return self.detector.detect(self.frame.positions, thickness=self.frame.radius)

    def record(self) -> None:
        """Record the device-array ``detect()`` (broad and narrow phase, results on the device) into a
        graph as a caller does (:class:`~pscc.collision.recorded.RecordedDetection`: an eager call that
        prepares the structures and sizes the buffers, the hash's tables fitted to it)."""
        self.positions = wp.array(self.frame.positions, dtype=wp.vec3, device=self.detector.device)
        recorded = RecordedDetection(self.detector, self.positions, thickness=self.frame.radius)
        self.contacts = recorded.contacts
        self.graph = recorded.graph

    def record_broad(self) -> None:
        """Record the device-array broad phase alone (:meth:`CollisionDetector.broad_phase_device`: BV tests,
        feature pairs and their boxes; the candidate rows stay on the device, no distance test) into a
        second graph: the same product as ipctk's ``Candidates.build``. Call right after :meth:`record`:
        the broad phase runs in the buffers that call sized and fitted, with no eager call that could grow
        one (a growth would leave the full graph writing into released buffers)."""
        detector = self.detector
        with wp.ScopedCapture(device=detector.device) as capture:
            detector.broad_phase_device(self.positions, thickness=self.frame.radius)
        self.broad_graph = capture.graph

    def replay_broad(self) -> None:
        """One replay of the broad-phase graph, then its counter read (as :meth:`replay`)."""
        wp.capture_launch(self.broad_graph)
        if not self.detector.check_capacity():
            raise RuntimeError(f"{self.frame.name}: a buffer overflowed in a broad-phase replay of unchanged "
                               "positions")

    def replay(self) -> None:
        """One replay of the recorded graph, then the counter read a caller needs to trust it
        (:meth:`CollisionDetector.check_capacity`, the device path's one sync point)."""
        wp.capture_launch(self.graph)
        if not self.detector.check_capacity():
            raise RuntimeError(f"{self.frame.name}: a buffer overflowed in a graph replay of unchanged positions")

    def replayed(self) -> Any:
        """The sorted host rows of the last replay (:meth:`CollisionDetector.collect`)."""
        return self.detector.collect(self.contacts)

    def row(self, result: Any) -> dict[str, Any]:
        """Counts and memory of ``result``."""
        stats = result.stats
        return {"bv_tests": stats["bv_tests"], "slab_tests": stats.get("grid", {}).get("slab_tests", 0),
                "triangle_pairs": stats["triangle_pairs"], "kept_triangle_pairs": stats.get("kept_triangle_pairs", 0),
                "candidate_pairs": stats["candidate_pairs"], "vertex_face_pairs": stats["vertex_face_pairs"],
                "edge_edge_pairs": stats["edge_edge_pairs"],
                "bytes_per_triangle": stats["device_bytes"]["total"] / self.frame.face_count,
                "cell_size": stats.get("grid", {}).get("cell_size", 0.0),
                "entries": stats.get("grid", {}).get("entries", 0),
                "wide_faces": stats.get("grid", {}).get("wide_faces", 0)}


class _NewtonRunner:
    """Newton's detector on one frame (a wrapper of :class:`NewtonDetection` with this module's row),
    refitting its BVHs every call (the recorded graph replays that) or rebuilding them."""

    def __init__(self, frame: CorpusFrame, device: str, rebuild: bool = False) -> None:
        self.frame = frame
        self.detection = NewtonDetection(frame.faces, frame.positions, frame.radius, device, rebuild=rebuild)

    def run(self) -> None:
        """One detection (refit or rebuild, both queries, then a sync)."""
        self.detection.run()

    def record(self) -> None:
        """Record refit and both queries into a graph (after the warm-up call)."""
        detector = self.detection.detector
        with wp.ScopedCapture(device=self.detection.device) as capture:
            detector.refit(self.detection.positions)
            detector.vertex_triangle_collision_detection(self.detection.radius)
            detector.edge_edge_collision_detection(self.detection.radius)
        self.graph = capture.graph

    def replay(self) -> None:
        """One replay of the recorded graph, then a sync."""
        wp.capture_launch(self.graph)
        wp.synchronize_device(self.detection.device)

    def row(self, _: Any) -> dict[str, Any]:
        """Pairs found (and whether a buffer overflowed) and the detector's array bytes."""
        row = self.detection.row(0.0)
        return {"vertex_face_pairs": row["vertex_face_pairs"], "edge_edge_pairs": row["edge_edge_pairs"],
                "overflow": row["overflow"],
                "bytes_per_triangle": self.detection.device_bytes() / self.frame.face_count}


class _NewtonRebuildRunner(_NewtonRunner):
    """Newton's detector rebuilding its BVHs every call: eager calls only (``wp.Bvh.rebuild`` on the CPU is
    a host call, which a recorded graph would not repeat)."""

    def __init__(self, frame: CorpusFrame, device: str) -> None:
        super().__init__(frame, device, rebuild=True)

    record = None  # type: ignore[assignment]


class IpctkLbvh:
    """ipctk's DCD candidates with its LBVH broad phase on ``threads`` threads (boxes inflated by
    half the frame's contact radius)."""

    def __init__(self, frame: CorpusFrame, threads: int) -> None:
        import ipctk

        self.ipctk = ipctk
        self.threads = int(threads)
        self.vertices = np.asfortranarray(frame.positions, dtype=np.float64)
        faces = np.asfortranarray(frame.faces, dtype=np.int32)
        self.mesh = ipctk.CollisionMesh(self.vertices, np.asfortranarray(ipctk.edges(faces), dtype=np.int32), faces)
        self.inflation = 0.5 * frame.radius

    def run(self) -> Any:
        """Set the thread count, then build the candidates (the LBVH is built inside)."""
        self.ipctk.set_num_threads(self.threads)
        candidates = self.ipctk.Candidates()
        candidates.build(self.mesh, self.vertices, self.inflation, self.ipctk.LBVH())
        return candidates

    def row(self, candidates: Any) -> dict[str, Any]:
        """Candidate counts (face-vertex and edge-edge; 3-D meshes give no others)."""
        vertex_face = len(candidates.fv_candidates)
        edge_edge = len(candidates.ee_candidates)
        return {"candidate_pairs": vertex_face + edge_edge + len(candidates.ev_candidates)
                + len(candidates.vv_candidates), "vertex_face_candidates": vertex_face,
                "edge_edge_candidates": edge_edge}


def _runners(frame: CorpusFrame, device: str, with_newton: bool, with_ipctk: bool) -> tuple[dict[str, Any], list[str]]:
    """The methods to run on ``frame`` by row key, and why any were left out."""
    runners: dict[str, Any] = {}
    missing = []
    if frame.rest is not None:
        runners["pscc"] = _PsccRunner(frame, "pscc", frame.rest, device)
    runners["pscc-no-rest"] = _PsccRunner(frame, "pscc", None, device)
    runners["spatial-hash"] = _PsccRunner(frame, "spatial-hash", None, device)
    # Plain hashing with pscc's 26-DOP face test: what the diagonal slabs alone cull, without normal cones.
    runners["spatial-hash-dop"] = _PsccRunner(frame, "spatial-hash", None, device, face_diagonals=True)
    if with_newton:
        try:
            runners["newton"] = _NewtonRunner(frame, device)
            runners["newton-rebuild"] = _NewtonRebuildRunner(frame, device)
        except ImportError as exc:
            missing.append(f"newton: {exc}")
    if with_ipctk:
        try:
            runners["ipctk-lbvh-1"] = IpctkLbvh(frame, 1)
            runners["ipctk-lbvh-2"] = IpctkLbvh(frame, 2)
        except ImportError as exc:
            missing.append(f"ipctk: {exc}")
    return runners, missing


def _alternate(runners: dict[str, Any], repeats: int,
               broad: tuple[str, ...] = ()) -> tuple[dict[str, list[float]], dict[str, Any]]:
    """Time every runner once per repeat, rotating the order each repeat (after one warm-up call each).

    A runner with a ``record`` method (the Warp detectors) is recorded into a graph after its warm-up,
    and its replay is timed as one more entry of the rotation, under ``"<name> graph"``; the runners named
    in ``broad`` also record their broad phase alone, timed under ``"<name> broad"``.

    Returns the seconds of each repeat per timed entry, and each runner's last ``run()`` result.
    """
    results = {name: runner.run() for name, runner in runners.items()}
    timed: dict[str, Callable[[], Any]] = {}
    for name, runner in runners.items():
        timed[name] = runner.run
        if getattr(runner, "record", None) is not None:
            runner.record()
            runner.replay()
            timed[f"{name} graph"] = runner.replay
            if name in broad:
                runner.record_broad()
                runner.replay_broad()
                timed[f"{name} broad"] = runner.replay_broad
    names = list(timed)
    seconds: dict[str, list[float]] = {name: [] for name in names}
    for k in range(repeats):
        shift = k % len(names)
        for name in names[shift:] + names[:shift]:
            started = time.perf_counter()
            value = timed[name]()
            seconds[name].append(time.perf_counter() - started)
            if name in runners:
                results[name] = value
    return seconds, results


def _best_seconds(seconds: dict[str, list[float]], name: str) -> list[float]:
    """Per repeat, the faster of ``name``'s call and its graph replay (the call alone without a graph)."""
    if f"{name} graph" not in seconds:
        return seconds[name]
    return [min(a, b) for a, b in zip(seconds[name], seconds[f"{name} graph"], strict=True)]


def _same_rows(a: Any, b: Any) -> bool:
    """Whether results ``a`` and ``b`` hold the same vertex-face and edge-edge rows."""
    return (np.array_equal(a.vertex_face, b.vertex_face) and np.array_equal(a.edge_edge, b.edge_edge))


def _is_subset(a: Any, b: Any) -> bool:
    """Whether every vertex-face and edge-edge pair of result ``a`` is one of result ``b``."""
    def rows(pairs: np.ndarray) -> set[tuple[int, ...]]:
        return {tuple(r) for r in pairs.tolist()}

    return rows(a.vertex_face) <= rows(b.vertex_face) and rows(a.edge_edge) <= rows(b.edge_edge)


def _found(result: Any, base: Any) -> float | None:
    """``result``'s colliding pairs over ``base``'s, or None when ``base`` has none."""
    total = len(base.vertex_face) + len(base.edge_edge)
    return (len(result.vertex_face) + len(result.edge_edge)) / total if total else None


def bench_frame(frame: CorpusFrame, device: str, repeats: int, with_newton: bool = True,
                with_ipctk: bool = True) -> dict[str, Any]:
    """Every method on one frame: a row per method and pscc's per-repeat time ratios.

    Returns:
        ``{"frame", "source", "faces", "radius", "rest", "missing", "rows", "ratios"}``: ``rows`` hold
        ``method``, ``seconds`` (median of the call: pscc's host ``detect()``, Newton's eager launches),
        ``graph_seconds`` (median graph replay, Warp detectors), ``graph_matches`` (pscc: the replay
        gave the host call's rows) and the method's counts; ``ratios`` map each pscc row key (``pscc``,
        ``pscc-no-rest``) to its triangle pairs over spatial-hash's, whether its colliding pairs are a
        subset of spatial-hash's and what fraction of them it finds (in DCD pscc culls pairs inside one
        front node or between two certified neighbouring faces), and, against every other method,
        ``time_vs_<method>`` (pscc's graph replay over the other's faster of call and replay) and
        ``host_vs_<method>`` (pscc's host call over the other's call), each the median of per-repeat
        ratios.
    """
    runners, missing = _runners(frame, device, with_newton, with_ipctk)
    seconds, results = _alternate(runners, repeats, broad=("pscc", "pscc-no-rest"))
    rows = []
    for name, runner in runners.items():
        row = {"method": name, "seconds": statistics.median(seconds[name]), **runner.row(results[name])}
        if f"{name} graph" in seconds:
            row["graph_seconds"] = statistics.median(seconds[f"{name} graph"])
        if f"{name} broad" in seconds:
            row["broad_seconds"] = statistics.median(seconds[f"{name} broad"])
        if isinstance(runner, _PsccRunner):
            runner.replay()  # the last timed call may have been the host call, which shares the buffers
            row["graph_matches"] = _same_rows(runner.replayed(), results[name])
        rows.append(row)
    base = results["spatial-hash"]
    by_method = {r["method"]: r for r in rows}
    ratios = {}
    for name in ("pscc", "pscc-no-rest"):
        if name not in runners:
            continue
        base_pairs = max(1, by_method["spatial-hash"]["triangle_pairs"])
        entry: dict[str, Any] = {
            "pairs_vs_spatial_hash": by_method[name]["triangle_pairs"] / base_pairs,
            "pairs_vs_spatial_hash_dop": by_method[name]["triangle_pairs"]
            / max(1, by_method["spatial-hash-dop"]["triangle_pairs"]),
            "subset_of_spatial_hash": _is_subset(results[name], base),
            "found_vs_spatial_hash": _found(results[name], base),
        }
        for other in runners:
            if other in ("pscc", "pscc-no-rest"):
                continue
            entry[f"time_vs_{other}"] = statistics.median(
                a / b for a, b in zip(seconds[f"{name} graph"], _best_seconds(seconds, other), strict=True))
            entry[f"host_vs_{other}"] = statistics.median(
                a / b for a, b in zip(seconds[name], seconds[other], strict=True))
            if other.startswith("ipctk"):
                entry[f"broad_vs_{other}"] = statistics.median(
                    a / b for a, b in zip(seconds[f"{name} broad"], seconds[other], strict=True))
        ratios[name] = entry
    return {"frame": frame.name, "source": frame.source, "faces": frame.face_count, "radius": frame.radius,
            "rest": frame.rest is not None, "check": frame.check, "missing": missing, "rows": rows, "ratios": ratios}


def run(specs: tuple[FrameSpec, ...], device: str, repeats: int, with_newton: bool = True,
        cache_dir: Path | None = DEFAULT_CACHE_DIR, progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Load (or simulate) the corpus and bench every frame; ``{"frames", "skipped", "repeats", "seconds",
    "corpus_seconds"}``."""
    started = time.perf_counter()
    frames, skipped = load_corpus(specs, device, cache_dir, progress)
    corpus_seconds = time.perf_counter() - started
    out = []
    for frame in frames:
        out.append(bench_frame(frame, device, repeats, with_newton=with_newton))
        progress(f"benched {frame.name}")
    grounded = []
    for frame in frames:
        if frame.name in GROUND_FRAMES:
            grounded.append(bench_frame(frame.with_ground(), device, repeats, with_newton=with_newton))
            progress(f"benched {frame.name} + ground")
    moved = []
    for frame in frames:
        if frame.name in MOVED_FRAMES:
            moved.append(bench_frame(frame.moved(MOVED_OFFSET), device, repeats, with_newton=with_newton))
            progress(f"benched {frame.name} moved")
    return {"frames": out, "grounded": grounded, "moved": moved, "skipped": skipped, "repeats": repeats,
            "corpus_seconds": corpus_seconds, "seconds": time.perf_counter() - started}


def _verdict(value: float, target: float) -> str:
    return f"{value:.2f} ({'met' if value <= target else 'not met'})"


_LABELS = {"pscc": "pscc (rest)", "pscc-no-rest": "pscc (no rest)", "spatial-hash-dop": "spatial-hash (26-DOP)"}


CORPUS_TITLE: str = "Broad phase on a realistic corpus: pscc, spatial hashing, Newton and ipctk"
"""The heading of the corpus section."""

CORPUS_ABOUT: str = (
    "Frames that were not designed for pscc (`pscc/bench/corpus.py`): pscc's paper scenes simulated to "
    "tangled moments (smallest scale), Newton's stock cloth examples run headless to a late frame, and "
    "Newton's shipped `unisex_shirt.usd`; then, added as a check after those had been tuned on, later "
    "moments of the two twisting scenes (denser tangles), Newton's shipped `bunny.usd` and `bear.usd` "
    "(closed surfaces), and its two CAD assemblies `rj45_plug.usd` and `crazyflie.usd` (rigid parts, one object "
    "per mesh; at their radius, walls thinner than it and touching parts make many true contacts), and its "
    "`axis_cube.usda`, a cube of long slivers. DCD at each "
    "frame's own contact radius: a paper scene's cloth thickness, a Newton "
    "example's self-contact margin, half the median edge length for a shipped mesh (no radius of its own). "
    "`python -m pscc.bench --frames FILE ...` benches frames of your own the same way (README).")
"""The paragraph that says which frames the corpus section holds."""

USER_FRAMES_TITLE: str = "Broad phase on your frames: pscc, spatial hashing, Newton and ipctk"
"""The heading of the section that :func:`run_frames` fills (``--frames``)."""

USER_FRAMES_ABOUT: str = (
    "Frames given on the command line (`--frames`, `pscc/bench/user_frames.py`), benched like the corpus "
    "frames of `BENCHMARKS.md`: rest coordinates from the file where it has them (an NPZ's `rest`, else one "
    "texture coordinate per vertex), DCD at the given contact radius (`--frame-radius`) or at half each "
    "frame's median edge length.")
"""The paragraph that says which frames a ``--frames`` report holds."""


def run_frames(frames: list[CorpusFrame], device: str, repeats: int, with_newton: bool = True,
               progress: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Bench the given frames (:func:`pscc.bench.user_frames.load_user_frames`) as :func:`run` benches the
    corpus, without its ground and moved checks; the result carries its own heading for :func:`report`."""
    started = time.perf_counter()
    out = []
    for frame in frames:
        out.append(bench_frame(frame, device, repeats, with_newton=with_newton))
        progress(f"benched {frame.name}")
    return {"frames": out, "grounded": [], "moved": [], "skipped": [], "repeats": repeats, "corpus_seconds": 0.0,
            "seconds": time.perf_counter() - started, "title": USER_FRAMES_TITLE, "about": USER_FRAMES_ABOUT}


_PLOT_PANELS: tuple[tuple[str, str, str], ...] = (
    ("pairs_vs_spatial_hash", "triangle pairs / spatial-hash", "pairs"),
    ("time_vs_newton-rebuild", "time / Newton (rebuild)", "time_vs_newton"),
    ("time_vs_ipctk-lbvh-1", "time / ipctk LBVH, 1 thread", "time_vs_ipctk_1"),
)


def plot_corpus(results: dict[str, Any], path: Path) -> bool:
    """Three panels of horizontal bars, one bar per frame and pscc row (rest / no rest): triangle pairs over
    spatial hashing's, DCD time over Newton's rebuild and over ipctk's one thread, each against its target
    line (green: met, red: not). Check frames are marked ``*``. False without matplotlib or frames."""
    from pscc.bench.simulator import pyplot

    plt = pyplot()
    entries = [(e, name, q) for e in results["frames"] for name, q in e["ratios"].items()]
    if plt is None or not entries:
        return False
    labels = [f"{'* ' if e.get('check') else ''}{e['frame']} ({'rest' if name == 'pscc' else 'no rest'})"
              for e, name, _ in entries]
    y = np.arange(len(entries))[::-1]
    fig, axes = plt.subplots(1, len(_PLOT_PANELS), figsize=(11.0, 1.2 + 0.22 * len(entries)), sharey=True)
    for ax, (key, title, target_key) in zip(axes, _PLOT_PANELS, strict=True):
        values, targets = [], []
        for _, name, q in entries:
            values.append(q.get(key, np.nan))
            targets.append(TARGETS[("pairs_rest" if name == "pscc" else "pairs_no_rest")] if target_key == "pairs"
                           else TARGETS[target_key])
        colours = ["#2e7d32" if v <= t else "#c62828" for v, t in zip(values, targets, strict=True)]
        ax.barh(y, values, color=colours, height=0.7)
        for yy, t in zip(y, targets, strict=True):
            ax.plot([t, t], [yy - 0.45, yy + 0.45], color="black", linewidth=1.0)
        ax.set_title(title, fontsize=9)
        ax.tick_params(axis="x", labelsize=7)
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(y, labels, fontsize=7)
    fig.suptitle("pscc against its targets (black ticks; green met, red not; * check frames)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def report(results: dict[str, Any], plot: str | None = None) -> list[str]:
    """Markdown lines for BENCHMARKS.md (the corpus section, or the ``--frames`` section when ``results``
    carries a ``title`` and an ``about`` paragraph); ``plot``: the path of :func:`plot_corpus`'s picture,
    relative to the report, shown under the ratio table."""
    lines = [
        f"## {results.get('title', CORPUS_TITLE)}",
        "",
        results.get("about", CORPUS_ABOUT),
        "`pscc (rest)` builds its BVH over the frame's rest coordinates, `pscc (no rest)` over the frame's",
        "own shape embedded by distance along the surface (`pscc/collision/intrinsic.py`). `newton`:",
        "`TriMeshCollisionDetector` (refit, vertex-triangle and edge-edge queries), `newton-rebuild` the same",
        "with its BVHs rebuilt every call, as issue 14 defines Newton's detector (eager calls only: the",
        "rebuild is a host call that a recorded graph would not repeat);",
        "`ipctk-lbvh-1`/`-2`: ipctk's `Candidates.build` with its LBVH on one and two threads, broad phase",
        "only (candidates, no distance tests). The methods alternate within each repeat in one process",
        f"({results['repeats']} repeats after a warm-up); ratios are medians of per-repeat ratios. `VF`/`EE`",
        "are colliding pairs after the narrow phase (Newton: its own queries; ipctk: candidates). `overflow`:",
        "an edge met more edges than Newton's default per-edge buffer (32) holds; its count is truncated.",
        "`bytes/tri` is pscc's device memory, Newton's detector arrays (its BVH nodes not counted).",
        "`call s`: pscc's host `detect()` (upload, detection, sorted host rows), Newton's eager launches;",
        "`graph s`: the device-array detection recorded once and replayed, as pscc's simulator runs it (pscc:",
        "`RecordedDetection`, the hash's tables fitted to the call before recording; Newton: `wp.ScopedCapture`),",
        "plus pscc's one counter read (`check_capacity`) or Newton's sync. Every pscc",
        "replay gave the host call's rows (checked on every frame). `broad s`: pscc's broad phase alone",
        "(`broad_phase_device`: BV tests, then feature pairs whose boxes overlap; candidate rows, no distance",
        "test), recorded and replayed on its own with its counter read: the product ipctk's row times.",
        "pscc tests face pairs with 26-DOPs (the box and ten diagonal slabs, `pscc/geometry/dop.py`);",
        "`spatial-hash` is the paper's plain hashing (boxes only), and `spatial-hash (26-DOP)` the same hash",
        "with pscc's face test, to show which part of pscc's culling the normal cones do.",
        "",
        "| frame | faces | method | BV tests | triangle pairs | candidates | VF | EE | call s | graph s "
        "| broad s | bytes/tri |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for entry in results["frames"]:
        for r in entry["rows"]:
            label = _LABELS.get(r["method"], r["method"])
            vf = r.get("vertex_face_pairs", r.get("vertex_face_candidates", ""))
            ee = r.get("edge_edge_pairs", r.get("edge_edge_candidates", ""))
            if r.get("overflow"):
                ee = f"{ee} (overflow)"
            graph = f"{r['graph_seconds']:.4f}" if "graph_seconds" in r else ""
            if r.get("graph_matches") is False:
                graph += " (**rows differ**)"
            cells = [entry["frame"], f"{entry['faces']:,}", label, _count(r.get("bv_tests")),
                     _count(r.get("triangle_pairs")), _count(r.get("candidate_pairs")), _count(vf), _count(ee),
                     f"{r['seconds']:.4f}", graph, f"{r['broad_seconds']:.4f}" if "broad_seconds" in r else "",
                     f"{r['bytes_per_triangle']:.0f}" if "bytes_per_triangle" in r else ""]
            lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        f"Targets (issue 14): triangle pairs at most {TARGETS['pairs_rest']} of spatial-hash's with rest",
        f"coordinates and {TARGETS['pairs_no_rest']} without; DCD time at most 1/3 of Newton's (the issue's",
        "detector: rebuild and both queries; also shown against the faster refit), at most ipctk's",
        "LBVH on one thread, at most spatial-hash's. `time` ratios: pscc's graph replay over the other",
        "method's faster of call and replay (ipctk: its call); `host` ratios: pscc's host call over the other's",
        "call; `broad` the same for pscc's broad phase alone (not a target: ipctk's row has no distance",
        "tests, pscc's DCD time does). `found`: pscc's colliding pairs (VF + EE) over spatial-hash's, which",
        "are brute force's. In DCD",
        "pscc returns a subset (checked): features of one front node, or of two neighbouring faces certified",
        "to meet only in what they share, closer than the radius are culled, because the certificates are",
        "about intersection, not distance (`docs/pscc.md`; on the shirt, whose radius is half its median",
        "edge, most rows join neighbouring faces).",
        "",
        "| frame | pscc | pairs / spatial-hash | pairs / spatial-hash (26-DOP) | found | time / spatial-hash "
        "| time / newton rebuild | time / newton refit | host / newton refit | time / ipctk 1 thread "
        "| host / ipctk 1 thread | broad / ipctk 1 thread | time / ipctk 2 threads |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    tallies = {False: {key: [0, 0] for key in TARGETS}, True: {key: [0, 0] for key in TARGETS}}
    for entry in results["frames"]:
        met = tallies[bool(entry.get("check", False))]
        for name, q in entry["ratios"].items():
            pair_target = "pairs_rest" if name == "pscc" else "pairs_no_rest"
            found = "none to find" if q["found_vs_spatial_hash"] is None else f"{q['found_vs_spatial_hash']:.2f}"
            found += "" if q["subset_of_spatial_hash"] else " (**not a subset**)"
            cells = [entry["frame"], _LABELS[name], _verdict(q["pairs_vs_spatial_hash"], TARGETS[pair_target]),
                     f"{q['pairs_vs_spatial_hash_dop']:.2f}", found,
                     _verdict(q["time_vs_spatial-hash"], TARGETS["time_vs_spatial_hash"])]
            _tally(met, pair_target, q["pairs_vs_spatial_hash"])
            _tally(met, "time_vs_spatial_hash", q["time_vs_spatial-hash"])
            if "time_vs_newton-rebuild" in q:
                cells.append(_verdict(q["time_vs_newton-rebuild"], TARGETS["time_vs_newton"]))
                _tally(met, "time_vs_newton", q["time_vs_newton-rebuild"])
            else:
                cells.append("")
            for key, target in (("newton", "time_vs_newton_refit"), ("ipctk-lbvh-1", "time_vs_ipctk_1")):
                if f"time_vs_{key}" in q:
                    cells += [_verdict(q[f"time_vs_{key}"], TARGETS[target]), f"{q[f'host_vs_{key}']:.2f}"]
                    _tally(met, target, q[f"time_vs_{key}"])
                else:
                    cells += ["", ""]
            cells.append(f"{q['broad_vs_ipctk-lbvh-1']:.2f}" if "broad_vs_ipctk-lbvh-1" in q else "")
            cells.append(f"{q['time_vs_ipctk-lbvh-2']:.2f}" if "time_vs_ipctk-lbvh-2" in q else "")
            lines.append("| " + " | ".join(cells) + " |")
    if plot is not None:
        lines += ["", f"![pscc against issue 14's targets, frame by frame]({plot})"]
    names = {"pairs_rest": "pairs with rest <= 0.4", "pairs_no_rest": "pairs without rest <= 0.6",
             "time_vs_newton": "time <= 1/3 of Newton (rebuild, the issue's detector)",
             "time_vs_newton_refit": "time <= 1/3 of Newton refit (not the issue's target; stricter)",
             "time_vs_ipctk_1": "time <= ipctk LBVH 1 thread",
             "time_vs_spatial_hash": "time <= spatial-hash"}
    def tally(met: dict[str, list[int]]) -> str:
        return "; ".join(f"{names[k]}: {m} of {n}" for k, (m, n) in met.items() if n) + "."

    lines += ["", "Targets met: " + tally(tallies[False])]
    if any(n for _, n in tallies[True].values()):
        lines += ["", "On the frames added as a check after the others had been tuned on (marked *check* below): "
                  + tally(tallies[True])]
    lines += ["", "Frames:", ""]
    for entry in results["frames"]:
        rest = "with rest coordinates" if entry["rest"] else "no rest coordinates"
        mark = " *check*:" if entry.get("check") else ":"
        lines.append(f"- `{entry['frame']}`{mark} {entry['source']}; {entry['faces']:,} faces, {rest}, "
                     f"contact radius {entry['radius']:.4g}.")
    for skip in results["skipped"]:
        lines.append(f"- left out: {skip['spec']}: {skip['reason']}.")
    lines += _ground_report(results)
    lines += _moved_report(results)
    if "title" in results:
        lines += ["", f"Section time: {results['seconds']:.0f} s.", ""]
    else:
        lines += ["", f"Section time: {results['seconds']:.0f} s, of which {results['corpus_seconds']:.0f} s loading "
                  "or simulating the corpus (cached frames load in well under a second).", ""]
    return lines


def _ground_report(results: dict[str, Any]) -> list[str]:
    """Lines of the ground-quad check: the same frames with two very large faces added."""
    grounded = results.get("grounded", [])
    if not grounded:
        return []
    plain = {entry["frame"]: entry for entry in results["frames"]}
    lines = ["", "**A ground quad added.** The frames above, without rest coordinates, plus two ground triangles 50 "
             "times the frame's extent just below it (`CorpusFrame.with_ground`; our check, not an exported frame: "
             "exported scenes often carry such a ground or a collider's large triangles). The ground's faces are "
             "*wide* (`docs/spatial-hash.md` section 6a): out of the grid and out of its cell size. Cell and entries "
             "are pscc's, without and with the ground.", "",
             "| frame | wide faces | cell | entries | time / spatial-hash | time / newton rebuild "
             "| time / newton refit | time / ipctk 1 thread |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for entry in grounded:
        base = plain.get(entry["frame"].removesuffix(" + ground"))
        row = next(r for r in entry["rows"] if r["method"] == "pscc-no-rest")
        before = next((r for r in base["rows"] if r["method"] == "pscc-no-rest"), None) if base else None
        q = entry["ratios"]["pscc-no-rest"]
        cell = f"{row['cell_size']:.4g}" if before is None else f"{before['cell_size']:.4g} / {row['cell_size']:.4g}"
        entries = f"{row['entries']:,}" if before is None else f"{before['entries']:,} / {row['entries']:,}"
        cells = [entry["frame"], str(row["wide_faces"]), cell, entries,
                 _verdict(q["time_vs_spatial-hash"], TARGETS["time_vs_spatial_hash"])]
        for key, target in (("newton-rebuild", "time_vs_newton"), ("newton", "time_vs_newton_refit"),
                            ("ipctk-lbvh-1", "time_vs_ipctk_1")):
            cells.append(_verdict(q[f"time_vs_{key}"], TARGETS[target]) if f"time_vs_{key}" in q else "")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _moved_report(results: dict[str, Any]) -> list[str]:
    """Lines of the moved-frame check: the same frames far from the origin."""
    moved = results.get("moved", [])
    if not moved:
        return []
    plain = {entry["frame"]: entry for entry in results["frames"]}
    lines = ["", f"**Far from the origin.** The frames above moved {MOVED_OFFSET:g} units along each axis "
             "(`CorpusFrame.moved`; our check: exported scenes need not put the cloth at the origin). The float32 "
             "rounding pads of the boxes grow with the coordinates; those of pscc's diagonal slabs are taken in a "
             "local frame (`pscc/geometry/dop.py`). Pairs: pscc's triangle pairs at the origin / moved, and moved "
             "over spatial-hash's moved.", "",
             "| frame | pscc | pairs | pairs / spatial-hash | time / spatial-hash | time / newton rebuild "
             "| time / ipctk 1 thread |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for entry in moved:
        base = plain.get(entry["frame"].removesuffix(f" moved {MOVED_OFFSET:g}"))
        for name, q in entry["ratios"].items():
            row = next(r for r in entry["rows"] if r["method"] == name)
            before = next((r for r in base["rows"] if r["method"] == name), None) if base else None
            pairs = f"{row['triangle_pairs']:,}" if before is None else \
                f"{before['triangle_pairs']:,} / {row['triangle_pairs']:,}"
            target = "pairs_rest" if name == "pscc" else "pairs_no_rest"
            cells = [entry["frame"], _LABELS[name], pairs, _verdict(q["pairs_vs_spatial_hash"], TARGETS[target]),
                     _verdict(q["time_vs_spatial-hash"], TARGETS["time_vs_spatial_hash"])]
            for key, target in (("newton-rebuild", "time_vs_newton"), ("ipctk-lbvh-1", "time_vs_ipctk_1")):
                cells.append(_verdict(q[f"time_vs_{key}"], TARGETS[target]) if f"time_vs_{key}" in q else "")
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def _count(value: Any) -> str:
    return f"{value:,}" if isinstance(value, int) else ("" if value is None else str(value))


def _tally(met: dict[str, list[int]], key: str, value: float) -> None:
    met[key][1] += 1
    met[key][0] += int(value <= TARGETS[key])
