"""Local repair of a few self-intersecting face pairs by relaxing their vertices.

Mapped scaffolds (000 ch.3, 004) are marching-cubes surfaces carried through an
isoparametric map. Where the map is nearly singular — cells whose two boundary
faces meet at almost 180° along a parameter-box edge — flat triangles of a
fraction of a sample can fold over their neighbours although the map's
Jacobian stays positive. The fold is local: moving the vertices of the faces
involved (and their one-ring) a step towards the centroid of their neighbours
(the umbrella operator of 004 eq. 4, restricted to that region) unfolds it.
Everything else is left exactly as it was, and the repair is reported.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .smooth import laplacian_smooth
from .validate import self_intersections, stored_coordinates, stored_with

__all__ = ["relax_self_intersections"]


def _vertex_adjacency(faces, n_vertices):
    rows = np.repeat(np.arange(len(faces)), 3)
    incidence = sp.csr_matrix((np.ones(rows.size, dtype=np.float32), (rows, faces.ravel())),
                              shape=(len(faces), n_vertices))
    return (incidence.T @ incidence).tocsr()


#: the widest neighbourhood (rings of vertices) :func:`relax_self_intersections` widens a stuck fold's region to
MAX_RINGS = 3


def relax_self_intersections(vertices, faces, pairs=None, max_rounds: int = 10, rings: int = 1,
                             lam: float = 0.5):
    """Unfold isolated self-intersections by local umbrella steps.

    Each round finds the self-intersecting face pairs, marks their vertices
    and ``rings`` rings of neighbours, and moves only those by one umbrella
    step ``v ← v + λ (mean of neighbours − v)`` (004 eq. 4); rounds repeat
    until no pair is left or ``max_rounds`` is reached. A round that leaves
    as many pairs as the one before widens the region by a ring (up to
    :data:`MAX_RINGS`): a fold that one ring cannot flatten (the femur's
    5×10×60 D scaffold at its strained end: 22 pairs, 3 left after ten
    rounds of one ring) is flattened with its wider neighbourhood (0 left).

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        A closed manifold mesh; the connectivity is not changed.
    pairs : (P, 2) int array, optional
        All self-intersecting face pairs when already known.

    Returns
    -------
    vertices : (V, 3) float64 array
        Rounded as mesh files store them (:func:`~porecad.mesh.validate.stored_coordinates`).
    info : dict
        ``pairs_before``, ``pairs_after`` (exact counts; ``pairs_after`` is that
        of the returned vertices), ``rounds``, ``vertices_moved``,
        ``max_move`` (the largest displacement, mesh units).
    """
    v, pairs = stored_with(vertices, pairs)
    v = np.asarray(v, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if pairs is None:
        pairs, total = self_intersections(v, f)
    else:
        total = len(pairs)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    info = {"pairs_before": int(total), "pairs_after": int(total), "rounds": 0,
            "vertices_moved": 0, "max_move": 0.0}
    if total == 0:
        return v, info
    v0 = v.copy()
    adjacency = _vertex_adjacency(f, len(v))
    moved = np.zeros(len(v), dtype=bool)
    width = int(rings)
    for rnd in range(max_rounds):
        region = np.zeros(len(v), dtype=bool)
        region[f[pairs.ravel()].ravel()] = True
        for _ in range(width):
            region |= (adjacency @ region.astype(np.float32)) > 0
        v = stored_coordinates(laplacian_smooth(v, f, iterations=1, lam=lam, fixed=~region))
        moved |= region
        before = total
        pairs, total = self_intersections(v, f)
        info["rounds"] = rnd + 1
        if total == 0:
            break
        if total >= before:  # stuck: flatten a wider neighbourhood
            width = min(width + 1, max(MAX_RINGS, int(rings)))
    info["rings"] = width
    info["pairs_after"] = int(total)
    info["vertices_moved"] = int(np.count_nonzero(np.any(v != v0, axis=1)))
    info["max_move"] = float(np.linalg.norm(v - v0, axis=1).max())
    return v, info
