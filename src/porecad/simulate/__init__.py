"""From scaffold to simulation: volume meshes, homogenised stiffness and permeability.

Modules
-------
hex8
    The 8-node voxel hexahedron: stiffness and macro-strain loads.
voxel_fe
    Matrix-free periodic voxel operator and its Galerkin multigrid (numba).
homogenise
    Homogenised 6 × 6 stiffness by periodic voxel FE (six unit strains, MG-PCG).
elastic_tensors
    Engineering constants, directional modulus, Zener ratio, Hashin–Shtrikman
    bounds, exact laminate, Gibson–Ashby fit.
periodic_components
    Face-connected components of a periodic phase and the axes they span.
cell_voxels
    Periodic voxel images of TPMS recipes, voxel images of closed meshes.
stokes
    Darcy permeability tensor by a Stokes solve on the voxel pore space.
"""

from porecad.simulate.elastic_tensors import (
    directional_modulus,
    directional_modulus_extremes,
    engineering_constants,
    gibson_ashby_fit,
    hashin_shtrikman_upper,
    laminate_stiffness,
    zener_ratio,
)
from porecad.simulate.homogenise import check_moduli, estimate_stiffness_memory, homogenise_stiffness

__all__ = [
    "check_moduli",
    "directional_modulus",
    "directional_modulus_extremes",
    "engineering_constants",
    "estimate_stiffness_memory",
    "gibson_ashby_fit",
    "hashin_shtrikman_upper",
    "homogenise_stiffness",
    "laminate_stiffness",
    "zener_ratio",
]
