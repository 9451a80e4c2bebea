"""Which vertices a seam joins: stitched features count as connected, never as a contact or a crossing.

A stitch ``(i, j, k, r)`` sews vertex i to the point ``(1 - r) x_j + r x_k`` of another panel's edge
(:attr:`pscc.sim.scene.Scene.stitches`). Along a closed seam, i lies on that edge and touches the faces
around it, exactly as two faces that share a vertex touch; like those, the pairs a stitch joins are left
out of collision detection and of the intersection check. :class:`SeamAdjacency` holds, for every vertex
of the collision mesh, the vertices it is stitched to (i with j and k, both ways), as CSR arrays on the
device; :func:`stitched` and :func:`stitched_to_face` test them in kernels. A pair is left out when:

* vertex-face (v, f): v is a vertex of f (as before) or stitched to one of f's vertices;
* edge-edge (a, b): they share a vertex (as before) or an end of a is stitched to an end of b;
* intersection check, edge e against face f: an end of e is a vertex of f or stitched to one.

Without stitches the arrays hold one zero and every test is one comparison.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.mesh.mesh_data import check_stitches

wp.set_module_options({"enable_backward": False})

__all__ = ["SeamAdjacency", "SeamArgs", "stitched", "stitched_to_face"]


@wp.struct
class SeamArgs:
    """Stitch partners of every vertex, CSR: ``partners[offsets[v]:offsets[v + 1]]``."""

    offsets: wp.array(dtype=wp.int32)
    partners: wp.array(dtype=wp.int32)


@wp.func
def stitched(seams: SeamArgs, a: int, b: int) -> bool:
    """Whether vertices a and b are joined by a stitch."""
    if a < 0 or a >= seams.offsets.shape[0] - 1:
        return False
    for k in range(seams.offsets[a], seams.offsets[a + 1]):
        if seams.partners[k] == b:
            return True
    return False


@wp.func
def stitched_to_face(seams: SeamArgs, v: int, face: wp.vec3i) -> bool:
    """Whether vertex v is stitched to a vertex of ``face``."""
    return stitched(seams, v, face[0]) or stitched(seams, v, face[1]) or stitched(seams, v, face[2])


class SeamAdjacency:
    """The stitch partners of each vertex on the device (module docstring).

    Args:
        stitches: (s, 4) rows ``(i, j, k, r)`` in the collision mesh's vertex ids, or None.
        vertex_count: vertices of the collision mesh.
        device: Warp device.
    """

    def __init__(self, stitches: np.ndarray | None, vertex_count: int, device: wp.DeviceLike) -> None:
        self.device = wp.get_device(device)
        self.vertex_count = int(vertex_count)
        self.args = SeamArgs()
        """The device arrays as the kernels' struct."""
        self.rebuild(stitches)

    def rebuild(self, stitches: np.ndarray | None) -> None:
        """Replace the partners with those of ``stitches`` (new arrays: consumers that copied :attr:`args`
        into a struct of their own assign it again, and graphs that bound the old arrays are recorded
        again). Allocates: yes. Capture-safe: no."""
        vertex_count = self.vertex_count
        rows = check_stitches(np.zeros((0, 4)) if stitches is None else stitches, vertex_count, "argument")
        ids = rows[:, :3].astype(np.int64)
        pairs = np.concatenate([ids[:, [0, 1]], ids[:, [0, 2]]]) if ids.size else np.zeros((0, 2), np.int64)
        pairs = np.unique(np.concatenate([pairs, pairs[:, ::-1]]), axis=0)  # both ways, sorted by vertex
        self.pair_count = int(pairs.shape[0] // 2)
        """Distinct stitched vertex pairs."""
        self.args = SeamArgs()
        if pairs.size:
            offsets = np.zeros(vertex_count + 1, dtype=np.int32)
            np.add.at(offsets, pairs[:, 0] + 1, 1)
            self.args.offsets = wp.array(np.cumsum(offsets).astype(np.int32), dtype=wp.int32, device=self.device)
            self.args.partners = wp.array(pairs[:, 1].astype(np.int32), dtype=wp.int32, device=self.device)
        else:
            self.args.offsets = wp.zeros(1, dtype=wp.int32, device=self.device)
            self.args.partners = wp.zeros(1, dtype=wp.int32, device=self.device)

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self.args.offsets.capacity + self.args.partners.capacity
