"""Parameterisation of closed bodies: heat-method geodesics and the hexahedral cube map (000 ch.3).

* :mod:`porecad.param.heat` — heat-method geodesic distance (Crane et al.
  2013) and geodesic edge paths (cotangent Laplacian and lumped mass from
  :mod:`porecad.mesh.operators`).
* :mod:`porecad.param.hexcube` — the structured ``(nu+1, nv+1, nw+1)`` node
  grid of a closed body, from its parts: :mod:`~porecad.param.cube` (labels,
  checks, face patches, box corners), :mod:`~porecad.param.cube_edges`
  (twelve geodesic cube edges, Table 3.1; side edges guided by conformal
  coordinates where geodesics touch), :mod:`~porecad.param.cube_ends`
  (corners around the ends of long bodies), :mod:`~porecad.param.patch_maps`
  (surface nodes by per-patch harmonic maps, interior by the discrete Laplace
  equation 000 eq. 3.2.3), :mod:`~porecad.param.grid_untangle` (untangling
  where a Jacobian is low; its local search :mod:`~porecad.param.grid_polish`) and :mod:`~porecad.param.hex_quality` (VTK
  hexahedra and scaled Jacobians); the facts of a run are a
  :class:`~porecad.param.hexgrid_info.HexGridInfo`.
"""

from porecad.mesh.operators import cotangent_laplacian, mass_matrix
from porecad.param.cube import CUBE, CUBE_EDGES, CUBE_FACES, FACE_EDGES, HEAT_RUNS, choose_corners
from porecad.param.cube_edges import cube_edges, surface_patches
from porecad.param.heat import HeatGeodesics, descent_path, dijkstra_path, edge_graph
from porecad.param.hex_quality import grid_to_hexes, scaled_jacobian
from porecad.param.hexcube import hex_parameterisation

__all__ = [
    "CUBE",
    "CUBE_EDGES",
    "CUBE_FACES",
    "FACE_EDGES",
    "HEAT_RUNS",
    "HeatGeodesics",
    "choose_corners",
    "cotangent_laplacian",
    "cube_edges",
    "descent_path",
    "dijkstra_path",
    "edge_graph",
    "grid_to_hexes",
    "hex_parameterisation",
    "mass_matrix",
    "scaled_jacobian",
    "surface_patches",
]
