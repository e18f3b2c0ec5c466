"""Trivariate tensor-product B-spline volumes and trivariate B-spline solids (TBSS).

A B-spline volume of degrees ``(p, q, r)`` (001 eq. (2); Piegl & Tiller,
*The NURBS Book*, §3.4 extended to three variables) is

.. math::

    V(u, v, w) = \\sum_{i=0}^{n_1-1} \\sum_{j=0}^{n_2-1} \\sum_{k=0}^{n_3-1}
                 N_{i,p}(u) N_{j,q}(v) N_{k,r}(w) P_{ijk},

with control values ``P_{ijk}`` in ``R^d``: ``d = 3`` for a TBSS (a solid,
the map from the parameter cube ``[0,1]^3`` into space, in mm), ``d = 1`` for
a scalar field such as 001's threshold distribution field (eq. (5)).

Point evaluation (:meth:`BSplineVolume.evaluate`, :meth:`TBSS.map_points`)
runs a numba kernel per point with the ``(p+1)(q+1)(r+1)`` loop
(:mod:`porecad.splines._volume_kernel`); grid
evaluation contracts the control net with one collocation matrix per axis.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ._volume_kernel import derivatives_points, evaluate_points, evaluate_points3
from .basis import span_range, basis_matrix
from .knots import clamped_uniform_knots, validate_knots

__all__ = ["BSplineVolume", "TBSS", "tensor_apply"]

_AXES = ("u", "v", "w")
_FACES = {"u0": (0, 0), "u1": (0, 1), "v0": (1, 0), "v1": (1, 1), "w0": (2, 0), "w1": (2, 1)}


def tensor_apply(mats, arr: np.ndarray) -> np.ndarray:
    """``out[a, b, c, ...] = sum_ijk M0[a, i] M1[b, j] M2[c, k] arr[i, j, k, ...]``.

    The Kronecker product ``(M0 ⊗ M1 ⊗ M2)`` applied to a grid one axis at a
    time; ``mats`` are scipy sparse or dense 2-D matrices, ``None`` leaves an
    axis as is. Axis 0 (whose reshape is free) takes the largest product: it
    goes first when ``M0`` shrinks the grid and last when it grows it.
    Sparse products are single-threaded C (no BLAS thread pool).
    """
    out = np.asarray(arr)
    order = (0, 1, 2)
    if mats[0] is not None and mats[0].shape[0] > mats[0].shape[1]:
        order = (2, 1, 0)
    for axis in order:
        m = mats[axis]
        if m is None:
            continue
        a = np.moveaxis(out, axis, 0)
        shape = a.shape
        r = m @ a.reshape(shape[0], -1)
        out = np.moveaxis(np.asarray(r).reshape((m.shape[0],) + shape[1:]), 0, axis)
    return np.ascontiguousarray(out)


def as3(x, name, kind=int):
    """One value for all three axes, or three values; integers must be integral."""
    vals = (x,) * 3 if np.ndim(x) == 0 else tuple(x)
    if len(vals) != 3:
        raise InputError(f"{name} needs 3 values (u, v, w), got {len(vals)}")
    if kind is bool:
        return tuple(bool(a) for a in vals)
    try:
        ok = all(float(a) == int(a) for a in vals)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"{name} must be whole numbers, got {x}")
    return tuple(int(a) for a in vals)


class BSplineVolume:
    """Tensor-product B-spline volume ``[0,1]^3 -> R^d`` (001 eq. (2)).

    Parameters
    ----------
    control : (n1, n2, n3, d) float array
        Control values ``P_ijk`` (a 3-D array is taken as ``d = 1``).
    degrees : int or 3 ints
        Degrees ``(p, q, r)``.
    knots : 3 arrays or None
        Clamped knot vectors (checked by :func:`~porecad.splines.knots.validate_knots`);
        ``None`` (or ``None`` entries) gives uniform clamped knots on ``[0, 1]``.
    """

    def __init__(self, control, degrees=3, knots=None):
        c = np.asarray(control, dtype=np.float64)
        if c.ndim == 3:
            c = c[..., None]
        if c.ndim != 4:
            raise InputError(f"control net must be a (n1, n2, n3, d) array, got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise InputError("control net has non-finite values")
        self.degrees = as3(degrees, "degrees")
        if knots is None:
            knots = (None, None, None)
        if len(knots) != 3:
            raise InputError(f"need 3 knot vectors (u, v, w), got {len(knots)}")
        kk = []
        for a in range(3):
            n, p = c.shape[a], self.degrees[a]
            if knots[a] is None:
                kk.append(clamped_uniform_knots(n, p))
            else:
                kk.append(validate_knots(knots[a], p, n, f"knot vector {_AXES[a]}"))
        self.knots = tuple(kk)
        self.control = np.ascontiguousarray(c)
        self._spans = np.array([v for a in range(3) for v in span_range(self.knots[a], self.degrees[a],
                                                                           c.shape[a])], np.int64)

    # ------------------------------------------------------------------ info
    @property
    def n_ctrl(self) -> tuple:
        return tuple(self.control.shape[:3])

    @property
    def dim(self) -> int:
        return int(self.control.shape[3])

    @property
    def domain(self) -> np.ndarray:
        """(3, 2) parameter domain ``[[u_p, u_n], ...]`` (``[0, 1]`` for porecad's knots)."""
        return np.array([[k[p], k[-p - 1]] for k, p in zip(self.knots, self.degrees)])

    def with_control(self, control):
        """A volume of the same class, degrees and knots (and periodicity) with new control values."""
        c = np.asarray(control, dtype=np.float64)
        if c.ndim == 3:
            c = c[..., None]
        if c.shape[:3] != self.control.shape[:3]:
            raise InputError(f"control net shape {c.shape} does not match {self.control.shape}")
        return type(self)(c, self.degrees, self.knots, **self._init_extra())

    def _init_extra(self) -> dict:
        return {}

    def __repr__(self):
        return (f"{type(self).__name__}(n_ctrl={self.n_ctrl}, degrees={self.degrees}, "
                f"dim={self.dim})")

    # ------------------------------------------------------------------ points
    def _points(self, u, v, w) -> np.ndarray:
        uu, vv, ww = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64),
                                         np.asarray(w, dtype=np.float64))
        pts = np.empty((uu.size, 3))
        pts[:, 0], pts[:, 1], pts[:, 2] = uu.ravel(), vv.ravel(), ww.ravel()
        return self._check_params(pts)

    def _check_params(self, pts: np.ndarray) -> np.ndarray:
        if pts.shape[0] == 0:
            return pts
        dom = self.domain
        for a in range(3):
            col = pts[:, a]
            lo, hi = col.min(), col.max()
            tol = 1e-9 * (dom[a, 1] - dom[a, 0])
            if not (lo >= dom[a, 0] - tol and hi <= dom[a, 1] + tol):
                bad = col[~((col >= dom[a, 0] - tol) & (col <= dom[a, 1] + tol))][0]
                raise InputError(f"parameter {_AXES[a]} = {bad:g} lies outside the domain "
                                 f"[{dom[a, 0]:g}, {dom[a, 1]:g}]")
        return pts

    def _eval(self, pts: np.ndarray) -> np.ndarray:
        out = np.empty((pts.shape[0], self.dim))
        if pts.shape[0]:
            (p, q, r), (ku, kv, kw) = self.degrees, self.knots
            kern = evaluate_points3 if self.dim == 3 else evaluate_points
            kern(self.control, ku, kv, kw, p, q, r, self._spans, pts, out)
        return out

    def evaluate(self, u, v, w) -> np.ndarray:
        """Values ``V(u_m, v_m, w_m)`` at scattered parameters, shape ``(m, d)``.

        ``u, v, w`` are broadcast together and flattened. Parameters must lie
        in the domain (a round-off of 1e-9 outside is accepted and extrapolated
        by the end polynomial piece).
        """
        return self._eval(self._points(u, v, w))

    def derivatives(self, u, v, w):
        """Value and first partial derivatives at scattered parameters.

        Returns
        -------
        value, d_du, d_dv, d_dw : (m, d) float arrays
            ``∂V/∂u = Σ N'_i(u) N_j(v) N_k(w) P_ijk`` and likewise.
        """
        pts = self._points(u, v, w)
        out = np.empty((4, pts.shape[0], self.dim))
        if pts.shape[0]:
            (p, q, r), (ku, kv, kw) = self.degrees, self.knots
            derivatives_points(self.control, ku, kv, kw, p, q, r, self._spans, pts, out)
        return out[0], out[1], out[2], out[3]

    # ------------------------------------------------------------------ grids
    def basis_matrices(self, us, vs, ws, deriv=(0, 0, 0)):
        """Per-axis collocation matrices (CSR, ``(len(t), n_ctrl)``) at grid parameters."""
        return [basis_matrix(self.knots[a], self.degrees[a],
                             self._check_grid(t, a), deriv=int(deriv[a]))
                for a, t in enumerate((us, vs, ws))]

    def _check_grid(self, t, a):
        t = np.asarray(t, dtype=np.float64).ravel()
        pts = np.zeros((t.size, 3))
        pts[:] = self.domain[:, 0]
        pts[:, a] = t
        self._check_params(pts)
        return t

    def evaluate_grid(self, us, vs, ws, deriv=(0, 0, 0)) -> np.ndarray:
        """Values on the tensor grid ``us × vs × ws``, shape ``(len(us), len(vs), len(ws), d)``.

        ``V[a, b, c] = Σ_ijk B^u[a, i] B^v[b, j] B^w[c, k] P_ijk`` with the
        collocation matrices ``B^u[a, i] = N_i(us[a])`` (of derivative order
        ``deriv[0]``, ...), contracted one axis at a time.
        """
        return tensor_apply(self.basis_matrices(us, vs, ws, deriv), self.control)


