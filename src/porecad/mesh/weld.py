"""Merging points that coincide up to rounding (cells mapped separately, templates placed separately)."""

from __future__ import annotations

import numpy as np

__all__ = ["close_point_representatives", "compact"]


def close_point_representatives(points, tol: float, candidates=None) -> np.ndarray:
    """For each point, the smallest index of the points within ``tol`` of it (transitively).

    ``candidates`` (indices) limits the search to the points that may have
    twins (e.g. those on shared faces); the others map to themselves. Pairs
    come from a k-d tree, groups from the connected components of the pair
    graph. Use ``np.unique(rep[ids], return_inverse=True)`` to renumber.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    cand = np.arange(n) if candidates is None else np.asarray(candidates, dtype=np.int64)
    pairs = cKDTree(p[cand]).query_pairs(float(tol), output_type="ndarray")
    if len(pairs) == 0:
        return np.arange(n)
    a, b = cand[pairs[:, 0]], cand[pairs[:, 1]]
    g = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, labels = connected_components(g, directed=False)
    first = np.full(labels.max() + 1, n)
    np.minimum.at(first, labels, np.arange(n))
    return first[labels]


def compact(points, faces):
    """Drop the points no face uses and renumber: ``(points[used], faces renumbered)``."""
    f = np.asarray(faces, dtype=np.int64)
    mask = np.zeros(len(points), bool)
    mask[f.ravel()] = True  # a mask, not np.unique: no sort of 3F indices
    used = np.flatnonzero(mask)
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    return np.asarray(points)[used], remap[f]
