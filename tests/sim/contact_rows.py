"""Test support: a ``ContactArgs`` filled by hand from host rows (shared by the device-path tests)."""

from __future__ import annotations

import numpy as np
import warp as wp

from pscc.collision.contacts import ContactArgs


def contact_args(device: str, faces: np.ndarray, edges: np.ndarray, vertex_face: np.ndarray,
                  vertex_face_toi: np.ndarray, edge_edge: np.ndarray, edge_edge_toi: np.ndarray,
                  spare: int = 3) -> ContactArgs:
    """A ContactArgs filled by hand. The buffers hold ``spare`` extra rows past the counts, all hits
    (toi 0) of valid ids: a reader that does not clamp to the counts appends them."""
    vf = np.concatenate([np.asarray(vertex_face, np.int32).reshape(-1, 2), np.zeros((spare, 2), np.int32)])
    ee = np.concatenate([np.asarray(edge_edge, np.int32).reshape(-1, 2), np.tile([[0, 1]], (spare, 1))])
    contacts = ContactArgs()
    contacts.faces = wp.array(np.asarray(faces, np.int32), dtype=wp.vec3i, device=device)
    contacts.edges = wp.array(np.asarray(edges, np.int32), dtype=wp.vec2i, device=device)
    contacts.vertex_face = wp.array(vf, dtype=wp.vec2i, device=device)
    contacts.edge_edge = wp.array(ee.astype(np.int32), dtype=wp.vec2i, device=device)
    contacts.vertex_face_toi = wp.array(np.concatenate([vertex_face_toi, np.zeros(spare)]).astype(np.float32),
                                        dtype=float, device=device)
    contacts.edge_edge_toi = wp.array(np.concatenate([edge_edge_toi, np.zeros(spare)]).astype(np.float32),
                                      dtype=float, device=device)
    contacts.counts = wp.array(np.array([len(vertex_face_toi), len(edge_edge_toi)], np.int32), dtype=wp.int32,
                               device=device)
    return contacts
