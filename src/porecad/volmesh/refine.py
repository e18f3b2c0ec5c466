"""Conforming refinement of hex meshes by templates (004 §3.2, Fig. 6: the point template).

The *point template* refines a hex mesh around a marked vertex ``v``: every
hexahedron containing ``v`` is split into four — a cube of one third of its
size at ``v`` and three hexahedra joining that cube's inner faces to the far
faces. In the reference cube with ``v`` at the origin, with ``p = 1/3``:

* ``S``  = ``[0, p]³``;
* ``Hx`` = the quad ``x = p`` of S (``(p,0,0) (p,p,0) (p,p,p) (p,0,p)``)
  joined to the face ``x = 1`` (``(1,0,0) (1,1,0) (1,1,1) (1,0,1)``),
  and ``Hy``, ``Hz`` likewise.

On a face containing ``v`` the split is the 2D corner template (a small
square and two quads through ``(p, p)`` to the far corner); faces without
``v`` stay whole. Both hexahedra sharing a face split it identically, so the
refined mesh is conforming whatever the neighbours, and one TPMS cell per
hexahedron puts pores a third of the size around ``v``
(:func:`porecad.maps.hexcells.hex_cells_scaffold`).
Marked vertices must not share a hexahedron; for whole regions (edge, face
and full templates) see :mod:`porecad.volmesh.refine_region`, which also
holds the templates themselves.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def refine_points(points, hexes, marked, tol=1e-9):
    """Apply the point template at each marked vertex; return the refined ``(points, hexes)``.

    Parameters
    ----------
    points : (V, 3) float
    hexes : (H, 8) int, valid (positive corner Jacobians), VTK order
    marked : iterable of vertex ids; no two in one hexahedron
    """
    from .hexshapes import check_hex_mesh
    P, H = check_hex_mesh(points, hexes)
    marked = np.unique(np.asarray(list(marked), dtype=np.int64))
    if marked.size == 0:
        return P, H
    if marked.min() < 0 or marked.max() >= len(P):
        raise InputError(f"refinement vertex ids must lie in 0..{len(P) - 1}")
    is_marked = np.zeros(len(P), bool)
    is_marked[marked] = True
    per_hex = is_marked[H].sum(axis=1)
    if per_hex.max() > 1:
        h = int(np.flatnonzero(per_hex > 1)[0])
        both = [int(v) for v in H[h][is_marked[H[h]]]]
        raise InputError(f"hexahedron {h} holds two refinement points {both}: the point template refines "
                         "around one vertex per hexahedron; mark vertices at least two cells apart")
    if np.any(~np.isin(marked, H)):
        raise InputError(f"refinement vertex {int(marked[~np.isin(marked, H)][0])} belongs to no hexahedron")
    from .refine_region import refine_region
    return refine_region(P, H, marked, tol=tol)
