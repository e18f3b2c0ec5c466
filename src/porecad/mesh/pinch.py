"""Pinched vertices: one vertex where two or more fans of faces meet, split into one vertex per fan.

A marching-cubes or cut surface can pass two sheets of a solid through the
same vertex (a "bowtie": two cones sharing their apex). The mesh is closed
and every edge has two faces, but the vertex is not manifold, and a volume
mesher or Boolean refuses it. Splitting the vertex into one copy per fan and
moving each copy a hair into its own fan (a thousandth of the mean edge
length, towards the fan's centroid) separates the sheets without changing the
solid measurably; nothing else moves.
"""

from __future__ import annotations

import numpy as np


def split_pinched_vertices(vertices, faces, nudge: float = 1e-3):
    """``(vertices, faces, n_split)``: every pinched vertex of a closed mesh split into one per fan.

    Fans are the edge-connected groups of faces around a vertex, found by
    joining each face corner to the corner at the same vertex across each
    of the corner's two edges. A mesh with an edge of more or fewer than two
    faces (not closed, non-manifold edges) is returned unchanged with
    ``n_split = 0``, as is a mesh without pinched vertices.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    v = np.asarray(vertices)
    f = np.asarray(faces, np.int64)
    nf, nv = len(f), len(v)
    if nf == 0:
        return v, f, 0
    corner = np.arange(3 * nf).reshape(nf, 3)
    a, b = f.ravel(), np.roll(f, -1, axis=1).ravel()         # half-edge a -> b of each corner slot
    ca, cb = corner.ravel(), np.roll(corner, -1, axis=1).ravel()
    key, rkey = a * nv + b, b * nv + a
    order = np.argsort(key, kind="stable")
    skey = key[order]
    if np.any(skey[1:] == skey[:-1]):  # a half-edge twice: not an oriented manifold
        return v, f, 0
    pos = np.clip(np.searchsorted(skey, rkey), 0, len(skey) - 1)
    if not np.array_equal(skey[pos], rkey):
        return v, f, 0
    opp = order[pos]  # the opposite half-edge b -> a; its second corner (cb) sits at a
    g = coo_matrix((np.ones(len(ca), np.int8), (ca, cb[opp])), shape=(3 * nf, 3 * nf))
    _, fan = connected_components(g, directed=False)
    m = int(fan.max()) + 1  # (vertex, fan) pairs as one sorted integer key: np.unique(axis=0) is far slower
    keys, new_index = np.unique(f.ravel() * m + fan, return_inverse=True)
    pairs = np.column_stack([keys // m, keys % m])
    n_split = len(pairs) - int(np.count_nonzero(np.bincount(f.ravel(), minlength=nv)))
    if n_split == 0:
        return v, f, 0
    new_v = v[pairs[:, 0]].astype(np.float64)
    new_f = new_index.reshape(nf, 3)
    pinched = np.flatnonzero(np.bincount(pairs[:, 0], minlength=nv) > 1)
    copy = np.isin(pairs[:, 0], pinched)
    centroid = np.zeros_like(new_v)
    np.add.at(centroid, new_f.ravel(), np.repeat(v[f].mean(axis=1), 3, axis=0))
    centroid /= np.maximum(np.bincount(new_f.ravel(), minlength=len(new_v)), 1)[:, None]
    edge = float(np.linalg.norm(v[f[:, 1]] - v[f[:, 0]], axis=1).mean())
    step = centroid[copy] - new_v[copy]
    step *= (nudge * edge / np.maximum(np.linalg.norm(step, axis=1), 1e-300))[:, None]
    new_v[copy] += step
    return new_v, new_f, int(n_split)
