"""Parameterisation of closed bodies: heat-method geodesics and the hexahedral cube map (000 ch.3).

* :mod:`porecad.param.heat` — cotangent Laplacian, lumped mass, heat-method
  geodesic distance (Crane et al. 2013) and geodesic edge paths.
* :mod:`porecad.param.hexcube` — eight corners, twelve geodesic cube edges
  (Table 3.1; side edges guided by conformal coordinates where geodesics
  touch), six face patches, and the structured ``(nu+1, nv+1, nw+1)`` node
  grid (surface by per-patch harmonic maps, interior by the discrete Laplace
  equation 000 eq. 3.2.3, untangled where a corner Jacobian is low), with
  VTK hexahedra and scaled Jacobians.
"""

from porecad.param.heat import (
    HeatGeodesics,
    cotangent_laplacian,
    descent_path,
    dijkstra_path,
    edge_graph,
    geodesic_distance,
    mass_matrix,
)
from porecad.param.hexcube import (
    CUBE,
    CUBE_EDGES,
    CUBE_FACES,
    FACE_EDGES,
    HEAT_RUNS,
    choose_corners,
    cube_edges,
    grid_to_hexes,
    hex_parameterisation,
    scaled_jacobian,
    surface_patches,
)

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
    "geodesic_distance",
    "grid_to_hexes",
    "hex_parameterisation",
    "mass_matrix",
    "scaled_jacobian",
    "surface_patches",
]
