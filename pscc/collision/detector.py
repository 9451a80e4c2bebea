"""``CollisionDetector``: the one interface every detection method of pscc shares.

A detector is built once per mesh topology and called once per step::

    det = pscc.CollisionDetector(faces, method="brute-force", object_ids=None, device=None)
    res = det.detect(positions, positions_end=None, thickness=0.0)

Discrete detection (DCD, ``positions_end=None``) reports the pairs closer than ``thickness``.
Continuous detection (CCD) reports the pairs that come within ``thickness`` (0 = touching) at some
time of the step, with a time of impact that is never later than the true one. Pairs that share a
vertex are never reported. Both are conservative: a true pair is never missed; a reported pair may
be a near miss within the tolerance band documented in :mod:`pscc.tolerances` (``docs/ccd.md``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp

from pscc._checks import as_numpy, check_nonnegative, check_points
from pscc.collision.boxes import PrimitiveBoxes
from pscc.collision.brute_force import BroadPhaseBruteForce
from pscc.collision.candidates import CandidatePairs
from pscc.collision.narrow_phase import NarrowPhase
from pscc.errors import InputError
from pscc.mesh.mesh_data import validate_mesh
from pscc.mesh.topology import MeshTopology

METHODS: tuple[str, ...] = ("brute-force",)
"""Detection methods available through :class:`CollisionDetector`."""


def resolve_device(device: str | None) -> wp.Device:
    """Return the Warp device for a name, or raise :class:`InputError` listing the devices."""
    try:
        return wp.get_device(device)
    except (RuntimeError, ValueError) as exc:
        names = ", ".join(d.alias for d in wp.get_devices())
        raise InputError("argument", "device", f"{device!r} is not available ({exc})",
                         f"use one of: {names}") from exc


@dataclass
class CollisionResult:
    """Pairs found by one :meth:`CollisionDetector.detect` call; rows sorted lexicographically.

    Attributes:
        vertex_face: (K, 2) int32 rows (vertex, face).
        edge_edge: (L, 4) int32 rows (a0, a1, b0, b1) with a0 < a1, b0 < b1, (a0, a1) < (b0, b1).
        vertex_face_toi: (K,) float32 time of impact in [0, 1] (CCD only, else None).
        edge_edge_toi: (L,) float32 time of impact (CCD only, else None).
        stats: counts, per-stage seconds and device bytes (see :meth:`CollisionDetector.detect`).
    """

    vertex_face: np.ndarray
    edge_edge: np.ndarray
    vertex_face_toi: np.ndarray | None = None
    edge_edge_toi: np.ndarray | None = None
    stats: dict[str, Any] = field(default_factory=dict)


class CollisionDetector:
    """Collision detection for a triangle mesh with fixed topology (one or several objects).

    Args:
        faces: (face_count, 3) integer vertex ids.
        method: one of :data:`METHODS`.
        object_ids: optional (face_count,) object id per face (default: one object).
        device: Warp device name (default: Warp's default device).

    Raises:
        InputError: bad faces, object ids or method.
    """

    def __init__(
        self,
        faces: Any,
        *,
        method: str = "brute-force",
        object_ids: Any = None,
        device: str | None = None,
    ) -> None:
        if method not in METHODS:
            raise InputError("argument", "method", f"unknown method {method!r}",
                             f"use one of {', '.join(METHODS)}")
        faces_np = as_numpy(faces)
        if faces_np.ndim != 2 or faces_np.shape[-1] != 3:
            raise InputError("argument", "faces", f"shape {faces_np.shape} is not (m, 3)",
                             "pass triangle faces as an (m, 3) integer array")
        if faces_np.size and faces_np.dtype.kind not in "iu":
            raise InputError("argument", "faces", f"dtype {faces_np.dtype} is not an integer type",
                             "pass vertex ids as integers")
        self.method = method
        self.device = resolve_device(device)
        self._faces_np = np.ascontiguousarray(faces_np, dtype=np.int32)
        self._object_ids_np = None if object_ids is None else as_numpy(object_ids)
        self._vertex_count: int | None = None
        self.topology: MeshTopology | None = None

    def _setup(self, vertex_count: int, positions: np.ndarray) -> None:
        """Validate the topology against the first positions and allocate device buffers."""
        mesh = validate_mesh(positions, self._faces_np, object_ids=self._object_ids_np)
        self._vertex_count = vertex_count
        self.object_ids = mesh.object_ids
        self.topology = MeshTopology.from_faces(mesh.faces, vertex_count)
        device = self.device
        self._faces = wp.array(mesh.faces, dtype=wp.vec3i, device=device)
        self._edges = wp.array(self.topology.edges, dtype=wp.vec2i, device=device)
        self._positions_t0 = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        self._positions_t1 = wp.empty(vertex_count, dtype=wp.vec3, device=device)
        self.boxes = PrimitiveBoxes(self._faces, self._edges, vertex_count, device)
        self.candidates = CandidatePairs(4 * mesh.face_count, 4 * self.topology.edge_count, device)
        self.broad_phase = BroadPhaseBruteForce(self.boxes, device)
        self.narrow_phase = NarrowPhase(self._faces, self._edges, device)

    def _positions(self, value: Any, name: str) -> np.ndarray:
        points = check_points(value, name, shape_tail=(3,))
        if self._vertex_count is not None and points.shape[0] != self._vertex_count:
            raise InputError("argument", name,
                             f"{points.shape[0]} vertices, but this detector was set up for "
                             f"{self._vertex_count}", "pass positions of the same mesh every call")
        return points

    def detect(self, positions: Any, positions_end: Any = None, thickness: float = 0.0) -> CollisionResult:
        """Find the colliding vertex-face and edge-edge pairs of one step.

        Args:
            positions: (vertex_count, 3) positions at the start of the step.
            positions_end: optional (vertex_count, 3) positions at the end of the step (CCD).
            thickness: proximity distance (>= 0), in the units of the positions.

        Returns:
            A :class:`CollisionResult`. ``stats`` holds ``vertex_face_pairs``, ``edge_edge_pairs``,
            ``bv_tests``, ``candidate_pairs``, ``seconds`` (per stage: ``setup``, ``boxes``,
            ``broad_phase``, ``narrow_phase``, ``output``, ``total``) and ``device_bytes`` (per
            structure and ``total``).

        Raises:
            InputError: bad positions or thickness.
        """
        started = time.perf_counter()
        seconds: dict[str, float] = {}
        x0 = self._positions(positions, "positions")
        x1 = None if positions_end is None else self._positions(positions_end, "positions_end")
        if x1 is not None and x1.shape != x0.shape:
            raise InputError("argument", "positions_end", f"shape {x1.shape} differs from positions {x0.shape}",
                             "pass end positions of the same vertices")
        h = check_nonnegative(thickness, "thickness")
        if self.topology is None:
            self._setup(x0.shape[0], x0)
        seconds["setup"] = time.perf_counter() - started

        mark = time.perf_counter()
        self._positions_t0.assign(x0)
        positions_t1 = self._positions_t0
        if x1 is not None:
            self._positions_t1.assign(x1)
            positions_t1 = self._positions_t1
        self.boxes.compute(self._positions_t0, positions_t1, h)
        wp.synchronize_device(self.device)
        seconds["boxes"] = time.perf_counter() - mark

        mark = time.perf_counter()
        while True:
            self.candidates.reset()
            self.broad_phase.find_pairs(self.candidates)
            if self.candidates.fits():
                break
        seconds["broad_phase"] = time.perf_counter() - mark

        mark = time.perf_counter()
        self.narrow_phase.run(self.candidates, self._positions_t0, positions_t1, h)
        wp.synchronize_device(self.device)
        seconds["narrow_phase"] = time.perf_counter() - mark

        mark = time.perf_counter()
        result = self._collect(ccd=x1 is not None)
        seconds["output"] = time.perf_counter() - mark
        seconds["total"] = time.perf_counter() - started
        topology = self.topology
        result.stats = {
            "method": self.method,
            "mode": "ccd" if x1 is not None else "dcd",
            "thickness": h,
            "vertex_count": int(x0.shape[0]),
            "face_count": int(self._faces_np.shape[0]),
            "edge_count": topology.edge_count,
            "bv_tests": self.broad_phase.bounding_volume_tests(
                x0.shape[0], self._faces_np.shape[0], topology.edge_count),
            "candidate_pairs": self.candidates.vertex_face_count + self.candidates.edge_edge_count,
            "vertex_face_pairs": int(result.vertex_face.shape[0]),
            "edge_edge_pairs": int(result.edge_edge.shape[0]),
            "seconds": seconds,
            "device_bytes": self.device_bytes(),
        }
        return result

    def device_bytes(self) -> dict[str, int]:
        """Device memory per structure, in bytes, and their ``total``."""
        sizes = {
            "mesh": self._faces.capacity + self._edges.capacity
            + self._positions_t0.capacity + self._positions_t1.capacity,
            "boxes": self.boxes.device_bytes,
            "candidates": self.candidates.device_bytes,
            "narrow_phase": self.narrow_phase.device_bytes,
        }
        sizes["total"] = sum(sizes.values())
        return sizes

    def _collect(self, *, ccd: bool) -> CollisionResult:
        """Copy the reported pairs to the host as sorted rows (a sync point)."""
        vf_count = self.candidates.vertex_face_count
        ee_count = self.candidates.edge_edge_count
        vf_pairs = self.candidates.vertex_face.numpy()[:vf_count].reshape(-1, 2)
        ee_pairs = self.candidates.edge_edge.numpy()[:ee_count].reshape(-1, 2)
        vf_toi = self.narrow_phase.vertex_face_toi.numpy()[:vf_count]
        ee_toi = self.narrow_phase.edge_edge_toi.numpy()[:ee_count]
        vf_keep = vf_toi <= 1.0
        ee_keep = ee_toi <= 1.0
        vertex_face = vf_pairs[vf_keep].astype(np.int32)
        vf_toi = vf_toi[vf_keep]
        edges = self.topology.edges
        ee_ids = ee_pairs[ee_keep]
        edge_edge = np.concatenate([edges[ee_ids[:, 0]], edges[ee_ids[:, 1]]], axis=1).astype(np.int32)
        ee_toi = ee_toi[ee_keep]
        vf_order = np.lexsort(vertex_face.T[::-1]) if len(vertex_face) else np.zeros(0, dtype=np.int64)
        ee_order = np.lexsort(edge_edge.T[::-1]) if len(edge_edge) else np.zeros(0, dtype=np.int64)
        return CollisionResult(
            vertex_face=np.ascontiguousarray(vertex_face[vf_order]).reshape(-1, 2),
            edge_edge=np.ascontiguousarray(edge_edge[ee_order]).reshape(-1, 4),
            vertex_face_toi=vf_toi[vf_order].astype(np.float32) if ccd else None,
            edge_edge_toi=ee_toi[ee_order].astype(np.float32) if ccd else None,
        )
