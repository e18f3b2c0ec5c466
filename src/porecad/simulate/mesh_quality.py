"""Periodic matching of tetrahedral meshes of a cell; their quality report is
:func:`porecad.volmesh.tetmesh.tet_quality`.
"""

from __future__ import annotations

import numpy as np


__all__ = ["periodic_face_mismatch"]


def periodic_face_mismatch(points, lo, hi, tol: float = 1e-9) -> dict:
    """How well the nodes on opposite faces of a cell box match under translation.

    For each axis, every node on the lower face is paired with the nearest
    node on the upper face translated back by the cell length (and vice
    versa).

    Returns
    -------
    dict
        ``x``, ``y``, ``z``: {``nodes_low``, ``nodes_high``, ``max_distance``
        (relative to the cell size)}, and ``matched`` (equal counts and every
        distance ≤ ``tol``).
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    size = float(np.max(hi - lo))
    eps = 1e-9 * size
    out = {}
    ok = True
    for a, name in enumerate("xyz"):
        A = p[np.abs(p[:, a] - lo[a]) <= eps]
        B = p[np.abs(p[:, a] - hi[a]) <= eps].copy()
        B[:, a] -= hi[a] - lo[a]
        if len(A) == 0 or len(B) == 0:
            dist = 0.0 if len(A) == len(B) else float("inf")
        else:
            d1, _ = cKDTree(B).query(A)
            d2, _ = cKDTree(A).query(B)
            dist = float(max(d1.max(), d2.max()) / size)
        out[name] = {"nodes_low": int(len(A)), "nodes_high": int(len(B)), "max_distance": dist}
        ok &= len(A) == len(B) and dist <= tol
    out["matched"] = bool(ok)
    return out
