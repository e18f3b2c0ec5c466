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

Lofting through sections is in :mod:`porecad.splines.loft`, fitting to a
body mesh in :mod:`porecad.splines.meshfit`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..errors import InputError
from .lspia import fit_grid_lstsq
from .volume import TBSS, as3

__all__ = ["box_tbss", "fit_map", "cylinder_tbss", "tube_tbss", "disc_map", "disc_tbss", "finish_tbss",
           "open_edges", "elliptic_square_to_disc", "point3", "positive", "positive3"]

_ETAS = (0.05, 0.1, 0.2, 0.4)


# ---------------------------------------------------------------- common
def positive3(x, name):
    v = np.asarray(x, dtype=np.float64).ravel()
    if v.size != 3 or not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise InputError(f"{name} must be 3 positive numbers, got {x}")
    return v


def positive(x, name):
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {x!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be positive, got {x}")
    return v


def point3(x, name):
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
    per = as3(periodic, "periodic", bool)
    idx = np.indices(n).reshape(3, -1).T
    onb = np.zeros(len(idx), np.int64)
    for a in range(3):
        if not per[a]:
            onb += (idx[:, a] == 0) | (idx[:, a] == n[a] - 1)
    cand = idx[onb >= 2]
    _open_edges_kernel(P, cand, np.array(per, dtype=np.bool_), float(eta), int(iterations))
    return P


@njit(cache=True)
def _cross(x, y):
    return np.array([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])


@njit(cache=True)
def _norm(x):
    return math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])


@njit(cache=True)
def _open_edges_kernel(P, cand, per, eta, iterations):
    """The moves of :func:`open_edges`, in place, candidates in order (each sees the moves before it)."""
    n = P.shape[:3]
    D = np.empty((3, 3))
    S = np.empty(3)
    for _ in range(iterations):
        changed = False
        for k in range(cand.shape[0]):
            c = cand[k]
            for a in range(3):
                i = c[a]
                lo = c.copy()
                hi = c.copy()
                if per[a] and (i == 0 or i == n[a] - 1):
                    lo[a] = n[a] - 2 if i == 0 else i - 1
                    hi[a] = 1 if i == n[a] - 1 else i + 1
                    D[a] = 0.5 * (P[hi[0], hi[1], hi[2]] - P[lo[0], lo[1], lo[2]])
                    S[a] = 0.0
                elif i == 0:
                    D[a] = P[c[0] + (a == 0), c[1] + (a == 1), c[2] + (a == 2)] - P[c[0], c[1], c[2]]
                    S[a] = -1.0
                elif i == n[a] - 1:
                    D[a] = P[c[0], c[1], c[2]] - P[c[0] - (a == 0), c[1] - (a == 1), c[2] - (a == 2)]
                    S[a] = 1.0
                else:
                    lo[a], hi[a] = i - 1, i + 1
                    D[a] = 0.5 * (P[hi[0], hi[1], hi[2]] - P[lo[0], lo[1], lo[2]])
                    S[a] = 0.0
            c12, c20, c01 = _cross(D[1], D[2]), _cross(D[2], D[0]), _cross(D[0], D[1])
            f = D[0, 0] * c12[0] + D[0, 1] * c12[1] + D[0, 2] * c12[2]
            tau = eta * (_norm(D[0]) * _norm(D[1]) * _norm(D[2]))
            if f >= tau:
                continue
            g = S[0] * c12 + S[1] * c20 + S[2] * c01
            if S[0] != 0.0 and S[1] != 0.0 and S[2] != 0.0:
                g = _in_face(P, c, D, g)
            gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2]
            if gg == 0.0:
                continue
            P[c[0], c[1], c[2]] += (tau - f) / gg * g
            changed = True
        if not changed:
            break


