"""Localised implicit fields of one skeleton segment (003 §3.3).

:func:`tube_distance` is the *swept-radius tube* used when only radii are
known: the signed distance to the union of balls ``B(p(t), r(t))`` swept
along the segment's polyline with the radius varying linearly along every
edge. Per edge ``a → b`` (length ``ℓ``, radii ``r_a, r_b``, ``|r_b − r_a| < ℓ``)
this is the exact "round cone": in the axial/radial coordinates ``(h, q)``
of a point, with ``n_h = (r_a − r_b)/ℓ`` (the common tangent ``n·(h, q) = r_a``
of the circles about ``(0, 0)`` and ``(ℓ, 0)``), ``n_q = sqrt(1 − n_h²)`` and the
centre parameter ``t_c = h − q n_h / n_q``::

    d = n_h h + n_q q − r_a      if 0 ≤ t_c ≤ ℓ    (the cone side)
    d = |x − a| − r_a            if t_c < 0
    d = |x − b| − r_b            if t_c > ℓ

(the larger ball when one contains the other). The tube is the minimum over
the edges, exact outside, negative inside (003 Eq. 4.9 sign convention).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _round_cone(px, py, pz, ax, ay, az, bx, by, bz, ra, rb):
    ux, uy, uz = bx - ax, by - ay, bz - az
    ell = np.sqrt(ux * ux + uy * uy + uz * uz)
    wx, wy, wz = px - ax, py - ay, pz - az
    da = np.sqrt(wx * wx + wy * wy + wz * wz) - ra
    vx, vy, vz = px - bx, py - by, pz - bz
    db = np.sqrt(vx * vx + vy * vy + vz * vz) - rb
    dr = ra - rb
    if abs(dr) >= ell:
        return min(da, db)
    ux /= ell
    uy /= ell
    uz /= ell
    h = wx * ux + wy * uy + wz * uz
    q2 = wx * wx + wy * wy + wz * wz - h * h
    q = np.sqrt(q2) if q2 > 0 else 0.0
    nh = dr / ell
    nq = np.sqrt(1.0 - nh * nh)
    tc = h - q * nh / nq
    if tc < 0.0:
        return da
    if tc > ell:
        return db
    return nh * h + nq * q - ra


@njit(cache=True, nogil=True)
def tube_points(X, P, R, out):
    """Swept-tube distance of points ``X (N, 3)`` to the polyline ``P (m, 3)``, radii ``R (m,)``."""
    for i in range(X.shape[0]):
        best = 1e300
        for k in range(P.shape[0] - 1):
            d = _round_cone(X[i, 0], X[i, 1], X[i, 2], P[k, 0], P[k, 1], P[k, 2],
                            P[k + 1, 0], P[k + 1, 1], P[k + 1, 2], R[k], R[k + 1])
            if d < best:
                best = d
        out[i] = best
    return out


@njit(cache=True, nogil=True)
def tube_grid(xs, ys, zs, P, R, out):
    """Swept-tube distance on the tensor grid ``zs × ys × xs`` into ``out (nz, ny, nx)`` (float32)."""
    for kz in range(zs.shape[0]):
        for jy in range(ys.shape[0]):
            for ix in range(xs.shape[0]):
                best = 1e300
                for k in range(P.shape[0] - 1):
                    d = _round_cone(xs[ix], ys[jy], zs[kz], P[k, 0], P[k, 1], P[k, 2],
                                    P[k + 1, 0], P[k + 1, 1], P[k + 1, 2], R[k], R[k + 1])
                    if d < best:
                        best = d
                out[kz, jy, ix] = best
    return out


def tube_distance(points, polyline, radii) -> np.ndarray:
    """Signed swept-tube distance (module docstring) at ``points (N, 3)``."""
    X = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    P = np.ascontiguousarray(polyline, dtype=np.float64).reshape(-1, 3)
    R = np.ascontiguousarray(radii, dtype=np.float64).reshape(-1)
    if len(P) == 1:
        return np.linalg.norm(X - P[0], axis=1) - R[0]
    return tube_points(X, P, R, np.empty(len(X)))


def box_slices(axes, lo, hi):
    """Index slices ``(sx, sy, sz)`` of the grid samples inside the box, or None if empty."""
    out = []
    for a in range(3):
        ax = np.asarray(axes[a])
        i0 = int(np.searchsorted(ax, lo[a], side="left"))
        i1 = int(np.searchsorted(ax, hi[a], side="right"))
        if i1 <= i0:
            return None
        out.append(slice(i0, i1))
    return tuple(out)
