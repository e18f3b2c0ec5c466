"""Splines: B-spline bases, trivariate B-spline volumes and solids (TBSS), LSPIA fitting.

The scaffold's macro shape is a TBSS, a map of the parameter cube ``[0,1]^3``
into space (001 §2.1); TPMS structures are designed in the cube and mapped
into it (001 §3.3). Threshold fields are scalar B-spline volumes fitted to
grid data by LSPIA (001 §3.2).
"""

from .basis import basis_functions, basis_matrix, find_spans, greville
from .construct import box_tbss, cylinder_tbss, disc_map, disc_tbss, fit_map, open_edges, tube_tbss
from .loft import loft_tbss
from .meshfit import fit_tbss_to_mesh
from .knots import clamped_uniform_knots, validate_knots
from .lspia import FitReport, fit_grid, fit_grid_lstsq, local_lspia
from .volume import TBSS, BSplineVolume, tensor_apply

__all__ = [
    "basis_functions", "basis_matrix", "find_spans", "greville",
    "clamped_uniform_knots", "validate_knots",
    "BSplineVolume", "TBSS", "tensor_apply",
    "FitReport", "fit_grid", "fit_grid_lstsq", "local_lspia",
    "box_tbss", "fit_map", "cylinder_tbss", "tube_tbss", "disc_map", "disc_tbss", "loft_tbss",
    "fit_tbss_to_mesh", "open_edges",
]
