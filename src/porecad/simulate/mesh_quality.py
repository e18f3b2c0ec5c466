"""Quality of tetrahedral meshes: dihedral angles, radius ratio, aspect ratio, periodic matching.

Definitions (Shewchuk, "What is a good linear finite element?", 2002, §6;
Liu & Joe, *BIT* 34 (1994) 268): the dihedral angle along an edge is the
angle between the two faces meeting there (70.53° for the regular tet);
the radius ratio is ``3 r / R`` (inradius over circumradius, 1 for the
regular tet, 0 for a flat one); the aspect ratio is the longest edge over
``2 √6 r`` (1 for the regular tet, unbounded for slivers and needles).
"""

from __future__ import annotations

import numpy as np

from porecad.errors import InputError
from porecad.simulate.sliver_repair import tet_dihedral_angles

__all__ = ["tet_mesh_quality", "periodic_face_mismatch", "DIHEDRAL_BINS"]

#: Histogram bin edges (degrees) of the dihedral angle distribution.
DIHEDRAL_BINS = [0, 5, 10, 15, 20, 30, 40, 60, 90, 120, 150, 165, 170, 175, 180]


def tet_mesh_quality(points, tets) -> dict:
    """Quality report of a linear tet mesh (the corner nodes of a quadratic one).

    Parameters
    ----------
    points : (V, 3) float array
    tets : (T, 4) int array

    Returns
    -------
    dict
        ``tets``, ``nodes``, ``volume``, ``volume_min`` (mm³), ``inverted``
        (tets with volume ≤ 0), ``dihedral_deg`` {min, max, p01, p1, p5,
        median, histogram {edges, counts}}, ``radius_ratio`` {min, p1,
        mean}, ``aspect_ratio`` {max, p99, mean}, ``below_5deg`` (tets
        with a dihedral angle under 5°).
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64)
    if t.ndim != 2 or t.shape[1] != 4 or len(t) == 0:
        raise InputError("a tet mesh needs a (T, 4) array of at least one tet")
    q = p[t]
    a, b, c = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    vol = det / 6.0
    dih = tet_dihedral_angles(p, t)
    dmin = dih.min(axis=1)
    faces = q[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]]
    area = 0.5 * np.linalg.norm(np.cross(faces[:, :, 1] - faces[:, :, 0], faces[:, :, 2] - faces[:, :, 0]), axis=2)
    num = (np.einsum("ij,ij->i", a, a)[:, None] * np.cross(b, c) + np.einsum("ij,ij->i", b, b)[:, None]
           * np.cross(c, a) + np.einsum("ij,ij->i", c, c)[:, None] * np.cross(a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_in = 3 * np.abs(vol) / area.sum(axis=1)
        R = np.linalg.norm(num, axis=1) / (2 * np.abs(det))
        ratio = np.nan_to_num(3 * r_in / R, nan=0.0)
        edges = q[:, [1, 2, 3, 2, 3, 3]] - q[:, [0, 0, 0, 1, 1, 2]]
        lmax = np.linalg.norm(edges, axis=2).max(axis=1)
        aspect = np.nan_to_num(lmax / (2 * np.sqrt(6) * r_in), nan=np.inf, posinf=np.inf)
    hist, _ = np.histogram(dih.ravel(), bins=DIHEDRAL_BINS)
    return {
        "tets": int(len(t)), "nodes": int(len(np.unique(t))), "volume": float(vol.sum()),
        "volume_min": float(vol.min()), "inverted": int((vol <= 0).sum()),
        "dihedral_deg": {"min": float(dih.min()), "max": float(dih.max()),
                         "p01": float(np.percentile(dmin, 0.1)), "p1": float(np.percentile(dmin, 1)),
                         "p5": float(np.percentile(dmin, 5)), "median": float(np.median(dih)),
                         "histogram": {"edges": DIHEDRAL_BINS, "counts": hist.tolist()}},
        "radius_ratio": {"min": float(ratio.min()), "p1": float(np.percentile(ratio, 1)),
                         "mean": float(ratio.mean())},
        "aspect_ratio": {"max": float(aspect.max()), "p99": float(np.percentile(aspect, 99)),
                         "mean": float(aspect[np.isfinite(aspect)].mean())},
        "below_5deg": int((dmin < 5).sum()),
    }


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
