"""Point location in a tetrahedral mesh: the tet holding each query point and its barycentric coordinates.

Tets are binned by bounding box into a uniform grid (:class:`TetLocator`,
built once, queried many times by the TIS grid sampler, curvature and the
BCC coverage check); :func:`locate_points` is the one-shot form. Meshes are
plain arrays as in :mod:`porecad.volmesh.tetmesh`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from porecad.errors import InputError
from porecad.mesh.box_bins import bin_boxes, bin_index
from porecad.volmesh.tetmesh import as_points, as_tets

__all__ = ["TetLocator", "locate_points"]


@njit(cache=True, parallel=True)
def _locate(query, p0, inv, origin, cell, dims, start, items, tol, out_t, out_b):
    nq = query.shape[0]
    for q in prange(nq):
        out_t[q] = -1
        i = int(math.floor((query[q, 0] - origin[0]) / cell))
        j = int(math.floor((query[q, 1] - origin[1]) / cell))
        k = int(math.floor((query[q, 2] - origin[2]) / cell))
        if i < 0 or j < 0 or k < 0 or i >= dims[0] or j >= dims[1] or k >= dims[2]:
            continue
        c = bin_index(i, j, k, dims)
        best = -np.inf
        for s in range(start[c], start[c + 1]):
            t = items[s]
            dx = query[q, 0] - p0[t, 0]
            dy = query[q, 1] - p0[t, 1]
            dz = query[q, 2] - p0[t, 2]
            l1 = inv[t, 0, 0] * dx + inv[t, 0, 1] * dy + inv[t, 0, 2] * dz
            l2 = inv[t, 1, 0] * dx + inv[t, 1, 1] * dy + inv[t, 1, 2] * dz
            l3 = inv[t, 2, 0] * dx + inv[t, 2, 1] * dy + inv[t, 2, 2] * dz
            l0 = 1.0 - l1 - l2 - l3
            m = min(min(l0, l1), min(l2, l3))
            if m >= -tol and m > best:  # the tet holding the point most deeply
                best = m
                out_t[q] = t
                out_b[q, 0] = l0
                out_b[q, 1] = l1
                out_b[q, 2] = l2
                out_b[q, 3] = l3
                if m >= 0.0:
                    break


class TetLocator:
    """Point location in a tet mesh: tets binned by bounding box into a uniform grid.

    The grid cell is about the mean tet size; a query tests the tets of its
    cell with the barycentric coordinates ``(l1, l2, l3) = M^{-1} (x - p0)``,
    ``l0 = 1 - l1 - l2 - l3``, ``M = [p1 - p0, p2 - p0, p3 - p0]``. Build once,
    query many times (the TIS grid sampler and curvature use it).
    """

    def __init__(self, points, tets):
        p = as_points(points)
        t = as_tets(tets, len(p))
        self.n_tets = len(t)
        if len(t) == 0:
            return
        q = p[t]
        M = np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]], axis=2)  # columns
        try:
            self.inv = np.ascontiguousarray(np.linalg.inv(M))
        except np.linalg.LinAlgError:
            det = np.linalg.det(M)
            raise InputError(f"tet {int(np.argmin(np.abs(det)))} is degenerate (zero volume); "
                             "cannot locate points in it") from None
        self.p0 = np.ascontiguousarray(q[:, 0])
        lo_t = q.min(axis=1)
        hi_t = q.max(axis=1)
        self.origin = lo_t.min(axis=0)
        ext = hi_t.max(axis=0) - self.origin
        cell = float(np.mean((hi_t - lo_t).max(axis=1)))
        # at most ~8 cells per tet and 2^31 cells in all
        cell = max(cell, float(ext.max()) / 2**10, 1e-12)
        while True:
            dims = (np.floor(ext / cell).astype(np.int64) + 1)
            if np.prod(dims.astype(np.float64)) <= max(8.0 * len(t), 1e6):
                break
            cell *= 1.25
        self.cell, self.dims = cell, dims
        self.start, self.items = bin_boxes(lo_t, hi_t, self.origin, cell, dims)

    def locate(self, query, tol: float = 1e-9):
        """``(tet (Q,), bary (Q, 4))``: containing tet (-1 outside) and its barycentric coordinates (NaN outside)."""
        qp = as_points(query)
        out_t = np.full(len(qp), -1, np.int64)
        out_b = np.full((len(qp), 4), np.nan)
        if self.n_tets == 0 or len(qp) == 0:
            return out_t, out_b
        _locate(qp, self.p0, self.inv, self.origin, self.cell, self.dims, self.start, self.items, float(tol),
                out_t, out_b)
        return out_t, out_b


def locate_points(points, tets, query, tol: float = 1e-9):
    """The tet containing each query point, with its barycentric coordinates (see :class:`TetLocator`).

    Parameters
    ----------
    points : (V, 3) float array
    tets : (T, 4) int array
        Non-degenerate tets (any orientation).
    query : (Q, 3) float array
    tol : float
        Barycentric tolerance (points on shared faces find one of the tets).

    Returns
    -------
    tet : (Q,) int64
        Index of the containing tet, ``-1`` outside the mesh.
    bary : (Q, 4) float64
        Barycentric coordinates in that tet (weights of ``tets[tet]``), NaN
        outside.
    """
    return TetLocator(points, tets).locate(query, tol)
