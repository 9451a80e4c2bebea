"""Broad-phase benchmark: PSCC against plain spatial hashing and against Newton's detector.

Scenes are generated three-layer folded and twisted cloth (``pscc.mesh.generate``) at the
requested triangle counts. For each scene and method the benchmark records, for CCD over one step
and DCD at the step's end (contact radius = half the mean edge length):

- bounding-volume tests, triangle pairs (self / inter), front size, feature candidates;
- colliding pairs (identical across methods for CCD; checked here);
- median seconds per ``detect()`` call and per stage; device bytes per triangle.

Newton's ``TriMeshCollisionDetector`` (the ``newton`` package, a benchmark-only extra) runs the
same DCD frames at the same radius: refit plus vertex-triangle and edge-edge queries. Its calls
alternate with pscc's DCD calls (one of each per repeat), so both medians see the same machine load.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np
import warp as wp

from pscc.bench.corpus import half_mean_edge
from pscc.collision.detector import CollisionDetector
from pscc.mesh.generate import folded_sheet
from pscc.mesh.mesh_data import MeshData


def _twist(points: np.ndarray, turns: float) -> np.ndarray:
    """Rotate every x-slice of ``points`` about the x axis by ``turns`` full turns per unit of x."""
    x = points.astype(np.float64)
    center = x.mean(axis=0)
    angle = 2.0 * np.pi * turns * (x[:, 0] - x[:, 0].min())
    y = x[:, 1] - center[1]
    z = x[:, 2] - center[2]
    out = x.copy()
    out[:, 1] = center[1] + np.cos(angle) * y - np.sin(angle) * z
    out[:, 2] = center[2] + np.sin(angle) * y + np.cos(angle) * z
    return out.astype(np.float32)


def twisted_layers(triangles: int) -> MeshData:
    """The three-layer folded cloth twisted about its long axis by half a turn, twisting a little
    further (0.5 % of a turn, about one step of a twisting animation) while its layers are pressed
    together over the step."""
    mesh = folded_sheet(triangles, layers=3, seed=0)
    return MeshData(vertices=_twist(mesh.vertices, 0.5), faces=mesh.faces,
                    vertices_end=_twist(mesh.vertices_end, 0.505), rest=mesh.rest, object_ids=mesh.object_ids,
                    source=f"twisted_layers({triangles})")


SCENES = {
    "folded": lambda triangles: folded_sheet(triangles, layers=3, seed=0),
    "twisted": twisted_layers,
}


def contact_radius(mesh: MeshData) -> float:
    """Half the mean edge length of the mesh's start positions."""
    return half_mean_edge(mesh.vertices, mesh.faces)


PAIRED_REPEATS: int = 15
"""Least number of alternating pscc / Newton pairs behind a ratio (more than ``repeats``: the ratio
is the target, and this machine's speed shifts between calls)."""


def _median(run: Any, repeats: int) -> tuple[float, Any]:
    result = run()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - started)
    return statistics.median(times), result


def device_seconds(result: Any) -> float:
    """Seconds of a detect() call up to the narrow phase (every stage but ``output``)."""
    return sum(v for k, v in result.stats["seconds"].items() if k not in ("total", "setup", "output"))


def _paired_medians(run: Any, other: Any, repeats: int) -> tuple[float, Any, float, float, float]:
    """``run`` and ``other`` timed alternately (after one warm-up call of each).

    Returns the median seconds of ``run``, its last result, the median seconds of ``other``, and the
    medians of the per-repeat ratios run / other and device seconds of run / other: each ratio
    compares two calls made back to back, so slow and fast phases of a shared machine cancel.
    """
    result = run()
    other()
    times, other_times, ratios, device_ratios = [], [], [], []
    for _ in range(repeats):
        started = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - started)
        started = time.perf_counter()
        other()
        other_times.append(time.perf_counter() - started)
        ratios.append(times[-1] / other_times[-1])
        device_ratios.append(device_seconds(result) / other_times[-1])
    return (statistics.median(times), result, statistics.median(other_times), statistics.median(ratios),
            statistics.median(device_ratios))


