"""Triangle meshes: validation, file input/output, topology tables and procedural generators.

See ``docs/mesh-input.md`` for the accepted file formats and what is rejected.
"""

from __future__ import annotations

from pscc.mesh.generate import folded_sheet, grid_sheet, twisted_sheet
from pscc.mesh.io import SUPPORTED_EXTENSIONS, load_mesh, load_positions, save_mesh_npz
from pscc.mesh.mesh_data import MeshData, validate_mesh
from pscc.mesh.topology import MeshTopology

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "MeshData",
    "MeshTopology",
    "folded_sheet",
    "grid_sheet",
    "load_mesh",
    "load_positions",
    "save_mesh_npz",
    "twisted_sheet",
    "validate_mesh",
]
