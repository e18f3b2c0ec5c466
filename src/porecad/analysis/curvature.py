"""Discrete mean and Gaussian curvature of a triangle mesh (per vertex).

Mean curvature from the cotangent Laplacian (Meyer et al. 2003, with the
barycentric vertex area ``A_i`` = a third of the adjacent faces' areas):

.. math:: \\mathbf K(x_i) = \\frac{1}{2A_i} \\sum_j (\\cot\\alpha_{ij} + \\cot\\beta_{ij})(x_i - x_j)
          = 2 H_i \\mathbf n_i ,

signed positive where the surface bends away from its outward normal (a
sphere has ``H = 1/R``). Gaussian curvature by the angle deficit,
``K_i = (2π − Σ θ_j) / A_i``. Boundary vertices of open meshes get NaN.
002 Table 2 reports such statistics (min, max, median, mean, standard
deviation, variance) for TPMS surfaces: symmetric about ≈ 0.
"""

from __future__ import annotations

import numpy as np


def vertex_curvatures(vertices, faces):
    """Per-vertex ``(H, K, area)``: mean and Gaussian curvature (1/mm, 1/mm²) and vertex area."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    p = [v[f[:, c]] for c in range(3)]
    e = [p[(c + 2) % 3] - p[(c + 1) % 3] for c in range(3)]  # edge opposite corner c
    cross = np.cross(p[1] - p[0], p[2] - p[0])
    dbl = np.linalg.norm(cross, axis=1)
    area = np.zeros(n)
    for c in range(3):
        np.add.at(area, f[:, c], dbl / 6.0)
    lap = np.zeros((n, 3))
    angle_sum = np.zeros(n)
    normal = np.zeros((n, 3))
    safe = np.where(dbl > 0, dbl, np.inf)
    for c in range(3):
        a = -e[(c + 1) % 3]       # from corner c along its two edges
        b = e[(c + 2) % 3]
        cot = np.einsum("ij,ij->i", a, b) / safe   # cot of the angle at corner c
        ang = np.arctan2(dbl, np.einsum("ij,ij->i", a, b))
        np.add.at(angle_sum, f[:, c], ang)
        np.add.at(normal, f[:, c], cross)
        i, j = f[:, (c + 1) % 3], f[:, (c + 2) % 3]   # the edge opposite corner c
        w = cot  # each face adds its angle's cot: the two faces of an edge give cot α + cot β
        d = (v[i] - v[j]) * w[:, None]
        np.add.at(lap, i, d)
        np.add.at(lap, j, -d)
    with np.errstate(invalid="ignore", divide="ignore"):
        kvec = lap / (2.0 * area[:, None])
        nn = normal / np.linalg.norm(normal, axis=1)[:, None]
        H = 0.5 * np.einsum("ij,ij->i", kvec, nn)
        K = (2.0 * np.pi - angle_sum) / area
    # boundary vertices (open meshes): curvature undefined
    from ..mesh.validate import edge_topology
    if not edge_topology(f)["closed"]:
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, counts = np.unique(edges, axis=0, return_counts=True)
        boundary = np.unique(uniq[counts == 1])
        H[boundary] = np.nan
        K[boundary] = np.nan
    return H, K, area


def curvature_stats(values, weights=None) -> dict:
    """Min, max, median, mean, standard deviation and variance (weighted by area), NaNs dropped."""
    x = np.asarray(values, dtype=np.float64)
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=np.float64)
    ok = np.isfinite(x) & (w > 0)
    x, w = x[ok], w[ok]
    if x.size == 0:
        return {}
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    median = float(x[order][np.searchsorted(cw, 0.5 * cw[-1])])
    mean = float(np.average(x, weights=w))
    var = float(np.average((x - mean) ** 2, weights=w))
    return {"min": float(x.min()), "max": float(x.max()), "median": median, "mean": mean,
            "std": var ** 0.5, "variance": var}
