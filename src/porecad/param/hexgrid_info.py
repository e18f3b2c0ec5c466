"""The facts of a hexahedral parameterisation: :class:`HexGridInfo`, the second value of
:func:`porecad.param.hexcube.hex_parameterisation`.

Its fields are the run's figures (JSON: the corner choice, the grid's
quality, the untangling, times, what was rejected) and the arrays the grid
was built on (the mesh, its corners, cube-edge paths and patch labels, and
when asked for the patch maps' locators). :meth:`HexGridInfo.report` gives
the facts as the hex job reports them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["SJ_POOR", "HexGridInfo"]

#: scaled Jacobian below which a cell counts as poor (:attr:`HexGridInfo.fraction_below_poor`)
SJ_POOR = 0.2


@dataclasses.dataclass(kw_only=True)
class HexGridInfo:
    """What :func:`~porecad.param.hexcube.hex_parameterisation` found besides the nodes (module docstring)."""

    # -- figures (JSON) -------------------------------------------------------------------------------------------
    corner_choice: str           # "given", "box", "sphere" or "ends (offset …)"; ", proportional" appended when
    #                              the Laplace grid with the body's proportions was kept
    grid: tuple                  # the element grid (nu, nv, nw)
    element: str                 # "hex8" or "hex20" (then the node grid has half steps)
    subdivisions: int            # midpoint subdivisions of the input mesh (one more when no corner choice found paths)
    patch_maps: list             # the map weights used per face patch ("cotangent" or "mean-value")
    patch_balance: int           # rounds of stretch balancing of the patch maps
    path_fallbacks: int          # Dijkstra paths in the heat runs
    times: dict                  # seconds: setup (mesh checks, subdivision), corners (choices tried and not kept),
    #                              geodesics (the kept choice's corners and cube edges), surface_grid, volume,
    #                              untangle, patches, total
    min_scaled_jacobian: float   # smallest corner scaled Jacobian of the elements' corner cells
    min_scaled_jacobian_inside: float  # smallest det / mean |det| of the element maps (maps.hexmesh.sampled_jacobians)
    fraction_below_poor: float   # elements with corner scaled Jacobian < SJ_POOR (report key fraction_below_0.2)
    min_scaled_jacobian_laplace: float  # min corner scaled Jacobian of the Laplace grid, before untangling
    untangle_iterations: int     # iterations of the untangling
    untangle_stopped: bool       # the untangling stopped at its time limit
    straightened: dict | None    # hex20: param.half_grid.straighten_folded facts where curved elements still folded
    boundary_lift: dict          # max_lift (how far the untangling lifted boundary nodes outwards, mean grid
    #                              edges) and lifted_nodes
    estimates: dict              # estimated untangling seconds per grid untangled
    nodes: int                   # nodes of the node grid
    boundary_nodes: int          # of them on the boundary
    interior_nodes: int          # of them inside
    hexes: int                   # elements
    rejected: list               # (corner choice, reason) of the choices that failed
    laplace_grids: list          # every choice's grid before untangling: choice, folded_elements, min_quality
    conformal_sphere: dict | None = None  # param.sphere_map.conformal_sphere facts, when that choice was built
    # -- arrays and objects -----------------------------------------------------------------------------------------
    corners: np.ndarray          # (8,) the cube's corner vertices (indices of ``vertices``)
    vertices: np.ndarray         # (V, 3) the mesh the paths and labels refer to: the input or its subdivision
    faces: np.ndarray            # (F, 3) its triangles
    paths: list                  # the 12 cube edges as vertex paths
    patch_labels: np.ndarray     # (F,) face patch of each triangle
    locators: list | None = None  # with keep_locators: the six patches' maps (param.patch_maps.PatchLocator)

    def report(self) -> dict:
        """The facts as the hex job reports them (``body.parameterisation``).

        The figures only: not the arrays (``corners``, which the job writes as
        integers beside, the mesh, its paths and patch labels — a femur's
        report carried its subdivided mesh as JSON lists — and ``locators``);
        ``conformal_sphere`` only when that choice was built.
        """
        out = {"corner_choice": self.corner_choice, "grid": self.grid, "element": self.element,
               "subdivisions": self.subdivisions, "patch_maps": self.patch_maps,
               "patch_balance": self.patch_balance, "path_fallbacks": self.path_fallbacks, "times": self.times,
               "min_scaled_jacobian": self.min_scaled_jacobian,
               "min_scaled_jacobian_inside": self.min_scaled_jacobian_inside,
               f"fraction_below_{SJ_POOR:g}": self.fraction_below_poor,
               "min_scaled_jacobian_laplace": self.min_scaled_jacobian_laplace,
               "untangle_iterations": self.untangle_iterations, "untangle_stopped": self.untangle_stopped,
               "straightened": self.straightened, "boundary_lift": self.boundary_lift, "estimates": self.estimates,
               "nodes": self.nodes, "boundary_nodes": self.boundary_nodes, "interior_nodes": self.interior_nodes,
               "hexes": self.hexes, "rejected": self.rejected, "laplace_grids": self.laplace_grids}
        if self.conformal_sphere is not None:
            out["conformal_sphere"] = self.conformal_sphere
        return out
