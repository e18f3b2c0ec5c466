"""Tetrahedral meshes: validation, adjacency, colouring, quality, point location, BCC lattice meshing, file I/O.

Plain arrays throughout: ``points`` ``(V, 3)`` float64 (mm) and ``tets``
``(T, 4)`` int64, positively oriented (see :mod:`porecad.volmesh.tetmesh`).
"""

from porecad.volmesh.bcc import bcc_tet_mesh, tetrahedralise_body
from porecad.volmesh.shapes import cube_tets, icosahedron_tets, regular_tetrahedron, two_tetrahedra
from porecad.volmesh.tetio import (VOLUME_MESH_SUFFIXES, is_volume_mesh_path, read_tet_mesh, read_volume_mesh,
                                   write_tet_mesh)
from porecad.volmesh.tetlocate import TetLocator, locate_points
from porecad.volmesh.tetmesh import (
    FACE_LOCAL,
    boundary_faces,
    check_tet_mesh,
    face_adjacency,
    rainbow_coloring,
    signed_volumes,
    tet_quality,
)

__all__ = [
    "FACE_LOCAL",
    "TetLocator",
    "VOLUME_MESH_SUFFIXES",
    "bcc_tet_mesh",
    "tetrahedralise_body",
    "boundary_faces",
    "check_tet_mesh",
    "cube_tets",
    "face_adjacency",
    "icosahedron_tets",
    "is_volume_mesh_path",
    "locate_points",
    "rainbow_coloring",
    "read_tet_mesh",
    "read_volume_mesh",
    "regular_tetrahedron",
    "signed_volumes",
    "tet_quality",
    "two_tetrahedra",
    "write_tet_mesh",
]
