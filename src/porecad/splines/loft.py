"""Lofting a TBSS through closed cross-section curves (sections of a body), in mm.

Sections are resampled onto the boundary of the unit square, filled by the
discrete Laplace equation (:func:`laplace_fill`, exact by the type-I sine
transform) and relaxed by Winslow smoothing, stacked along ``w`` and fitted
by least squares; the solid's edges are opened and its Jacobian checked as
in :mod:`porecad.splines.construct`.
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft
from numba import njit, prange

from ..errors import InputError
from .construct import finish_tbss, point3
from .lspia import fit_grid_lstsq
from .volume import as3

__all__ = ["axis_frame", "laplace_fill", "loft_tbss", "polygon_frame", "star_about"]


def laplace_fill(grid, ndim):
    """Fill the interior nodes of the first ``ndim`` (2 or 3) grid axes by discrete Laplace.

    The interior solves ``Σ_neighbours (x_nb - x) = 0`` with the boundary nodes
    fixed: the limit of Laplace (Jacobi) smoothing (001 §3.2). The Dirichlet
    grid Laplacian is diagonalised by the type-I discrete sine transform
    (eigenvalues ``Σ_a 2 - 2 cos(π k_a / (m_a + 1))``), so the solve is exact and
    ``O(N log N)``; trailing axes (sections, coordinates) are batched.
    """
    g = np.array(grid, dtype=np.float64, copy=True)
    shape = g.shape[:ndim]
    if min(shape) < 3:
        raise InputError(f"grid {shape} has no interior")
    inner = tuple(slice(1, -1) for _ in range(ndim))
    gb = g.copy()
    gb[inner] = 0.0
    rhs = np.zeros_like(g[inner])
    for a in range(ndim):
        lo = [slice(1, -1)] * ndim
        hi = [slice(1, -1)] * ndim
        lo[a] = slice(0, -2)
        hi[a] = slice(2, None)
        rhs += gb[tuple(lo)] + gb[tuple(hi)]
    lam = np.zeros([k - 2 for k in shape])
    for a in range(ndim):
        m = shape[a] - 2
        la = 2.0 - 2.0 * np.cos(np.pi * np.arange(1, m + 1) / (m + 1))
        sh = [1] * ndim
        sh[a] = m
        lam = lam + la.reshape(sh)
    lam = lam.reshape(lam.shape + (1,) * (g.ndim - ndim))
    axes = tuple(range(ndim))
    x = sfft.idstn(sfft.dstn(rhs, type=1, axes=axes, norm="ortho") / lam, type=1, axes=axes, norm="ortho")
    g[inner] = x
    return g


def polygon_frame(pts, axis, e1, e2):
    """2-D coordinates, signed area and area centroid of a closed polygon in the plane ⟂ axis."""
    xy = np.stack([pts @ e1, pts @ e2], axis=1)
    x, y = xy[:, 0], xy[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cr = x * y1 - x1 * y
    area = 0.5 * cr.sum()
    if abs(area) < 1e-300:
        return xy, 0.0, xy.mean(axis=0)
    cx = ((x + x1) * cr).sum() / (6 * area)
    cy = ((y + y1) * cr).sum() / (6 * area)
    return xy, float(area), np.array([cx, cy])


def _ray_polygon_start(xy, c):
    """Index and position of the farthest crossing of the ray ``c + t (1, 0)`` with the polygon."""
    x, y = xy[:, 0] - c[0], xy[:, 1] - c[1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = (y <= 0) & (y1 > 0) | (y > 0) & (y1 <= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(cross, -y / (y1 - y), 0.0)
    xs = x + f * (x1 - x)
    ok = cross & (xs > 0)
    if not ok.any():
        i = int(np.argmax(x))
        return i, 0.0
    cand = np.flatnonzero(ok)
    i = int(cand[np.argmax(xs[cand])])
    return i, float(f[i])


def _square_boundary(n):
    """Boundary nodes of an ``n × n`` grid counter-clockwise from the corner ``(n-1, 0)``,
    with their side (0: u = 1, 1: v = 1, 2: u = 0, 3: v = 0) and position on it in ``[0, 1)``."""
    m = n - 1
    nodes = ([(m, j) for j in range(m)] + [(m - i, m) for i in range(m)]
             + [(0, m - j) for j in range(m)] + [(i, 0) for i in range(m)])
    k = np.arange(4 * m)
    return np.array(nodes), k // m, (k % m) / m


def _turning(xy, s, frac, delta):
    """Signed turning angle (left > 0) of a closed 2-D polyline between the chords
    ``P(f - δ) -> P(f)`` and ``P(f) -> P(f + δ)`` at arc-length fractions ``frac``."""
    closed = np.vstack([xy, xy[:1]])

    def at(f):
        t = np.mod(f, 1.0)
        return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)

    a, b, c = at(frac - delta), at(frac), at(frac + delta)
    d1, d2 = b - a, c - b
    return np.arctan2(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0], (d1 * d2).sum(axis=1))


def _corner_fractions(xy, window=0.07, delta=0.02, penalty=4.0):
    """Arc-length fractions of the 4 square corners on a counter-clockwise closed curve
    starting at fraction 0: near the nominal ``-1/8, 1/8, 3/8, 5/8`` (equal sides), moved
    within ``± window`` to where the curve turns left (convex) most over ``± delta``,
    less ``penalty`` rad per unit of fraction moved. A corner of the square on a
    straight or concave stretch would make the map singular or folded there."""
    seg = np.linalg.norm(np.diff(np.vstack([xy, xy[:1]]), axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()
    cand = np.linspace(-window, window, 57)
    out = []
    for nom in (-0.125, 0.125, 0.375, 0.625):
        score = _turning(xy, s, nom + cand, delta) - penalty * np.abs(cand)
        out.append(nom + cand[int(np.argmax(score))])
    return np.array(out)


def _resample_closed(pts, fractions):
    """Points at arc-length fractions (0 = first point) of a closed polyline."""
    seg = np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    L = s[-1]
    if L <= 0:
        raise InputError("a section curve has zero length")
    closed = np.vstack([pts, pts[:1]])
    t = np.mod(fractions, 1.0) * L
    return np.stack([np.interp(t, s, closed[:, k]) for k in range(pts.shape[1])], axis=1)


def _star_radius(xy, c, theta):
    """Distance from ``c`` to a polygon star-shaped about ``c`` (counter-clockwise) along angles.

    The exact intersection of the ray ``c + r (cos θ, sin θ)`` with the polygon
    edge spanning ``θ`` in angle.
    """
    d = xy - c
    ang = np.arctan2(d[:, 1], d[:, 0])
    i0 = int(np.argmin(ang))
    d = np.roll(d, -i0, axis=0)
    ang = np.unwrap(np.roll(ang, -i0))                 # increasing from the smallest angle
    ang_c = np.concatenate([ang, [ang[0] + 2 * np.pi]])
    dc = np.vstack([d, d[:1]])
    t = np.mod(theta - ang[0], 2 * np.pi) + ang[0]
    k = np.clip(np.searchsorted(ang_c, t, side="right") - 1, 0, len(d) - 1)
    a, e = dc[k], dc[k + 1] - dc[k]
    ux, uy = np.cos(t), np.sin(t)
    den = ux * e[:, 1] - uy * e[:, 0]
    num = a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(np.abs(den) > 0, num / den, np.hypot(a[:, 0], a[:, 1]))
    return r


def star_about(xy, c):
    """Whether a closed polygon (2-D) is star-shaped about ``c``: the angle about
    ``c`` increases (or decreases) monotonically once around."""
    ang = np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0])
    d = np.diff(np.concatenate([ang, ang[:1]]))
    d = (d + np.pi) % (2 * np.pi) - np.pi
    if d.sum() < 0:
        d = -d
    return bool(np.all(d > 0) and abs(d.sum() - 2 * np.pi) < 1e-6)


@njit(cache=True, parallel=True)
def _winslow(xy, iters, tol, omega):
    """Winslow smoothing of 2-D section grids ``(n1, n2, K, 2)`` (boundary fixed), in place.

    Gauss-Seidel/SOR sweeps of the inverse-Laplace (Winslow 1967) equations
    ``α x_uu - 2β x_uv + γ x_vv = 0``, ``α = |x_v|²``, ``β = x_u·x_v``,
    ``γ = |x_u|²``: the grid lines are the level sets of functions harmonic on
    the *physical* section, which stay unfolded on non-convex sections where
    a direct Laplace fill folds (Thompson, Warsi & Mastin, *Numerical Grid
    Generation*, 1985, §6). Stops when no node moves more than ``tol``.
    """
    n1, n2, K = xy.shape[0], xy.shape[1], xy.shape[2]
    sweeps = np.zeros(K, np.int64)
    for k in prange(K):
        for it in range(iters):
            mx = 0.0
            for i in range(1, n1 - 1):
                for j in range(1, n2 - 1):
                    xu0 = 0.5 * (xy[i + 1, j, k, 0] - xy[i - 1, j, k, 0])
                    xu1 = 0.5 * (xy[i + 1, j, k, 1] - xy[i - 1, j, k, 1])
                    xv0 = 0.5 * (xy[i, j + 1, k, 0] - xy[i, j - 1, k, 0])
                    xv1 = 0.5 * (xy[i, j + 1, k, 1] - xy[i, j - 1, k, 1])
                    a = xv0 * xv0 + xv1 * xv1
                    g = xu0 * xu0 + xu1 * xu1
                    b = xu0 * xv0 + xu1 * xv1
                    den = 2.0 * (a + g)
                    if den <= 0.0:
                        continue
                    for e in range(2):
                        cr = (xy[i + 1, j + 1, k, e] - xy[i + 1, j - 1, k, e]
                              - xy[i - 1, j + 1, k, e] + xy[i - 1, j - 1, k, e])
                        new = (a * (xy[i + 1, j, k, e] + xy[i - 1, j, k, e])
                               + g * (xy[i, j + 1, k, e] + xy[i, j - 1, k, e]) - 0.5 * b * cr) / den
                        d = omega * (new - xy[i, j, k, e])
                        xy[i, j, k, e] += d
                        if abs(d) > mx:
                            mx = abs(d)
            sweeps[k] = it + 1
            if mx < tol:
                break
    return sweeps


def _section_grids(curves, axis, e1, e2, n, fill="winslow"):
    """Section grids ``(n, n, K, 3)``: boundary by arc length, interior by Laplace.

    Every curve is oriented counter-clockwise about ``axis``, started where the
    ray from its area centroid along ``e1`` leaves it, split into 4 sides at
    convex points near equal arc lengths (:func:`_corner_fractions`) and each
    side resampled by arc length onto a side of the square's boundary nodes.

    Interior: ``fill="laplace"`` fills the physical coordinates by discrete
    Laplace (may fold on non-convex sections); ``fill="star"`` normalises the
    boundary points to the unit circle by their angle about the centroid,
    fills the grid by discrete Laplace there (a convex boundary: the
    barycentric map is an embedding, Tutte 1963) and maps it back by the star
    map ``c + ρ R(θ) (cos θ, sin θ)`` (sections star-shaped about their
    centroid only); ``fill="winslow"`` starts from "star" (or "laplace" for a
    section that is not star-shaped) and relaxes the grid by Winslow
    smoothing (:func:`_winslow`). The axial coordinate is filled by Laplace.
    """
    nodes, side, tpos = _square_boundary(n)
    K = len(curves)
    bxy = np.zeros((n, n, K, 2))
    bz = np.zeros((n, n, K, 1))
    polys, cents = [], []
    for k, pts in enumerate(curves):
        xy, area, c2 = polygon_frame(pts, axis, e1, e2)
        if area == 0.0:
            raise InputError(f"section {k} encloses no area")
        if area < 0:
            pts, xy = pts[::-1].copy(), xy[::-1].copy()
        i, f = _ray_polygon_start(xy, c2)
        j = (i + 1) % len(pts)
        start = pts[i] + f * (pts[j] - pts[i])
        ring = np.vstack([start[None, :], np.roll(pts, -(i + 1), axis=0)])
        if np.linalg.norm(ring[1] - ring[0]) == 0.0:
            ring = ring[1:]
        if np.linalg.norm(ring[-1] - ring[0]) == 0.0:
            ring = ring[:-1]
        rxy = np.stack([ring @ e1, ring @ e2], axis=1)
        cf = np.append(_corner_fractions(rxy), 0)
        cf[4] = cf[0] + 1.0
        b = _resample_closed(ring, cf[side] + (cf[side + 1] - cf[side]) * tpos)
        bxy[nodes[:, 0], nodes[:, 1], k] = np.stack([b @ e1, b @ e2], axis=1)
        bz[nodes[:, 0], nodes[:, 1], k, 0] = b @ axis
        polys.append(xy)
        cents.append(c2)
    if fill not in ("winslow", "star", "laplace"):
        raise InputError(f"unknown section fill {fill!r}; use 'winslow', 'star' or 'laplace'")
    z = laplace_fill(bz, 2)[..., 0]
    star = np.array([star_about(p, c) for p, c in zip(polys, cents)])
    if fill == "star" and not star.all():
        k = int(np.flatnonzero(~star)[0])
        raise InputError(f"section {k} is not star-shaped about its centroid; use fill='laplace'")
    xy = laplace_fill(bxy, 2)
    if fill != "laplace" and star.any():
        cents = np.array(cents)
        d = bxy - cents[None, None, :, :]
        rad = np.linalg.norm(d, axis=-1, keepdims=True)
        unit = np.where(rad > 0, d / np.where(rad > 0, rad, 1.0), 0.0)
        y = laplace_fill(unit, 2)
        rho = np.linalg.norm(y, axis=-1)
        th = np.arctan2(y[..., 1], y[..., 0])
        bmask = np.zeros((n, n), bool)
        bmask[nodes[:, 0], nodes[:, 1]] = True
        for k in np.flatnonzero(star):
            R = _star_radius(polys[k], cents[k], th[:, :, k].ravel()).reshape(n, n)
            sec = np.stack([cents[k][0] + rho[:, :, k] * R * np.cos(th[:, :, k]),
                            cents[k][1] + rho[:, :, k] * R * np.sin(th[:, :, k])], axis=-1)
            sec[bmask] = bxy[:, :, k][bmask]          # boundary exactly the arc-length samples
            xy[:, :, k] = sec
    if fill == "winslow":
        ext = float(np.ptp(bxy.reshape(-1, 2), axis=0).max())
        xy = np.ascontiguousarray(xy)
        _winslow(xy, 4000, 1e-7 * ext, 1.5)
    return (xy[..., 0:1] * e1 + xy[..., 1:2] * e2 + z[..., None] * axis), fill


def _clean_curves(curves):
    if len(curves) < 2:
        raise InputError(f"lofting needs at least 2 section curves, got {len(curves)}")
    out = []
    for k, c in enumerate(curves):
        a = np.asarray(c, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3:
            raise InputError(f"section curve {k} must be a (k, 3) array, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise InputError(f"section curve {k} has non-finite points")
        if len(a) > 1 and np.array_equal(a[0], a[-1]):
            a = a[:-1]
        keep = np.concatenate([[True], np.any(np.diff(a, axis=0) != 0, axis=1)])
        a = a[keep]
        if len(a) < 3:
            raise InputError(f"section curve {k} needs at least 3 distinct points")
        out.append(a)
    return out


def _newell(pts):
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    x1, y1, z1 = np.roll(x, -1), np.roll(y, -1), np.roll(z, -1)
    return np.array([((y - y1) * (z + z1)).sum(), ((z - z1) * (x + x1)).sum(), ((x - x1) * (y + y1)).sum()])


def axis_frame(axis):
    axis = axis / np.linalg.norm(axis)
    ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - np.dot(ref, axis) * axis
    e1 /= np.linalg.norm(e1)
    return axis, e1, np.cross(axis, e1)


def loft_tbss(curves, heights=None, n_ctrl=(8, 8, 8), degree=3, grid=None, axis=None, fill="winslow"):
    """Loft a TBSS through closed cross-section curves stacked along ``w``.

    Each curve (a ``(k_i, 3)`` closed polyline, e.g. a planar slice of a
    body) is oriented counter-clockwise about the loft axis and started where
    the ray from its area centroid along a common reference direction ``e1``
    (perpendicular to the axis) leaves it; it is split into 4 sides near equal
    arc lengths, the corners moved to nearby convex points, and each side
    resampled by arc length onto one side of the unit square ``(u, v)``
    (``u ~ e1``, ``v ~ e2 = axis × e1``, the start point in the middle of the
    side ``u = 1``). The section interior is filled by discrete Laplace
    smoothing with the boundary fixed, then relaxed by Winslow
    (inverse-Laplace) smoothing (see ``fill``); the sections are stacked along
    ``w`` at ``heights`` (normalised to ``[0, 1]``), the control points fitted
    by least squares, degenerate corner columns opened (:func:`open_edges`)
    and the Jacobian checked.

    Parameters
    ----------
    curves : list of (k_i, 3) arrays
        At least ``n_ctrl[2]`` sections, ordered along the loft axis.
    heights : (K,) array or None
        Positions of the sections along the axis (strictly increasing);
        default the projections of their centroids on the axis.
    n_ctrl : 3 ints
    degree : int or 3 ints
    grid : int or None
        Section grid resolution (default ``max(4 max(n1, n2), 24)``).
    axis : 3 floats or None
        Loft direction; default the mean section normal (Newell), pointing
        from the first to the last section.
    fill : {"winslow", "star", "laplace"}
        Section interiors (see :func:`_section_grids`): "laplace" fills the
        physical coordinates by discrete Laplace (a strongly non-convex
        section may fold and is then refused); "star" Laplace-fills the
        section normalised to the unit disc by the angle about its centroid
        and maps back radially (star-shaped sections only); "winslow"
        (default) relaxes either start by Winslow smoothing, which stays
        unfolded on non-convex sections.
    """
    cs = _clean_curves(curves)
    n = as3(n_ctrl, "n_ctrl")
    K = len(cs)
    if K < n[2]:
        raise InputError(f"{K} sections cannot determine {n[2]} control points along w")
    cents = np.array([c.mean(axis=0) for c in cs])
    if axis is None:
        normals = [_newell(c) for c in cs]
        ref = normals[0]
        ax = np.zeros(3)
        for nv in normals:
            ax += nv if np.dot(nv, ref) >= 0 else -nv
        if np.linalg.norm(ax) == 0:
            ax = cents[-1] - cents[0]
    else:
        ax = point3(axis, "loft axis")
    if np.linalg.norm(ax) == 0:
        raise InputError("cannot determine the loft axis")
    if np.dot(ax, cents[-1] - cents[0]) < 0:
        ax = -ax
    ax, e1, e2 = axis_frame(ax)
    h = cents @ ax if heights is None else np.asarray(heights, dtype=np.float64).ravel()
    if h.size != K or not np.all(np.isfinite(h)):
        raise InputError(f"need {K} finite section heights, got {h.size}")
    if np.any(np.diff(h) <= 0):
        raise InputError("section heights must be strictly increasing along the loft axis")
    g = int(grid) if grid is not None else max(4 * max(n[0], n[1]), 24)
    if g < max(n[0], n[1]) or g < 3:
        raise InputError(f"section grid {g} is too coarse for {n[0]} × {n[1]} control points")
    filled, _ = _section_grids(cs, ax, e1, e2, g, fill)
    wpar = (h - h[0]) / (h[-1] - h[0])
    s = np.linspace(0.0, 1.0, g)
    vol = fit_grid_lstsq(filled, n, degree, params=(s, s, wpar))
    return finish_tbss(vol.control, vol.degrees, vol.knots)[0]
