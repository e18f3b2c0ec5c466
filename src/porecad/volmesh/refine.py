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
Marked vertices must not share a hexahedron (that needs the edge/full
templates of 004's ref. [11], which porecad does not provide yet).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

_P = 1.0 / 3.0


def _template():
    """The four hexahedra of the point template as (4, 8, 3) reference coordinates, VTK order, valid."""
    s = _P
    cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    small = cube * s
    hx = np.array([[s, 0, 0], [1, 0, 0], [1, 1, 0], [s, s, 0], [s, 0, s], [1, 0, 1], [1, 1, 1], [s, s, s]])
    out = [small]
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # Hx, then the cyclic axis permutations (Hy, Hz)
        h = hx[:, np.argsort(perm)]
        out.append(_valid(h))
    return np.stack(out)


def _corner_jac(h):
    from .hexshapes import HEX_CORNER_NEIGHBOURS
    e = h[HEX_CORNER_NEIGHBOURS] - h[:, None, :]
    return np.linalg.det(e)


def _valid(h):
    if np.all(_corner_jac(h) > 0):
        return h
    flipped = h[[4, 5, 6, 7, 0, 1, 2, 3]]
    if np.all(_corner_jac(flipped) > 0):
        return flipped
    raise AssertionError("refinement template is not a valid hexahedron")  # pragma: no cover


TEMPLATE = _template()


def _frame(k):
    """A corner permutation σ (VTK order) of a valid hex with σ[0] = k, keeping the hex valid."""
    from .hexshapes import HEX_CORNER_NEIGHBOURS
    i, j, l_ = HEX_CORNER_NEIGHBOURS[k]
    # in a valid hex the neighbours (i, j, l) of corner k play the roles of corners 1, 3, 4 of corner 0
    cube = {0: k, 1: i, 3: j, 4: l_}
    ref = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    # unit-cube position of every corner relative to k: derived from the unit cube itself
    pos = {c: ref[c] for c in range(8)}
    origin = pos[k]
    axes = [pos[cube[1]] - origin, pos[cube[3]] - origin, pos[cube[4]] - origin]
    M = np.array(axes).T  # maps new-frame coordinates to old cube offsets
    sigma = np.empty(8, np.int64)
    for c in range(8):
        target = origin + M @ ref[c]
        sigma[c] = int(np.flatnonzero(np.all(ref == target, axis=1))[0])
    return sigma


def _trilinear(corners, ref):
    """Map reference points (n, 3) through the 8 corners (8, 3) of a hex (VTK order)."""
    from ..maps.hexmesh import CORNERS
    w = np.stack([np.prod(np.where(c == 1, ref, 1.0 - ref), axis=1) for c in CORNERS], axis=1)
    return w @ corners


def refine_points(points, hexes, marked, tol=1e-9):
    """Apply the point template at each marked vertex; return the refined ``(points, hexes)``.

    Parameters
    ----------
    points : (V, 3) float
    hexes : (H, 8) int, valid (positive corner Jacobians), VTK order
    marked : iterable of vertex ids; no two in one hexahedron
    """
    from scipy.spatial import cKDTree

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
    new_pts = [P]
    new_hex = [H[per_hex == 0]]
    n = len(P)
    for h in np.flatnonzero(per_hex == 1):
        k = int(np.flatnonzero(is_marked[H[h]])[0])
        sigma = _frame(k)
        corners = P[H[h][sigma]]
        for t in TEMPLATE:
            new_pts.append(_trilinear(corners, t))
            new_hex.append(np.arange(n, n + 8)[None, :])
            n += 8
    allp = np.concatenate(new_pts)
    allh = np.concatenate(new_hex)
    # merge coincident points (the template's points shared between neighbours, and the old corners)
    scale = float(np.ptp(P, axis=0).max()) or 1.0
    pairs = cKDTree(allp).query_pairs(tol * scale, output_type="ndarray")
    rep = np.arange(len(allp))
    if len(pairs):
        import scipy.sparse as sp
        from scipy.sparse.csgraph import connected_components
        g = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(allp), len(allp)))
        _, labels = connected_components(g, directed=False)
        first = np.full(labels.max() + 1, len(allp))
        np.minimum.at(first, labels, np.arange(len(allp)))
        rep = first[labels]
    used, inv = np.unique(rep, return_inverse=True)
    return check_hex_mesh(allp[used], inv[allh.reshape(-1)].reshape(-1, 8))
