"""pscc: parallel self-collision culling (PSCC, I3D 2018) and cloth simulation on NVIDIA Warp.

Public API (one import path per name):

- :class:`CollisionDetector` / :class:`CollisionResult`: vertex-face and edge-edge collision
  detection (DCD proximity and conservative CCD) for triangle meshes.
- :func:`vertex_face_distance`, :func:`edge_edge_distance`: batched float32 distances.
- :func:`vertex_face_ccd`, :func:`edge_edge_ccd`: batched conservative float32 CCD.
- :func:`load_mesh`, :func:`validate_mesh`, :class:`MeshData`, :class:`MeshTopology`: mesh input.
- :class:`PsccError`, :class:`InputError`, :class:`OutputError`, :class:`CapacityError`: errors.
"""

from __future__ import annotations

from pscc.collision.detector import METHODS as METHODS
from pscc.collision.detector import CollisionDetector as CollisionDetector
from pscc.collision.detector import CollisionResult as CollisionResult
from pscc.errors import CapacityError as CapacityError
from pscc.errors import InputError as InputError
from pscc.errors import OutputError as OutputError
from pscc.errors import PsccError as PsccError
from pscc.geometry.ccd import edge_edge_ccd as edge_edge_ccd
from pscc.geometry.ccd import vertex_face_ccd as vertex_face_ccd
from pscc.geometry.distance import edge_edge_distance as edge_edge_distance
from pscc.geometry.distance import vertex_face_distance as vertex_face_distance
from pscc.mesh import MeshData as MeshData
from pscc.mesh import MeshTopology as MeshTopology
from pscc.mesh import load_mesh as load_mesh
from pscc.mesh import validate_mesh as validate_mesh

__version__ = "0.1.0"

__all__ = [
    "METHODS",
    "CapacityError",
    "CollisionDetector",
    "CollisionResult",
    "InputError",
    "MeshData",
    "MeshTopology",
    "OutputError",
    "PsccError",
    "edge_edge_ccd",
    "edge_edge_distance",
    "load_mesh",
    "validate_mesh",
    "vertex_face_ccd",
    "vertex_face_distance",
]
