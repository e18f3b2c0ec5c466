"""The design domain of a lattice job (``tpms`` / ``infill``) for its report's analysis (issue 22).

The analysis measures porosity, pore and strut sizes and connectivity inside
the domain the lattice fills, never in the air of a bounding box:

* a box of cells — that box (:class:`~porecad.analysis.domain.BoxDomain`:
  its faces cut the lattice, they are no walls);
* a body with ``boundary = "cut"`` or ``"skin"`` — the body (a mesh body's
  exact surface, or the analytic disc's field);
* ``boundary = "whole"`` — the union of the complete cells the lattice
  fills (the band of the body around them holds no lattice), its boundary
  made only when a report directory asks for the analysis.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..lattice.plan import LatticePlan


def lattice_analysis_domain(plan: LatticePlan, grid, whole_info, domain_volume):
    """``(domain, volume)`` of a finished lattice job's plan (see the module doc).

    ``plan.cells`` is the :class:`~porecad.bodies.cells.CellUnion` of a
    ``whole`` infill (``whole_info`` not None).
    """
    from ..analysis.domain import BoxDomain
    from .contract import DeferredDomain
    if plan.body is None:
        return BoxDomain(grid.box_min, grid.box_max), domain_volume
    if whole_info is not None:
        from ..maps.domain_surface import cell_union_surface
        cells = plan.cells
        return (DeferredDomain(cell_union_surface, cells.kept, cells.c_lo, cells.origin, cells.L),
                float(whole_info["cells_volume"]))
    return plan.body, domain_volume