class TBSS(BSplineVolume):
    """Trivariate B-spline solid: a B-spline volume ``[0,1]^3 -> R^3`` (mm).

    Parameters
    ----------
    control : (n1, n2, n3, 3) float array
    degrees, knots
        As :class:`BSplineVolume`.
    periodic : 3 bools
        ``periodic[a]``: the faces ``a = 0`` and ``a = 1`` are the same
        surface (e.g. the angle of a tube); the first and last control slabs
        along that axis must coincide, and scaffold code welds rather than
        caps that face pair.
    """

    def __init__(self, control, degrees=3, knots=None, periodic=(False, False, False)):
        super().__init__(control, degrees, knots)
        if self.dim != 3:
            raise InputError(f"a TBSS needs 3-D control points, got dimension {self.dim}")
        self.periodic = as3(periodic, "periodic", bool)
        ext = float(np.ptp(self.control.reshape(-1, 3), axis=0).max()) if self.control.size else 0.0
        for a in range(3):
            if self.periodic[a]:
                first = np.take(self.control, 0, axis=a)
                last = np.take(self.control, -1, axis=a)
                gap = float(np.abs(first - last).max())
                if gap > 1e-9 * max(ext, 1.0):
                    raise InputError(f"periodic in {_AXES[a]}, but the faces {_AXES[a]}=0 and "
                                     f"{_AXES[a]}=1 differ by up to {gap:g} mm")

    def _init_extra(self) -> dict:
        return {"periodic": self.periodic}

    # ------------------------------------------------------------------ mapping
    def map_points(self, params) -> np.ndarray:
        """Map parameters ``(m, 3)`` in ``[0,1]^3`` to points ``(m, 3)`` in mm (001 §3.3)."""
        pts = np.ascontiguousarray(params, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"parameters must be an (m, 3) array, got shape {pts.shape}")
        return self._eval(self._check_params(pts))

    def jacobian(self, u, v, w) -> np.ndarray:
        """Jacobian matrices ``J[m, i, j] = ∂x_i/∂u_j``, shape ``(m, 3, 3)``."""
        _, du, dv, dw = self.derivatives(u, v, w)
        return np.stack([du, dv, dw], axis=2)

    def _grid_det(self, us, vs, ws, chunk_points=1 << 18):
        """det J on a grid, slab by slab along u; returns (len(us), len(vs), len(ws))."""
        Bv = [basis_matrix(self.knots[1], self.degrees[1], vs, deriv=k) for k in (0, 1)]
        Bw = [basis_matrix(self.knots[2], self.degrees[2], ws, deriv=k) for k in (0, 1)]
        # contract v and w once: (n1, nv, nw, 3) for the three needed combinations
        cvw = {key: tensor_apply([None, Bv[key[0]], Bw[key[1]]], self.control) for key in ((0, 0), (1, 0), (0, 1))}
        out = np.empty((len(us), len(vs), len(ws)))
        step = max(1, chunk_points // max(1, len(vs) * len(ws)))
        for a0 in range(0, len(us), step):
            uu = us[a0:a0 + step]
            B0 = basis_matrix(self.knots[0], self.degrees[0], uu, deriv=0)
            B1 = basis_matrix(self.knots[0], self.degrees[0], uu, deriv=1)
            du = tensor_apply([B1, None, None], cvw[(0, 0)])
            dv = tensor_apply([B0, None, None], cvw[(1, 0)])
            dw = tensor_apply([B0, None, None], cvw[(0, 1)])
            out[a0:a0 + step] = triple_product(du, dv, dw)
        return out

    def sample_params(self, axis, count):
        """Sample parameters along one axis: ``count`` uniform (ends included) plus
        3 Gauss-Legendre nodes in every non-empty knot span."""
        k, p = self.knots[axis], self.degrees[axis]
        lo, hi = k[p], k[-p - 1]
        g, _ = np.polynomial.legendre.leggauss(3)
        brk = np.unique(k[p:len(k) - p])
        mids = 0.5 * (brk[1:] + brk[:-1])
        half = 0.5 * (brk[1:] - brk[:-1])
        gauss = (mids[:, None] + half[:, None] * g[None, :]).ravel()
        return np.unique(np.concatenate([np.linspace(lo, hi, int(count)), gauss, brk]))

    def check_jacobian(self, samples_per_axis=None, rtol: float = 1e-9) -> dict:
        """Sample det J densely and refuse a folded solid (001 §3.3: "the Jacobian value of
        the TBSS should be positive").

        Samples, per axis, ``samples_per_axis`` uniform parameters (default
        ``max(4 n_i, 16)``; the ends, hence the faces, edges and corners, are
        included), every knot and 3 Gauss points per knot span; det J on their
        tensor grid.

        Returns
        -------
        dict
            ``min_det, max_det, mean_det`` (mm³ per unit parameter volume),
            ``samples`` (number of sample points), ``min_at`` (u, v, w).

        Raises
        ------
        InputError
            ``"TBSS folds: ..."`` when any sampled ``det J <= rtol * |mean det J|``.
        """
        axes = []
        for a in range(3):
            cnt = samples_per_axis if samples_per_axis is not None else max(4 * self.n_ctrl[a], 16)
            if np.ndim(cnt):
                cnt = cnt[a]
            if int(cnt) < 2:
                raise InputError(f"need at least 2 samples per axis, got {cnt}")
            axes.append(self.sample_params(a, cnt))
        det = self._grid_det(*axes)
        mean = float(det.mean())
        i = np.unravel_index(int(np.argmin(det)), det.shape)
        at = tuple(float(axes[a][i[a]]) for a in range(3))
        info = {"min_det": float(det[i]), "max_det": float(det.max()), "mean_det": mean,
                "samples": int(det.size), "min_at": at}
        if not info["min_det"] > rtol * abs(mean):
            if info["max_det"] <= 0:
                raise InputError("TBSS folds: Jacobian determinant <= 0 everywhere (the map is "
                                 "inverted: reverse one parametric direction)")
            x = self.evaluate(*at)[0]
            raise InputError(
                "TBSS folds: Jacobian determinant <= 0 at (u, v, w) = "
                f"({at[0]:.3g}, {at[1]:.3g}, {at[2]:.3g}), point ({x[0]:.4g}, {x[1]:.4g}, "
                f"{x[2]:.4g}) mm (min det J = {info['min_det']:.3g}, mean {mean:.3g})")
        return info

    def volume(self, lo=(0.0, 0.0, 0.0), hi=(1.0, 1.0, 1.0)) -> float:
        """Volume ``∫ det J du dv dw`` (mm³) of the parameter box ``[lo, hi]`` (default: the whole
        solid) by Gauss-Legendre quadrature per knot span.

        On a span det J is a polynomial of degree ``3p - 1`` in ``u`` (likewise
        ``v``, ``w``), so ``ceil(3p / 2)`` Gauss points per span integrate it exactly;
        the box's faces are added as breakpoints. Signed: a folded solid's
        overlapping parts cancel.
        """
        nodes, weights = [], []
        for a in range(3):
            k, p = self.knots[a], self.degrees[a]
            ng = max(1, math.ceil(3 * p / 2))
            g, gw = np.polynomial.legendre.leggauss(ng)
            brk = np.unique(k[p:len(k) - p])
            brk = np.unique(np.clip(np.concatenate([brk, [lo[a], hi[a]]]), lo[a], hi[a]))
            mids, half = 0.5 * (brk[1:] + brk[:-1]), 0.5 * (brk[1:] - brk[:-1])
            nodes.append((mids[:, None] + half[:, None] * g[None, :]).ravel())
            weights.append((half[:, None] * gw[None, :]).ravel())
        det = self._grid_det(*nodes)
        return float(np.einsum("abc,a,b,c->", det, *weights))

    def boundary_points(self, face: str, n: int) -> np.ndarray:
        """``(n, n, 3)`` points of a boundary surface on a uniform parameter grid.

        ``face`` is one of ``u0, u1, v0, v1, w0, w1`` (the parameter fixed at 0
        or 1); the two grid axes are the remaining parameters in order (e.g.
        ``(v, w)`` for ``u0``).
        """
        if face not in _FACES:
            raise InputError(f"unknown face {face!r}; use one of {', '.join(_FACES)}")
        n = int(n)
        if n < 2:
            raise InputError(f"need at least 2 points per side, got {n}")
        axis, end = _FACES[face]
        dom = self.domain
        grids = [np.linspace(dom[a, 0], dom[a, 1], n) for a in range(3)]
        grids[axis] = np.array([dom[axis, end]])
        pts = self.evaluate_grid(*grids)
        return np.squeeze(pts, axis=axis)

    def bounds(self, samples: int | None = None) -> np.ndarray:
        """Axis-aligned bounding box ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` (mm).

        From the six boundary surfaces sampled on ``samples``² points each
        (default ``max(8 max(n_ctrl), 64)``): a map with positive Jacobian
        takes its extremes on the boundary. Never larger than the control
        points' box (convex hull property).
        """
        n = samples if samples is not None else max(8 * max(self.n_ctrl), 64)
        pts = np.concatenate([self.boundary_points(f, n).reshape(-1, 3) for f in _FACES])
        return np.stack([pts.min(axis=0), pts.max(axis=0)])


def triple_product(a, b, c):
    """``a · (b × c)`` over the last axis: the determinant of the 3×3 matrices of columns ``a, b, c``,
    several times faster than :func:`numpy.linalg.det` on many small matrices."""
    return (a[..., 0] * (b[..., 1] * c[..., 2] - b[..., 2] * c[..., 1])
            - a[..., 1] * (b[..., 0] * c[..., 2] - b[..., 2] * c[..., 0])
            + a[..., 2] * (b[..., 0] * c[..., 1] - b[..., 1] * c[..., 0]))
