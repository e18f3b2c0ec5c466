"""Construction of trivariate B-spline solids (TBSS), in mm.

Every constructor samples a map ``[0,1]^3 -> R^3`` on a parametric grid,
fits the control points by least squares (:func:`~porecad.splines.lspia.fit_grid_lstsq`),
makes the fitted solid's edges slightly convex where needed (below) and
verifies ``det J > 0`` with :meth:`~porecad.splines.volume.TBSS.check_jacobian`.

Edges and corners. A smooth map of the cube whose boundary faces go onto a
*smooth* surface has ``det J = 0`` along the cube edges that land on it: the
three partial derivatives there are all tangent to the surface (in 2-D: any
smooth map of a square onto a round disc is singular at the 4 corners). A
fitted spline then has ``det J ≈ 0`` of either sign there. :func:`open_edges`
moves each control point lying on two or three boundary faces, minimally,
until the control-net determinant ``det[D_u, D_v, D_w] ≥ η |D_u||D_v||D_w|``
(``D`` the control-net differences at that point), which puts a slight
convex crease (dihedral angle about ``180° - asin(η)``) along those edges;
η starts at 0.05 and is raised to 0.1, 0.2, 0.4 while the Jacobian check
fails. Edges that already have a real crease (a box, the end caps of a
loft) are left unchanged.

Parametric frames are right-handed (``u`` ~ x, ``v`` ~ y, ``w`` ~ z), so
``det J > 0``.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft
from numba import njit, prange

from ..errors import InputError
from .lspia import fit_grid_lstsq
from .volume import TBSS, _as3

__all__ = ["box_tbss", "fit_map", "cylinder_tbss", "tube_tbss", "disc_map", "disc_tbss", "loft_tbss",
           "fit_tbss_to_mesh", "open_edges", "elliptic_square_to_disc"]

_ETAS = (0.05, 0.1, 0.2, 0.4)


# ---------------------------------------------------------------- common
def _positive3(x, name):
    v = np.asarray(x, dtype=np.float64).ravel()
    if v.size != 3 or not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise InputError(f"{name} must be 3 positive numbers, got {x}")
    return v


def _positive(x, name):
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {x!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be positive, got {x}")
    return v


def _point3(x, name):
    v = np.asarray(x, dtype=np.float64).ravel()
    if v.size != 3 or not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be 3 finite numbers, got {x}")
    return v


def open_edges(control, periodic=(False, False, False), eta: float = 0.05, iterations: int = 4):
    """Make the control net convex enough along its boundary edges and corners.

    For every control point ``C`` on two or three (non-periodic) boundary faces
    the control-net differences ``D_a`` (one-sided ``P_{i+1} - P_i`` at index 0,
    ``P_i - P_{i-1}`` at the last index, central elsewhere) give
    ``f(C) = det[D_u, D_v, D_w]``, which is affine in ``C``; if
    ``f < η |D_u||D_v||D_w|``, ``C`` moves along ``∇f`` by the least distance that
    reaches the bound (repeated ``iterations`` times as the lengths change).

    Returns a new ``(n1, n2, n3, 3)`` array; points already satisfying the bound
    keep their exact values.
    """
    P = np.array(control, dtype=np.float64, copy=True)
    n = P.shape[:3]
    per = _as3(periodic, "periodic", bool)
    idx = np.indices(n).reshape(3, -1).T
    onb = np.zeros(len(idx), np.int64)
    for a in range(3):
        if not per[a]:
            onb += (idx[:, a] == 0) | (idx[:, a] == n[a] - 1)
    cand = idx[onb >= 2]
    for _ in range(iterations):
        changed = False
        for c in cand:
            D, S = [], []
            for a in range(3):
                i = c[a]
                lo, hi = list(c), list(c)
                if per[a] and (i == 0 or i == n[a] - 1):
                    lo[a] = n[a] - 2 if i == 0 else i - 1
                    hi[a] = 1 if i == n[a] - 1 else i + 1
                    D.append(0.5 * (P[tuple(hi)] - P[tuple(lo)]))
                    S.append(0.0)
                elif i == 0:
                    hi[a] = 1
                    D.append(P[tuple(hi)] - P[tuple(c)])
                    S.append(-1.0)
                elif i == n[a] - 1:
                    lo[a] = i - 1
                    D.append(P[tuple(c)] - P[tuple(lo)])
                    S.append(1.0)
                else:
                    lo[a], hi[a] = i - 1, i + 1
                    D.append(0.5 * (P[tuple(hi)] - P[tuple(lo)]))
                    S.append(0.0)
            f = float(np.dot(D[0], np.cross(D[1], D[2])))
            tau = eta * float(np.prod([np.linalg.norm(d) for d in D]))
            if f >= tau:
                continue
            g = (S[0] * np.cross(D[1], D[2]) + S[1] * np.cross(D[2], D[0])
                 + S[2] * np.cross(D[0], D[1]))
            if all(S):
                g = _in_face(P, c, D, g)
            gg = float(np.dot(g, g))
            if gg == 0.0:
                continue
            P[tuple(c)] += (tau - f) / gg * g
            changed = True
        if not changed:
            break
    return P


def _in_face(P, c, D, g):
    """At a corner of the net, restrict the move ``g`` to the face across the most
    degenerate pair of directions (e.g. keep a cylinder's flat end flat).

    The pair ``(a, b)`` with the smallest ``|D_a × D_b| / (|D_a| |D_b|)`` spans the
    degenerate face ``c``; its normal comes from the diagonals of the face's
    corner quad (well conditioned even when ``D_a ∥ D_b``). Falls back to ``g``
    when the projection would leave less than 10 % of it.
    """
    sines = []
    for a, b in ((0, 1), (1, 2), (0, 2)):
        den = np.linalg.norm(D[a]) * np.linalg.norm(D[b])
        sines.append(np.linalg.norm(np.cross(D[a], D[b])) / den if den > 0 else 0.0)
    a, b = ((0, 1), (1, 2), (0, 2))[int(np.argmin(sines))]
    n = P.shape[:3]
    ia = list(c)
    ib = list(c)
    iab = list(c)
    ia[a] = 1 if c[a] == 0 else c[a] - 1
    ib[b] = 1 if c[b] == 0 else c[b] - 1
    iab[a], iab[b] = ia[a], ib[b]
    if min(n[a], n[b]) < 2:
        return g
    d1 = P[tuple(iab)] - P[tuple(c)]
    d2 = P[tuple(ia)] - P[tuple(ib)]
    nrm = np.cross(d1, d2)
    ln = np.linalg.norm(nrm)
    if ln == 0.0:
        return g
    nrm /= ln
    gp = g - np.dot(g, nrm) * nrm
    return gp if np.linalg.norm(gp) >= 0.1 * np.linalg.norm(g) else g


def _finish(control, degrees, knots, periodic=(False, False, False), samples=None):
    """Open the edges (increasing η until the solid passes) and check the Jacobian."""
    err = None
    for eta in _ETAS:
        P = open_edges(control, periodic, eta)
        per = _as3(periodic, "periodic", bool)
        for a in range(3):          # keep a periodic seam exact
            if per[a]:
                sl0 = [slice(None)] * 3
                sl1 = [slice(None)] * 3
                sl0[a], sl1[a] = 0, -1
                P[tuple(sl1)] = P[tuple(sl0)]
        tb = TBSS(P, degrees, knots, periodic=periodic)
        try:
            info = tb.check_jacobian(samples)
        except InputError as e:
            err = e
            continue
        return tb, info
    raise err


def _sample_grid(func, samples):
    s = [np.linspace(0.0, 1.0, k) for k in samples]
    U, V, W = np.meshgrid(*s, indexing="ij")
    out = func(U, V, W)
    if isinstance(out, (tuple, list)):
        if len(out) != 3:
            raise InputError(f"the map must return 3 coordinates, got {len(out)}")
        out = np.stack([np.broadcast_to(np.asarray(o, dtype=np.float64), U.shape) for o in out], axis=-1)
    out = np.asarray(out, dtype=np.float64)
    if out.shape != U.shape + (3,):
        raise InputError(f"the map must return (x, y, z) of the parameter grid's shape, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise InputError("the map returned non-finite points")
    return out, s


def fit_map(func, n_ctrl, degree=3, samples=None, periodic=(False, False, False)):
    """Least-squares TBSS fit of an analytic map ``func(u, v, w) -> (x, y, z)`` on ``[0,1]^3``.

    ``func`` is called once with three equal-shape arrays (a grid of
    ``samples`` uniform parameters per axis, default ``max(6 n_i, 16)``) and
    returns ``(x, y, z)`` arrays or one ``(..., 3)`` array. The control points
    minimise the squared distance to the samples
    (:func:`~porecad.splines.lspia.fit_grid_lstsq`), degenerate edges are opened
    (:func:`open_edges`), periodic seams made exact (first and last control
    slabs set equal) and the Jacobian is checked.

    Raises
    ------
    InputError
        If the fitted solid folds (see :meth:`TBSS.check_jacobian`).
    """
    n = _as3(n_ctrl, "n_ctrl")
    p = _as3(degree, "degree")
    if samples is None:
        samples = tuple(max(6 * k, 16) for k in n)
    samples = _as3(samples, "samples")
    Q, s = _sample_grid(func, samples)
    vol = fit_grid_lstsq(Q, n, p, params=s)
    per = _as3(periodic, "periodic", bool)
    P = vol.control.copy()
    for a in range(3):
        if per[a]:
            first = np.take(P, 0, axis=a)
            last = np.take(P, -1, axis=a)
            mean = 0.5 * (first + last)
            sl0 = [slice(None)] * 3
            sl1 = [slice(None)] * 3
            sl0[a], sl1[a] = 0, -1
            P[tuple(sl0)] = mean
            P[tuple(sl1)] = mean
    return _finish(P, p, vol.knots, per)[0]


# ---------------------------------------------------------------- primitives
def box_tbss(size=(10.0, 10.0, 10.0), origin=(0.0, 0.0, 0.0), n_ctrl=(4, 4, 4), degree=3):
    """Box ``origin + [0, a] × [0, b] × [0, c]`` (mm) as a TBSS: ``x = origin + size * (u, v, w)``.

    Control points at the Greville abscissae (``P_ijk = origin + size * (g_i, g_j, g_k)``)
    reproduce the linear map exactly (linear precision, P&T §2.2 / eq. 9.49);
    ``det J = a b c`` everywhere.
    """
    from .basis import greville
    from .knots import clamped_uniform_knots

    size = _positive3(size, "box size")
    origin = _point3(origin, "box origin")
    n = _as3(n_ctrl, "n_ctrl")
    p = _as3(degree, "degree")
    if min(p) < 1:
        raise InputError("a box needs degree >= 1 in every direction")
    knots = [clamped_uniform_knots(n[a], p[a]) for a in range(3)]
    g = [greville(knots[a], p[a]) for a in range(3)]
    G = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1)
    tb = TBSS(origin + size * G, p, knots)
    tb.check_jacobian()
    return tb


def elliptic_square_to_disc(a, b):
    """Elliptical grid map of the square ``[-1,1]^2`` onto the unit disc (Fong 2015).

    ``x = a sqrt(1 - b²/2)``, ``y = b sqrt(1 - a²/2)``: analytic, the square's
    sides go onto the 4 quarter circles, ``det J > 0`` except at the 4 corners
    (where it is 0). (C. Fong, "Analytical methods for squaring the disc", 2015.)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return a * np.sqrt(1.0 - 0.5 * b * b), b * np.sqrt(1.0 - 0.5 * a * a)


def cylinder_tbss(radius=10.0, height=20.0, center=(0.0, 0.0, 0.0), n_ctrl=(8, 8, 4), degree=3):
    """Circular cylinder as one TBSS patch: the square ``(u, v)`` section onto the disc.

    The section map is the elliptical grid map (:func:`elliptic_square_to_disc`),
    scaled by ``radius``; ``z = center_z + height w``; ``center`` is the centre
    of the bottom face. The map is singular at the 4 section corners, so the
    fitted solid has 4 slight vertical creases there (:func:`open_edges`).
    Roundness with the default 8 × 8 section control points: boundary radius
    within ``[0.9999 R, 1.003 R]`` (``min det J / mean det J ≈ 0.06``); the volume
    is within 0.1 % of ``π R² h``. More control points reduce the deviation.
    """
    R = _positive(radius, "cylinder radius")
    H = _positive(height, "cylinder height")
    c = _point3(center, "cylinder center")

    def f(u, v, w):
        x, y = elliptic_square_to_disc(2 * u - 1, 2 * v - 1)
        return c[0] + R * x, c[1] + R * y, c[2] + H * w

    return fit_map(f, n_ctrl, degree)


def tube_tbss(r_inner=5.0, r_outer=10.0, height=20.0, center=(0.0, 0.0, 0.0), n_ctrl=(16, 4, 4),
              degree=3):
    """Thick-walled tube: ``u`` angle, ``v`` radius, ``w`` height, ``periodic=(True, False, False)``.

    ``x = center + (r cos 2πu, -r sin 2πu, height w)`` with
    ``r = r_inner + (r_outer - r_inner) v`` (the angle runs clockwise seen
    from +z, which makes ``(u, v, w)`` right-handed); fitted by least squares, then the
    control slabs ``u = 0`` and ``u = 1`` are set equal so the seam matches
    exactly (scaffold code welds that face pair). With 16 control points
    around, the radii are within about 1e-4 relative of the circle (the
    non-rational cubic approximates it); ``det J = 2π r (r_out - r_in) h > 0``.
    """
    ri = _positive(r_inner, "inner radius")
    ro = _positive(r_outer, "outer radius")
    H = _positive(height, "tube height")
    if ro <= ri:
        raise InputError(f"outer radius {ro:g} must exceed inner radius {ri:g}")
    c = _point3(center, "tube center")
    n = _as3(n_ctrl, "n_ctrl")
    if n[0] < 8:
        raise InputError(f"a tube needs at least 8 control points around, got {n[0]}")

    def f(u, v, w):
        r = ri + (ro - ri) * v
        t = 2 * np.pi * u
        return c[0] + r * np.cos(t), c[1] - r * np.sin(t), c[2] + H * w

    return fit_map(f, n, degree, periodic=(True, False, False))


def disc_map(width=50.0, depth=35.0, height=11.0, wedge_deg=8.0, dome=1.0, indent=0.3):
    """The analytic lumbar-disc map ``(u, v, w) -> (x, y, z)`` fitted by :func:`disc_tbss`.

    Section: the unit disc (from the square by :func:`elliptic_square_to_disc`,
    ``(x, y) = s``) deformed by ``(x, y) -> (x, y + indent e^{-x²/0.3} ((1 - y)/2)²)``,
    which pushes the posterior side (``y < 0``) in near the midline (a
    kidney/bean section with a posterior concavity; ``∂y'/∂y = 1 - indent ·
    e^{..}(1-y)/2 > 0`` for ``indent < 1``), then scaled and centred so its
    bounding box is ``width`` (x, lateral) × ``depth`` (y, anterior +).
    Heights: ``z_top = h/2 - dome |s|² + tan(wedge/2) y``, ``z_bot = -z_top``,
    ``z = z_bot + w (z_top - z_bot)``: convex endplates (``dome`` mm lower at
    the rim), lordotic wedge (anterior taller), ``height`` at the centre.
    """
    W = _positive(width, "disc width")
    D = _positive(depth, "disc depth")
    H = _positive(height, "disc height")
    if not (0.0 <= indent < 1.0):
        raise InputError(f"disc indent must lie in [0, 1), got {indent}")
    if not (0.0 <= wedge_deg < 45.0):
        raise InputError(f"disc wedge angle must lie in [0, 45) degrees, got {wedge_deg}")
    if dome < 0:
        raise InputError(f"disc dome must be >= 0, got {dome}")

    def section(x, y):
        return x, y + indent * np.exp(-x * x / 0.3) * (0.25 * (1.0 - y) ** 2)

    th = np.linspace(0.0, 2 * np.pi, 4001)
    bx, by = section(np.cos(th), np.sin(th))
    sx, sy = W / np.ptp(bx), D / np.ptp(by)
    cx, cy = 0.5 * (bx.max() + bx.min()), 0.5 * (by.max() + by.min())
    tw = math.tan(math.radians(wedge_deg) / 2)
    rim = H - 2 * dome - 2 * tw * D / 2 * 1.0001
    if rim <= 0:
        raise InputError(f"disc height {H:g} mm is too small for dome {dome:g} mm and wedge "
                         f"{wedge_deg:g} degrees (posterior rim height {rim:g} mm)")

    def f(u, v, w):
        x0, y0 = elliptic_square_to_disc(2 * u - 1, 2 * v - 1)
        x1, y1 = section(x0, y0)
        X, Y = sx * (x1 - cx), sy * (y1 - cy)
        top = H / 2 - dome * (x0 * x0 + y0 * y0) + tw * Y
        return X, Y, -top + 2 * w * top

    return f


def disc_tbss(width=50.0, depth=35.0, height=11.0, wedge_deg=8.0, dome=1.0, center=(0.0, 0.0, 0.0),
              n_ctrl=(10, 10, 4), degree=3):
    """Lumbar-intervertebral-disc-shaped solid (:func:`disc_map`), by :func:`fit_map`.

    ``x`` lateral (``width``), ``y`` anterior (``depth``; the posterior side
    ``y < 0`` is concave), ``z`` cranial; ``height`` at the centre, endplates
    ``dome`` mm lower at the rim, ``wedge_deg`` lordotic angle between them;
    ``center`` is the centre of the section's bounding box at mid-height.
    """
    c = _point3(center, "disc center")
    f0 = disc_map(width, depth, height, wedge_deg, dome)

    def f(u, v, w):
        X, Y, Z = f0(u, v, w)
        return X + c[0], Y + c[1], Z + c[2]

    return fit_map(f, n_ctrl, degree)


# ---------------------------------------------------------------- lofting
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


def _polygon_frame(pts, axis, e1, e2):
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


def _star_about(xy, c):
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
        xy, area, c2 = _polygon_frame(pts, axis, e1, e2)
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
    star = np.array([_star_about(p, c) for p, c in zip(polys, cents)])
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


def _frame(axis):
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
    n = _as3(n_ctrl, "n_ctrl")
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
        ax = _point3(axis, "loft axis")
    if np.linalg.norm(ax) == 0:
        raise InputError("cannot determine the loft axis")
    if np.dot(ax, cents[-1] - cents[0]) < 0:
        ax = -ax
    ax, e1, e2 = _frame(ax)
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
    return _finish(vol.control, vol.degrees, vol.knots)[0]


# ---------------------------------------------------------------- mesh fitting
def _mesh_arrays(vertices, faces):
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
        raise InputError(f"mesh vertices must be a (V >= 4, 3) array, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 4:
        raise InputError(f"mesh faces must be an (F >= 4, 3) array, got shape {f.shape}")
    if not np.all(np.isfinite(v)):
        raise InputError("mesh vertices have non-finite coordinates")
    if not np.issubdtype(f.dtype, np.integer):
        raise InputError("mesh faces must be integer vertex indices")
    f = np.ascontiguousarray(f, dtype=np.int64)
    if f.min() < 0 or f.max() >= len(v):
        raise InputError("mesh faces reference missing vertices")
    return v, f


def _volume_centroid(v, f):
    """Signed volume and volume centroid (sum of tetrahedra from a reference point)."""
    ref = v.mean(axis=0)
    a, b, c = v[f[:, 0]] - ref, v[f[:, 1]] - ref, v[f[:, 2]] - ref
    vol6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    V = vol6.sum() / 6.0
    if abs(V) < 1e-300:
        raise InputError("the body mesh encloses no volume")
    cen = ref + ((a + b + c) * vol6[:, None]).sum(axis=0) / (24.0 * V)
    return float(V), cen


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
            "times; try --fit sliced")
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


def _surface_distance(tb, v, f, faces=("u0", "u1", "v0", "v1", "w0", "w1"), n=24):
    """rms and max distance (mm) of TBSS boundary samples to the mesh surface."""
    from ..bodies.mesh import MeshBody

    pts = np.concatenate([tb.boundary_points(fc, n).reshape(-1, 3) for fc in faces])
    band = 0.25 * float(np.ptp(v, axis=0).max())
    d = np.abs(MeshBody(v, f, band).evaluate(pts))
    return float(np.sqrt(np.mean(d * d))), float(d.max())


def _fit_radial(v, f, n_ctrl, degree, centre, grid):
    vol_body, cen = _volume_centroid(v, f)
    c = cen if centre is None else _point3(centre, "centre")
    bmask, dirs = _cube_boundary_dirs(grid)
    t = _radial_boundary(v, f, c, dirs)
    G = np.zeros((grid, grid, grid, 3))
    G[bmask] = c + t[:, None] * dirs
    G = laplace_fill(G, 3)
    s = np.linspace(0.0, 1.0, grid)
    vol = fit_grid_lstsq(G, n_ctrl, degree, params=(s, s, s))
    tb, info = _finish(vol.control, vol.degrees, vol.knots)
    rms, dmax = _surface_distance(tb, v, f)
    return tb, {"method": "radial", "centre": tuple(float(x) for x in c), "rms_distance": rms,
                "max_distance": dmax, "covered_fraction": tb.volume() / abs(vol_body),
                "min_det": info["min_det"], "mean_det": info["mean_det"]}


# ---------------------------------------------------------------- slicing
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
    xy, area, c = _polygon_frame(loop, axis, e1, e2)
    return area != 0.0 and _star_about(xy, c)


def _fit_sliced(v, f, n_ctrl, degree, grid, levels=None):
    vol_body, cen = _volume_centroid(v, f)
    X = v - cen
    _, vec = np.linalg.eigh(X.T @ X)
    ax = vec[:, -1] * np.sign(vec[np.argmax(np.abs(vec[:, -1])), -1])   # largest component > 0
    ax, e1, e2 = _frame(ax)
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
                         "star-shaped loops; cannot loft a TBSS (try --fit radial)")
    idx = np.unique(np.round(np.linspace(bs, bs + best - 1, min(best, max(grid, n_ctrl[2])))).astype(int))
    curves = [loops[k] for k in idx]
    tb = loft_tbss(curves, heights=hs[idx], n_ctrl=n_ctrl, degree=degree, axis=ax)
    info = tb.check_jacobian()
    rms, dmax = _surface_distance(tb, v, f, faces=("u0", "u1", "v0", "v1"))
    return tb, {"method": "sliced", "axis": tuple(float(x) for x in ax),
                "levels": (float(hs[idx[0]]), float(hs[idx[-1]])), "sections": int(len(idx)),
                "length_fraction": float((hs[idx[-1]] - hs[idx[0]]) / (hi - lo)),
                "rms_distance": rms, "max_distance": dmax,
                "covered_fraction": tb.volume() / abs(vol_body),
                "min_det": info["min_det"], "mean_det": info["mean_det"]}


