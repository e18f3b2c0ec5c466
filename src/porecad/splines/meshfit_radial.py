"""The radial TBSS fit of a star-shaped body: rays from a centre through a cube's boundary nodes.

Ray-triangle crossings by Möller & Trumbore (1997), counted per ray
(:func:`star_shaped`: every ray crosses the surface once), and the fit
through the rays' surface points (:func:`fit_radial`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..errors import InputError
from .construct import point3
from .loft import laplace_fill
from .meshfit_grid import check_folds, fit_report, fitted_tbss, mesh_arrays, volume_centroid

__all__ = ["fit_radial", "star_shaped"]


@njit(cache=True, parallel=True)
def _ray_hits(v0, e1, e2, origin, dirs, tol, counts, tfirst):
    """Distinct crossings ``t > 0`` of rays ``origin + t dir`` with triangles (Möller-Trumbore).

    Hits closer than ``tol`` along a ray (one crossing through a shared edge or
    vertex) count once; ``tfirst`` is the nearest crossing.
    """
    R = dirs.shape[0]
    F = v0.shape[0]
    for i in prange(R):
        buf = np.empty(256)
        cnt = 0
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        for f in range(F):
            ax, ay, az = e1[f, 0], e1[f, 1], e1[f, 2]
            bx, by, bz = e2[f, 0], e2[f, 1], e2[f, 2]
            px = dy * bz - dz * by
            py = dz * bx - dx * bz
            pz = dx * by - dy * bx
            det = ax * px + ay * py + az * pz
            if det == 0.0:
                continue
            inv = 1.0 / det
            tx = origin[0] - v0[f, 0]
            ty = origin[1] - v0[f, 1]
            tz = origin[2] - v0[f, 2]
            uu = (tx * px + ty * py + tz * pz) * inv
            if uu < -1e-12 or uu > 1.0 + 1e-12:
                continue
            qx = ty * az - tz * ay
            qy = tz * ax - tx * az
            qz = tx * ay - ty * ax
            vv = (dx * qx + dy * qy + dz * qz) * inv
            if vv < -1e-12 or uu + vv > 1.0 + 1e-12:
                continue
            t = (bx * qx + by * qy + bz * qz) * inv
            if t <= tol:
                continue
            if cnt < 256:
                buf[cnt] = t
                cnt += 1
        if cnt == 0:
            counts[i] = 0
            tfirst[i] = 0.0
            continue
        s = np.sort(buf[:cnt])
        k = 1
        for j in range(1, cnt):
            if s[j] - s[j - 1] > tol:
                k += 1
        counts[i] = k
        tfirst[i] = s[0]


def _radial_boundary(v, f, centre, dirs):
    """Distances from ``centre`` to the surface along unit ``dirs``; star-shapedness checked."""
    v0 = np.ascontiguousarray(v[f[:, 0]])
    e1 = np.ascontiguousarray(v[f[:, 1]] - v0)
    e2 = np.ascontiguousarray(v[f[:, 2]] - v0)
    ext = float(np.ptp(v, axis=0).max())
    counts = np.empty(len(dirs), np.int64)
    tf = np.empty(len(dirs))
    _ray_hits(v0, e1, e2, centre, np.ascontiguousarray(dirs), 1e-9 * ext, counts, tf)
    bad = np.flatnonzero(counts != 1)
    if bad.size:
        c = centre
        if np.all(counts % 2 == 0):
            raise InputError(f"centre ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}) lies outside the body")
        i = int(bad[0])
        d = dirs[i]
        raise InputError(
            f"body is not star-shaped about centre ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}): the ray "
            f"toward ({d[0]:.3g}, {d[1]:.3g}, {d[2]:.3g}) crosses the surface {int(counts[i])} "
            "times; try the `fit` sliced")
    return tf


def _cube_boundary_dirs(n):
    s = np.linspace(-1.0, 1.0, n)
    Q = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1)
    bmask = np.zeros((n, n, n), bool)
    bmask[[0, -1], :, :] = True
    bmask[:, [0, -1], :] = True
    bmask[:, :, [0, -1]] = True
    q = Q[bmask]
    return bmask, q / np.linalg.norm(q, axis=1)[:, None]


def star_shaped(vertices, faces, centre=None, rays: int = 12) -> bool:
    """Whether every ray from ``centre`` (default: the volume centroid) toward the boundary nodes of a
    ``rays³`` cube grid crosses the surface once (the radial fit's condition)."""
    v, f = mesh_arrays(vertices, faces)
    _, cen = volume_centroid(v, f)
    c = cen if centre is None else point3(centre, "centre")
    try:
        _radial_boundary(v, f, c, _cube_boundary_dirs(int(rays))[1])
    except InputError:
        return False
    return True


def fit_radial(v, f, n_ctrl, degree, centre, grid, untangle=None, inflate=0.0, fold_limit=None):
    """The radial fit of the body ``(v, f)`` (star-shaped about ``centre``): ``(tbss, diagnostics)``.

    The boundary nodes ``q`` of a ``grid³`` grid on ``[-1, 1]^3`` go to the
    surface point on the ray from ``centre`` (default: the volume centroid)
    toward ``q/|q|`` (ray-triangle intersection, Möller & Trumbore 1997;
    every ray must cross the surface exactly once), pushed ``inflate`` (mm)
    further along the ray (so a star-shaped body stays star-shaped); the
    interior nodes by discrete Laplace smoothing with the boundary fixed, the
    control points by least squares (:func:`fitted_tbss`, after
    :func:`check_folds` where ``fold_limit`` is given).
    """
    vol_body, cen = volume_centroid(v, f)
    c = cen if centre is None else point3(centre, "centre")
    bmask, dirs = _cube_boundary_dirs(grid)
    t = _radial_boundary(v, f, c, dirs)
    G = np.zeros((grid, grid, grid, 3))
    G[bmask] = c + (t + inflate)[:, None] * dirs
    G = laplace_fill(G, 3)
    s = np.linspace(0.0, 1.0, grid)
    if fold_limit is not None:
        check_folds(G, (s, s, s), n_ctrl, degree, "radial", fold_limit)
    tb, fit = fitted_tbss(G, (s, s, s), n_ctrl, degree, untangle)
    return tb, fit_report(tb, v, f, vol_body, {"method": "radial", "centre": tuple(float(x) for x in c), **fit})
