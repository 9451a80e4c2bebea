"""Narrow phase: the conservative CCD / proximity test on every candidate feature pair.

One thread per candidate pair calls :func:`pscc.geometry.ccd.vertex_face_ccd_toi` or
:func:`pscc.geometry.ccd.edge_edge_ccd_toi`. Discrete detection (DCD) is the same test with the
end positions equal to the start positions: the pair is reported when it is provably within, or
possibly within (the documented tolerance band), the thickness.

======================  =====================  ===============================================
buffer                  shape, dtype           meaning
======================  =====================  ===============================================
vertex_face_toi         (capacity_vf,) f32     time of impact per vertex-face candidate; > 1 =
                                               no contact (``pscc.geometry.ccd.NO_HIT``)
edge_edge_toi           (capacity_ee,) f32     likewise per edge-edge candidate
======================  =====================  ===============================================
"""

from __future__ import annotations

import warp as wp

from pscc.collision.candidates import CandidatePairs
from pscc.geometry.ccd import CcdParameters, ccd_parameters, edge_edge_ccd_toi, vertex_face_ccd_toi

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _vertex_face_narrow(
    # in:
    faces: wp.array(dtype=wp.vec3i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per vertex-face candidate."""
    i = wp.tid()
    pair = pairs[i]
    v = pair[0]
    f = faces[pair[1]]
    toi_out[i] = vertex_face_ccd_toi(
        positions_t0[v], positions_t0[f[0]], positions_t0[f[1]], positions_t0[f[2]],
        positions_t1[v], positions_t1[f[0]], positions_t1[f[1]], positions_t1[f[2]],
        thickness, 0.0, params,
    )


@wp.kernel
def _edge_edge_narrow(
    # in:
    edges: wp.array(dtype=wp.vec2i),
    pairs: wp.array(dtype=wp.vec2i),
    positions_t0: wp.array(dtype=wp.vec3),
    positions_t1: wp.array(dtype=wp.vec3),
    thickness: float,
    params: CcdParameters,
    # out:
    toi_out: wp.array(dtype=wp.float32),
):
    """One thread per edge-edge candidate."""
    i = wp.tid()
    pair = pairs[i]
    a = edges[pair[0]]
    b = edges[pair[1]]
    toi_out[i] = edge_edge_ccd_toi(
        positions_t0[a[0]], positions_t0[a[1]], positions_t0[b[0]], positions_t0[b[1]],
        positions_t1[a[0]], positions_t1[a[1]], positions_t1[b[0]], positions_t1[b[1]],
        thickness, 0.0, params,
    )


class NarrowPhase:
    """Runs the conservative test on candidate pairs (layout in the module docstring).

    Args:
        faces: (face_count,) ``wp.vec3i``.
        edges: (edge_count,) ``wp.vec2i``.
        device: Warp device.
    """

    def __init__(self, faces: wp.array, edges: wp.array, device: wp.Device) -> None:
        self.device = device
        self.faces = faces
        self.edges = edges
        self.params = ccd_parameters()
        self.vertex_face_toi = wp.empty(1, dtype=wp.float32, device=device)
        self.edge_edge_toi = wp.empty(1, dtype=wp.float32, device=device)

    @property
    def device_bytes(self) -> int:
        """Bytes held on the device."""
        return self.vertex_face_toi.capacity + self.edge_edge_toi.capacity

    def run(
        self,
        candidates: CandidatePairs,
        positions_t0: wp.array,
        positions_t1: wp.array,
        thickness: float,
    ) -> None:
        """Test the first ``count`` candidates of each kind (counts read by ``candidates.fits()``).

        Allocates: only when the candidate buffers grew. Capture-safe: no (sizes come from the host).
        """
        vf = candidates.vertex_face_count
        ee = candidates.edge_edge_count
        if self.vertex_face_toi.shape[0] < candidates.capacity_vf:
            self.vertex_face_toi = wp.empty(candidates.capacity_vf, dtype=wp.float32, device=self.device)
        if self.edge_edge_toi.shape[0] < candidates.capacity_ee:
            self.edge_edge_toi = wp.empty(candidates.capacity_ee, dtype=wp.float32, device=self.device)
        if vf > 0:
            wp.launch(_vertex_face_narrow, dim=vf,
                      inputs=[self.faces, candidates.vertex_face, positions_t0, positions_t1,
                              float(thickness), self.params],
                      outputs=[self.vertex_face_toi], device=self.device)
        if ee > 0:
            wp.launch(_edge_edge_narrow, dim=ee,
                      inputs=[self.edges, candidates.edge_edge, positions_t0, positions_t1,
                              float(thickness), self.params],
                      outputs=[self.edge_edge_toi], device=self.device)