def fit_tbss_to_mesh(vertices, faces, method: str = "radial", n_ctrl=(8, 8, 8), centre=None,
                     grid: int = 32, degree=3):
    """Fit a TBSS to a closed triangle mesh (a body), in the mesh's units (mm).

    ``method="radial"`` (star-shaped bodies): the boundary nodes ``q`` of an
    ``grid³`` grid on ``[-1, 1]^3`` go to the surface point on the ray from
    ``centre`` (default: the volume centroid) toward ``q/|q|`` (ray-triangle
    intersection, Möller & Trumbore 1997; every ray must cross the surface
    exactly once), the interior nodes by discrete Laplace smoothing with the
    boundary fixed, the control points by least squares.

    ``method="sliced"`` (elongated bodies): sections perpendicular to the
    principal (largest-variance) axis at ``max(4 grid, 8 n3)`` levels; the
    longest run of levels whose section is one closed loop, star-shaped about
    its centroid, is kept (the ends are trimmed) and lofted
    (:func:`loft_tbss`) through ``grid`` of them.

    Returns
    -------
    tbss : TBSS
    diagnostics : dict
        ``method``, ``rms_distance`` / ``max_distance`` (mm, TBSS boundary
        samples to the surface; for "sliced" the side faces only),
        ``covered_fraction`` (TBSS volume / body volume), ``min_det`` /
        ``mean_det``; "radial" adds ``centre``, "sliced" ``axis``,
        ``levels``, ``sections``, ``length_fraction``.
    """
    v, f = _mesh_arrays(vertices, faces)
    n = _as3(n_ctrl, "n_ctrl")
    grid = int(grid)
    if grid < max(n) or grid < 4:
        raise InputError(f"grid {grid} is too coarse for {n} control points")
    if method == "radial":
        return _fit_radial(v, f, n, degree, centre, grid)
    if method == "sliced":
        return _fit_sliced(v, f, n, degree, grid)
    raise InputError(f"unknown TBSS fitting method {method!r}; use 'radial' or 'sliced'")
