"""The sliced TBSS fit of an elongated body: sections along its long axis, lofted.

:func:`_slice_loops` cuts the closed mesh by a plane into closed loops;
:func:`fit_sliced` keeps the longest run of single star-shaped sections and
lofts them (:func:`porecad.splines.loft.loft_tbss`).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .loft import axis_frame, loft_tbss, polygon_frame, star_about
from .meshfit_grid import surface_distance, volume_centroid

__all__ = ["fit_sliced"]


def _slice_loops(v, f, axis, h):
    """Closed loops (lists of 3-D points) of the section ``x · axis = h`` of a closed mesh."""
    s = v @ axis - h
    ext = float(np.ptp(s))
    eps = 1e-9 * max(ext, 1.0)
    if np.any(np.abs(s) < eps):         # move the plane off vertices
        s = s - 2 * eps
    sf = s[f]
    pos = sf > 0
    npos = pos.sum(axis=1)
    tri = np.flatnonzero((npos == 1) | (npos == 2))
    if tri.size == 0:
        return []
    ft, st, pt = f[tri], sf[tri], pos[tri]
    keys, pts = [], []
    for e0, e1 in ((0, 1), (1, 2), (2, 0)):
        a, b = ft[:, e0], ft[:, e1]
        cross = pt[:, e0] != pt[:, e1]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        keys.append(np.where(cross, lo * len(v) + hi, -1))
        sa, sb = st[:, e0], st[:, e1]
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = np.where(cross, sa / (sa - sb), 0.0)
        pts.append(v[a] + tt[:, None] * (v[b] - v[a]))
    keys = np.stack(keys, axis=1)
    pts = np.stack(pts, axis=1)
    # the two crossing edges of every triangle
    order = np.argsort(keys < 0, axis=1, kind="stable")[:, :2]
    ka = np.take_along_axis(keys, order, axis=1)
    pa = np.take_along_axis(pts, order[:, :, None], axis=1)
    uk, inv = np.unique(ka.ravel(), return_inverse=True)
    inv = inv.reshape(-1, 2)
    node_pt = np.zeros((len(uk), 3))
    node_pt[inv[:, 0]] = pa[:, 0]
    node_pt[inv[:, 1]] = pa[:, 1]
    deg = np.bincount(inv.ravel(), minlength=len(uk))
    if np.any(deg != 2):
        raise InputError("the body mesh is not closed (a section has open ends)")
    # adjacency: two neighbours per node
    nb = np.full((len(uk), 2), -1, np.int64)
    fill = np.zeros(len(uk), np.int64)
    for a_, b_ in inv:
        nb[a_, fill[a_]] = b_
        fill[a_] += 1
        nb[b_, fill[b_]] = a_
        fill[b_] += 1
    seen = np.zeros(len(uk), bool)
    loops = []
    for start in range(len(uk)):
        if seen[start]:
            continue
        loop = [start]
        seen[start] = True
        prev, cur = -1, start
        while True:
            nxt = nb[cur, 0] if nb[cur, 0] != prev else nb[cur, 1]
            if nxt == start or seen[nxt]:
                break
            loop.append(nxt)
            seen[nxt] = True
            prev, cur = cur, nxt
        loops.append(node_pt[loop])
    return loops


def _star_about_centroid(loop, axis, e1, e2):
    xy, area, c = polygon_frame(loop, axis, e1, e2)
    return area != 0.0 and star_about(xy, c)


def fit_sliced(v, f, n_ctrl, degree, grid, levels=None):
    """The sliced fit of an elongated body ``(v, f)``: ``(tbss, diagnostics)``.

    Sections perpendicular to the principal (largest-variance) axis at
    ``max(4 grid, 8 n3)`` levels (or ``levels``); the longest run of levels
    whose section is one closed loop, star-shaped about its centroid, is kept
    (the ends are trimmed) and lofted (:func:`porecad.splines.loft.loft_tbss`)
    through ``grid`` of them.
    """
    vol_body, cen = volume_centroid(v, f)
    X = v - cen
    _, vec = np.linalg.eigh(X.T @ X)
    ax = vec[:, -1] * np.sign(vec[np.argmax(np.abs(vec[:, -1])), -1])   # largest component > 0
    ax, e1, e2 = axis_frame(ax)
    proj = v @ ax
    lo, hi = proj.min(), proj.max()
    nl = int(levels) if levels is not None else max(4 * grid, 8 * n_ctrl[2])
    hs = lo + (hi - lo) * (np.arange(nl) + 0.5) / nl
    good = np.zeros(nl, bool)
    loops = [None] * nl
    for k, h in enumerate(hs):
        ls = _slice_loops(v, f, ax, h)
        if len(ls) == 1 and len(ls[0]) >= 3 and _star_about_centroid(ls[0], ax, e1, e2):
            good[k] = True
            loops[k] = ls[0]
    # longest run of good levels
    best, bs, run, rs = 0, 0, 0, 0
    for k in range(nl):
        if good[k]:
            if run == 0:
                rs = k
            run += 1
            if run > best:
                best, bs = run, rs
        else:
            run = 0
    if best < max(n_ctrl[2], 4):
        raise InputError(f"only {best} consecutive sections along the body's long axis are single "
                         "star-shaped loops; cannot loft a TBSS (try the `fit` radial)")
    idx = np.unique(np.round(np.linspace(bs, bs + best - 1, min(best, max(grid, n_ctrl[2])))).astype(int))
    curves = [loops[k] for k in idx]
    tb = loft_tbss(curves, heights=hs[idx], n_ctrl=n_ctrl, degree=degree, axis=ax)
    info = tb.check_jacobian()
    rms, dmax = surface_distance(tb, v, f, faces=("u0", "u1", "v0", "v1"))
    return tb, {"method": "sliced", "axis": tuple(float(x) for x in ax),
                "levels": (float(hs[idx[0]]), float(hs[idx[-1]])), "sections": int(len(idx)),
                "length_fraction": float((hs[idx[-1]] - hs[idx[0]]) / (hi - lo)),
                "rms_distance": rms, "max_distance": dmax,
                "covered_fraction": tb.volume() / abs(vol_body),
                "min_det": info["min_det"], "mean_det": info["mean_det"]}