@njit(cache=True)
def _in_face(P, c, D, g):
    """At a corner of the net, restrict the move ``g`` to the face across the most
    degenerate pair of directions (e.g. keep a cylinder's flat end flat).

    The pair ``(a, b)`` with the smallest ``|D_a × D_b| / (|D_a| |D_b|)`` spans the
    degenerate face ``c``; its normal comes from the diagonals of the face's
    corner quad (well conditioned even when ``D_a ∥ D_b``). Falls back to ``g``
    when the projection would leave less than 10 % of it.
    """
    pairs = ((0, 1), (1, 2), (0, 2))
    best, a, b = np.inf, 0, 1
    for pa, pb in pairs:
        den = _norm(D[pa]) * _norm(D[pb])
        sine = _norm(_cross(D[pa], D[pb])) / den if den > 0 else 0.0
        if sine < best:
            best, a, b = sine, pa, pb
    n = P.shape[:3]
    if min(n[a], n[b]) < 2:
        return g
    ia, ib, iab = c.copy(), c.copy(), c.copy()
    ia[a] = 1 if c[a] == 0 else c[a] - 1
    ib[b] = 1 if c[b] == 0 else c[b] - 1
    iab[a], iab[b] = ia[a], ib[b]
    d1 = P[iab[0], iab[1], iab[2]] - P[c[0], c[1], c[2]]
    d2 = P[ia[0], ia[1], ia[2]] - P[ib[0], ib[1], ib[2]]
    nrm = _cross(d1, d2)
    ln = _norm(nrm)
    if ln == 0.0:
        return g
    nrm = nrm / ln
    gp = g - (g[0] * nrm[0] + g[1] * nrm[1] + g[2] * nrm[2]) * nrm
    return gp if _norm(gp) >= 0.1 * _norm(g) else g


def finish_tbss(control, degrees, knots, periodic=(False, False, False), samples=None):
    """Open the edges (increasing η until the solid passes) and check the Jacobian."""
    err = None
    for eta in _ETAS:
        P = open_edges(control, periodic, eta)
        per = as3(periodic, "periodic", bool)
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
    n = as3(n_ctrl, "n_ctrl")
    p = as3(degree, "degree")
    if samples is None:
        samples = tuple(max(6 * k, 16) for k in n)
    samples = as3(samples, "samples")
    Q, s = _sample_grid(func, samples)
    vol = fit_grid_lstsq(Q, n, p, params=s)
    per = as3(periodic, "periodic", bool)
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
    return finish_tbss(P, p, vol.knots, per)[0]


# ---------------------------------------------------------------- primitives
def box_tbss(size=(10.0, 10.0, 10.0), origin=(0.0, 0.0, 0.0), n_ctrl=(4, 4, 4), degree=3):
    """Box ``origin + [0, a] × [0, b] × [0, c]`` (mm) as a TBSS: ``x = origin + size * (u, v, w)``.

    Control points at the Greville abscissae (``P_ijk = origin + size * (g_i, g_j, g_k)``)
    reproduce the linear map exactly (linear precision, P&T §2.2 / eq. 9.49);
    ``det J = a b c`` everywhere.
    """
    from .basis import greville
    from .knots import clamped_uniform_knots

    size = positive3(size, "box size")
    origin = point3(origin, "box origin")
    n = as3(n_ctrl, "n_ctrl")
    p = as3(degree, "degree")
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
    R = positive(radius, "cylinder radius")
    H = positive(height, "cylinder height")
    c = point3(center, "cylinder center")

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
    ri = positive(r_inner, "inner radius")
    ro = positive(r_outer, "outer radius")
    H = positive(height, "tube height")
    if ro <= ri:
        raise InputError(f"outer radius {ro:g} must exceed inner radius {ri:g}")
    c = point3(center, "tube center")
    n = as3(n_ctrl, "n_ctrl")
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
    W = positive(width, "disc width")
    D = positive(depth, "disc depth")
    H = positive(height, "disc height")
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
    c = point3(center, "disc center")
    f0 = disc_map(width, depth, height, wedge_deg, dome)

    def f(u, v, w):
        X, Y, Z = f0(u, v, w)
        return X + c[0], Y + c[1], Z + c[2]

    return fit_map(f, n_ctrl, degree)