def bench_methods(mesh: MeshData, device: str, repeats: int, newton: Any = None) -> list[dict[str, Any]]:
    """Every pscc method on one scene, CCD and DCD. With ``newton`` (a :class:`NewtonDetection`),
    its DCD calls alternate with pscc's and its row is appended."""
    radius = contact_radius(mesh)
    rows = []
    pairs_by_mode: dict[str, tuple[int, int]] = {}
    for method in ("spatial-hash", "pscc"):
        for mode in ("ccd", "dcd"):
            # One detector per stream of calls: the pscc front follows the frames it is given.
            detector = CollisionDetector(mesh.faces, method=method, rest=mesh.rest, device=device)
            if mode == "ccd":
                def run(detector=detector):
                    return detector.detect(mesh.vertices, mesh.vertices_end)
            else:
                def run(detector=detector):
                    return detector.detect(mesh.vertices_end, thickness=radius)
            paired: dict[str, float] = {}
            if method == "pscc" and mode == "dcd" and newton is not None:
                seconds, result, newton_seconds, ratio, device_ratio = _paired_medians(
                    run, newton.run, max(repeats, PAIRED_REPEATS))
                paired = {"newton_ratio": ratio, "newton_device_ratio": device_ratio}
            else:
                seconds, result = _median(run, repeats)
            stats = result.stats
            pairs = (stats["vertex_face_pairs"], stats["edge_edge_pairs"])
            if mode == "ccd" and pairs_by_mode.setdefault(mode, pairs) != pairs:
                raise RuntimeError(f"{method} CCD pairs {pairs} differ from {pairs_by_mode[mode]}")
            rows.append({
                "method": method, "mode": mode, "seconds": seconds, "radius": radius if mode == "dcd" else 0.0,
                "bv_tests": stats["bv_tests"], "kept_triangle_pairs": stats.get("kept_triangle_pairs", 0),
                "slab_tests": stats.get("grid", {}).get("slab_tests", 0),
                "triangle_pairs": stats["triangle_pairs"],
                "self_triangle_pairs": stats["self_triangle_pairs"], "front_size": stats["front_size"],
                "candidate_pairs": stats["candidate_pairs"], "vertex_face_pairs": pairs[0],
                "edge_edge_pairs": pairs[1], "bytes_per_triangle": stats["device_bytes"]["total"] / mesh.face_count,
                "stage_seconds": {k: v for k, v in stats["seconds"].items() if k not in ("total", "setup")},
            })
            rows[-1]["device_seconds"] = device_seconds(result)
            rows[-1].update(paired)
    if newton is not None:
        rows.append(newton.row(newton_seconds))
    return rows


class NewtonDetection:
    """Newton's TriMeshCollisionDetector on the DCD frame of a scene (refit + vertex-triangle +
    edge-edge queries at pscc's contact radius); :meth:`create` gives None when newton is missing."""

    def __init__(self, faces: np.ndarray, positions: np.ndarray, radius: float, device: str,
                 vertices: np.ndarray | None = None, rebuild: bool = False) -> None:
        """Build the detector over ``faces`` (a Newton cloth mesh at ``vertices``, default ``positions``)
        to query ``positions`` at ``radius``; with ``rebuild``, every detection rebuilds Newton's BVHs
        instead of refitting them."""
        import newton
        from newton._src.geometry.tri_mesh_collision import TriMeshCollisionDetector

        self.radius = float(radius)
        self.device = device
        self.rebuild = bool(rebuild)
        builder = newton.ModelBuilder()
        builder.add_cloth_mesh(
            pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0, 0.0, 0.0),
            vertices=[wp.vec3(*v) for v in (positions if vertices is None else vertices).tolist()],
            indices=np.asarray(faces).reshape(-1).tolist(), density=0.02, tri_ke=0.0, tri_ka=0.0, tri_kd=0.0,
        )
        self.model = builder.finalize(device=device)
        self.detector = TriMeshCollisionDetector(model=self.model, init_collision_info=True)
        self.positions = wp.array(positions, dtype=wp.vec3, device=device)

    @classmethod
    def create(cls, mesh: MeshData, device: str) -> NewtonDetection | None:
        """The runner on the end positions of ``mesh``, or None when the ``newton`` package is not installed."""
        try:
            return cls(mesh.faces, mesh.vertices_end, contact_radius(mesh), device, vertices=mesh.vertices)
        except ImportError:
            return None

    def device_bytes(self) -> int:
        """Bytes of the detector's own Warp arrays (its ``wp.Bvh`` nodes are not counted: a lower bound)."""
        arrays = [v for v in vars(self.detector).values() if isinstance(v, wp.array)]
        return int(sum(a.capacity for a in arrays))

    def run(self) -> None:
        """One detection: refit (or rebuild), vertex-triangle and edge-edge queries, then a device sync."""
        if self.rebuild:
            self.detector.rebuild(self.positions)
        else:
            self.detector.refit(self.positions)
        self.detector.vertex_triangle_collision_detection(self.radius)
        self.detector.edge_edge_collision_detection(self.radius)
        wp.synchronize_device(self.device)

    def row(self, seconds: float) -> dict[str, Any]:
        """The benchmark row of the last detection, timed at ``seconds``."""
        detector = self.detector
        vertex_face = int(detector.vertex_colliding_triangles_count.numpy().sum())
        edge_edge = int(detector.edge_colliding_edges_count.numpy().sum()) // 2  # each pair is listed per edge
        return {"method": "newton", "mode": "dcd", "seconds": seconds, "radius": self.radius,
                "vertex_face_pairs": vertex_face, "edge_edge_pairs": edge_edge,
                "overflow": bool(detector.resize_flags.numpy().any())}


