"""B-spline basis functions, vectorised over the parameter.

Notation of Piegl & Tiller, *The NURBS Book* (2nd ed., 1997), §2.2-2.3: a
knot vector ``U = (u_0, ..., u_{n+p})`` of a degree-``p`` B-spline with ``n``
control points; the basis functions follow the Cox-de Boor recursion

.. math::

    N_{i,0}(u) = 1 \\text{ if } u_i \\le u < u_{i+1} \\text{ else } 0, \\qquad
    N_{i,p}(u) = \\frac{u - u_i}{u_{i+p} - u_i} N_{i,p-1}(u)
               + \\frac{u_{i+p+1} - u}{u_{i+p+1} - u_{i+1}} N_{i+1,p-1}(u),

(001 eq. (1)). On the knot span ``[u_s, u_{s+1})`` only ``N_{s-p..s,p}`` are
non-zero; :func:`basis_functions` returns those ``p + 1`` values (and their
derivatives) for every parameter at once, from scipy's de Boor evaluation
(:meth:`scipy.interpolate.BSpline.design_matrix`).
Knot vectors here are clamped (see :mod:`porecad.splines.knots`); the
parameter ``u = u_{n+p}`` (the end of the domain) belongs to the last
non-empty span, so the basis is right-continuous except at the end, where it
is left-continuous and ``N_{n-1,p}(u_{n+p}) = 1``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline

from ..errors import InputError

__all__ = ["find_spans", "basis_functions", "basis_matrix", "greville", "tensor_basis_matrix"]


def _n_ctrl(knots: np.ndarray, degree: int) -> int:
    n = len(knots) - int(degree) - 1
    if degree < 0 or n <= degree:
        raise InputError(f"a degree-{degree} basis needs more than {2 * degree + 1} knots, got {len(knots)}")
    return n


def span_range(knots: np.ndarray, p: int, n: int) -> tuple[int, int]:
    """First and last non-empty span index in ``[p, n-1]``."""
    nonempty = np.nonzero(knots[p:n + 1][1:] > knots[p:n + 1][:-1])[0] + p
    if nonempty.size == 0:
        raise InputError("knot vector has an empty parameter domain")
    return int(nonempty[0]), int(nonempty[-1])


def find_spans(knots, degree: int, t) -> np.ndarray:
    """Knot span index ``s`` with ``u_s <= t < u_{s+1}`` for every parameter (A2.1).

    Parameters outside the domain ``[u_p, u_n]`` are assigned to the first or
    last non-empty span (the polynomial piece is extrapolated); ``t == u_n``
    goes to the last non-empty span.

    Parameters
    ----------
    knots : (n + p + 1,) float array
    degree : int
    t : float or (m,) float array

    Returns
    -------
    (m,) int64 array, values in ``[p, n-1]``.
    """
    k = np.asarray(knots, dtype=np.float64)
    p = int(degree)
    n = _n_ctrl(k, p)
    lo, hi = span_range(k, p, n)
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    s = np.searchsorted(k, t, side="right") - 1
    return np.clip(s, lo, hi).astype(np.int64)


def basis_functions(knots, degree: int, t, n_derivs: int = 0):
    """Non-zero basis functions and their derivatives at each parameter (what P&T A2.2 / A2.3 compute).

    For the span ``s`` of ``t`` returns ``N^{(k)}_{s-p+j,p}(t)`` for
    ``j = 0..p`` and ``k = 0..n_derivs``: the entries of :func:`basis_matrix`
    in the columns ``s-p..s``. Derivatives of order above ``p`` are zero.

    Parameters
    ----------
    knots : (n + p + 1,) float array
    degree : int
    t : float or (m,) float array
    n_derivs : int

    Returns
    -------
    spans : (m,) int64 array
    values : (n_derivs + 1, m, p + 1) float64 array
    """
    k = np.asarray(knots, dtype=np.float64)
    p, nd = int(degree), int(n_derivs)
    if nd < 0:
        raise InputError(f"number of derivatives must be >= 0, got {n_derivs}")
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    spans = find_spans(k, p, t)
    rows, cols = np.arange(t.size)[:, None], spans[:, None] - p + np.arange(p + 1)
    out = [basis_matrix(k, p, t, d)[rows, cols].toarray() for d in range(nd + 1)]
    return spans, np.stack(out).reshape(nd + 1, t.size, p + 1)


def _derivative_matrix(knots: np.ndarray, q: int) -> sp.csr_array:
    """``(n-1, n)``: the coefficients (knots ``knots[1:-1]``, degree ``q-1``) of the derivative of the degree-``q``
    spline with knots ``knots``, ``c'_i = q (c_{i+1} - c_i) / (u_{i+q+1} - u_{i+1})`` (P&T eq. 3.8); 0 where the
    knot difference is (the basis function is then zero)."""
    n = len(knots) - q - 1
    h = knots[q + 1:n + q] - knots[1:n]
    c = np.divide(q, h, out=np.zeros_like(h), where=h > 0)
    return sp.diags_array([-c, c], offsets=[0, 1], shape=(n - 1, n), format="csr")


def basis_matrix(knots, degree: int, t, deriv: int = 0) -> sp.csr_matrix:
    """Collocation matrix ``B[j, i] = N^{(deriv)}_{i,p}(t_j)`` as CSR, shape ``(m, n_ctrl)``.

    scipy's :meth:`~scipy.interpolate.BSpline.design_matrix` (de Boor, extrapolated outside the domain),
    for a derivative that of degree ``p - deriv`` times the derivative matrices. Each row has ``p + 1``
    stored entries (some may be exactly zero at knots; none for ``deriv > p``); for ``deriv = 0`` every
    row sums to 1 (partition of unity, P&T property P2.4).
    """
    k = np.asarray(knots, dtype=np.float64)
    p, d = int(degree), int(deriv)
    n = _n_ctrl(k, p)
    span_range(k, p, n)
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    if not np.isfinite(t).all():
        raise InputError("B-spline parameters must be finite")
    if d > p:
        return sp.csr_matrix((t.size, n))
    b = BSpline.design_matrix(t, k[d:len(k) - d], p - d, extrapolate=True)
    for j in range(d, 0, -1):
        b = b @ _derivative_matrix(k[j - 1:len(k) - j + 1], p - j + 1)
    return sp.csr_matrix(b)


def greville(knots, degree: int) -> np.ndarray:
    """Greville abscissae ``g_i = (u_{i+1} + ... + u_{i+p}) / p`` (P&T eq. 9.49 context).

    The B-spline with control values ``g_i`` is the identity,
    ``sum_i N_{i,p}(u) g_i = u`` (linear precision), for ``p >= 1``. For
    ``p = 0`` the span midpoints ``(u_i + u_{i+1}) / 2`` are returned.
    """
    k = np.asarray(knots, dtype=np.float64)
    p = int(degree)
    n = _n_ctrl(k, p)
    if p == 0:
        return 0.5 * (k[:n] + k[1:n + 1])
    c = np.concatenate([[0.0], np.cumsum(k)])
    i = np.arange(n)
    return (c[i + p + 1] - c[i + 1]) / p


def tensor_basis_matrix(knots, degrees, uvw) -> sp.csr_matrix:
    """Collocation matrix of a trivariate tensor-product basis at scattered parameters.

    ``B[j, (i0 * n1 + i1) * n2 + i2] = N_{i0}(u_j) N_{i1}(v_j) N_{i2}(w_j)``,
    shape ``(m, n0 n1 n2)``: row ``j`` times the control points flattened in C
    order (``control.reshape(-1, d)``) is the volume at ``uvw[j]``. Each row
    has ``Π (p_a + 1)`` stored entries.
    """
    uvw = np.asarray(uvw, dtype=np.float64).reshape(-1, 3)
    m = len(uvw)
    idx, val, n = [], [], []
    for a in range(3):
        b = basis_matrix(knots[a], degrees[a], uvw[:, a])
        n.append(b.shape[1])
        idx.append(b.indices.reshape(m, -1).astype(np.int64))
        val.append(b.data.reshape(m, -1))
    cols = (idx[0][:, :, None, None] * (n[1] * n[2]) + idx[1][:, None, :, None] * n[2]
            + idx[2][:, None, None, :]).reshape(m, -1)
    vals = (val[0][:, :, None, None] * val[1][:, None, :, None] * val[2][:, None, None, :]).reshape(m, -1)
    k = cols.shape[1]
    return sp.csr_matrix((vals.ravel(), cols.ravel(), np.arange(0, m * k + 1, k)), shape=(m, n[0] * n[1] * n[2]))