def run(sizes: list[int], device: str, repeats: int, with_newton: bool = True) -> list[dict[str, Any]]:
    """All scenes at all sizes; one row per (scene, size, method, mode)."""
    rows = []
    for scene, make in SCENES.items():
        for triangles in sizes:
            mesh = make(triangles)
            newton = NewtonDetection.create(mesh, device) if with_newton else None
            for row in bench_methods(mesh, device, repeats, newton):
                rows.append({"scene": scene, "triangles": mesh.face_count, **row})
    return rows


def report(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown lines for BENCHMARKS.md."""
    lines = [
        "## Broad phase: PSCC against spatial hashing and Newton",
        "",
        "Generated three-layer folded and twisted cloth. CCD: one step from the start to the end",
        "positions (thickness 0). DCD: the end positions with a contact radius of half the mean edge",
        "length. `spatial-hash` is the same hash with cell-only keys (no normal-cone culling). Newton:",
        "`TriMeshCollisionDetector` (refit + vertex-triangle + edge-edge queries) on the same DCD frame",
        "and radius. Colliding pairs are identical for every method in CCD (checked by the run).",
        "",
        "`BV tests` counts every bounding-volume test: face box tests, plus for pscc the group slab tests",
        "(`slab tests`: two {cell, node} groups of a cell tested as wholes along a group normal before",
        "their face pairs; `docs/spatial-hash.md`). `triangle pairs` are the hash's output, the triangle",
        "pairs of the paper's Fig. 15; `kept pairs` are those that give at least one candidate feature",
        "pair (a vertex-face or edge-edge pair whose boxes overlap) and that no supporting plane separates",
        "(`pscc/collision/pair_filter.py`), which both methods run; `candidates` are the feature pairs",
        "given to the narrow phase.",
        "",
        "`seconds` is a whole `detect()` call, which ends by copying the pairs to the host and sorting",
        "them into canonical rows (the `output` stage). Newton's detector leaves its results on the",
        "device, so the last ratio column compares it with pscc's stages up to the narrow phase",
        "(`device seconds`: everything but `output`). pscc's DCD calls and Newton's alternate, one of",
        f"each per repeat, over at least {PAIRED_REPEATS} repeats; the ratio columns are medians of the",
        "per-repeat ratios (two calls made back to back), because this shared machine runs in slow and",
        "fast phases that shift whole medians.",
        "",
        "| scene | triangles | mode | method | BV tests | slab tests | triangle pairs | kept pairs | front "
        "| candidates | VF | EE | seconds | bytes/triangle |",
        "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r["method"] == "newton":
            lines.append(f"| {r['scene']} | {r['triangles']:,} | DCD | newton | | | | | | | "
                         f"{r['vertex_face_pairs']:,} | "
                         f"{r['edge_edge_pairs']:,} | {r['seconds']:.3f} | |")
            continue
        lines.append(
            f"| {r['scene']} | {r['triangles']:,} | {r['mode'].upper()} | {r['method']} | {r['bv_tests']:,} | "
            f"{r.get('slab_tests', 0):,} | {r['triangle_pairs']:,} | {r.get('kept_triangle_pairs', 0):,} | "
            f"{r['front_size']:,} | "
            f"{r['candidate_pairs']:,} | {r['vertex_face_pairs']:,} | "
            f"{r['edge_edge_pairs']:,} | {r['seconds']:.3f} | {r['bytes_per_triangle']:.0f} |")
    lines += ["", "Ratios (pscc / spatial-hash; pscc / newton for DCD time):", "",
              "| scene | triangles | mode | triangle pairs | kept pairs | BV tests | time | time vs newton "
              "| device vs newton |",
              "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    index = {(r["scene"], r["triangles"], r["mode"], r["method"]): r for r in rows}
    for (scene, triangles, mode, method), r in index.items():
        if method != "pscc":
            continue
        base = index[(scene, triangles, mode, "spatial-hash")]
        newton_row = index.get((scene, triangles, mode, "newton"))
        vs_newton = device_vs_newton = ""
        if newton_row:
            vs_newton = f"{r.get('newton_ratio', r['seconds'] / newton_row['seconds']):.2f}"
            device_vs_newton = f"{r.get('newton_device_ratio', r['device_seconds'] / newton_row['seconds']):.2f}"
        lines.append(f"| {scene} | {triangles:,} | {mode.upper()} | "
                     f"{r['triangle_pairs'] / max(1, base['triangle_pairs']):.3f} | "
                     f"{r.get('kept_triangle_pairs', 0) / max(1, base.get('kept_triangle_pairs', 0)):.3f} | "
                     f"{r['bv_tests'] / max(1, base['bv_tests']):.3f} | {r['seconds'] / base['seconds']:.2f} | "
                     f"{vs_newton} | {device_vs_newton} |")
    lines += ["", "Seconds per stage (pscc):", "", "| scene | triangles | mode | stages |", "|---|---:|---|---|"]
    for r in rows:
        if r["method"] == "pscc":
            stages = ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in r["stage_seconds"].items())
            lines.append(f"| {r['scene']} | {r['triangles']:,} | {r['mode'].upper()} | {stages} |")
    lines.append("")
    return lines
