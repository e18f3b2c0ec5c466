"""Numba kernels of B-spline volume evaluation at scattered parameters (:mod:`porecad.splines.volume`).

A point costs three span searches (binary search on the knot vector, P&T
A2.1), three sets of p + 1 basis values (A2.2; for derivatives the first
derivative from the degree p - 1 values, P&T eq. 2.7) and the
(p+1)(q+1)(r+1) weighted sum of control points (001 eq. (2)). Points are
processed in chunks in parallel; each chunk allocates its small scratch
arrays once, so memory is the input and output arrays only.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["derivatives_points", "evaluate_points", "evaluate_points3"]

_CHUNK = 4096


@njit(cache=True, inline="always")
def _span(knots, lo, hi, t):
    """``s`` in ``[lo, hi]`` with ``knots[s] <= t < knots[s+1]``, clamped to the end spans."""
    if t >= knots[hi]:
        return hi
    if t < knots[lo + 1]:
        return lo
    a, b = lo, hi
    while b - a > 1:
        mid = (a + b) // 2
        if t < knots[mid]:
            b = mid
        else:
            a = mid
    return a


@njit(cache=True, inline="always")
def _basis(knots, p, s, t, N, left, right):
    """A2.2: the ``p + 1`` non-zero basis values ``N_{s-p..s,p}(t)`` into ``N``."""
    N[0] = 1.0
    for j in range(1, p + 1):
        left[j] = t - knots[s + 1 - j]
        right[j] = knots[s + j] - t
        saved = 0.0
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            N[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        N[j] = saved


@njit(cache=True, inline="always")
def _basis_d1(knots, p, s, t, N, dN, left, right):
    """Values and first derivatives of the ``p + 1`` non-zero basis functions.

    ``N'_{i,p} = p (N_{i,p-1} / (u_{i+p} - u_i) - N_{i+1,p-1} / (u_{i+p+1} - u_{i+1}))``
    with the degree ``p - 1`` values taken from the A2.2 table before its last step.
    """
    N[0] = 1.0
    for j in range(1, p + 1):
        if j == p:
            for r in range(p):
                dN[r] = N[r]          # degree p-1 values N_{s-p+1..s, p-1}
        left[j] = t - knots[s + 1 - j]
        right[j] = knots[s + j] - t
        saved = 0.0
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            N[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        N[j] = saved
    if p == 0:
        dN[0] = 0.0
        return
    # dN holds the p lower-degree values; convert in place from the top index down
    dN[p] = p * dN[p - 1] / (knots[s + p] - knots[s])
    for r in range(p - 1, 0, -1):
        a = dN[r - 1] / (knots[s + r] - knots[s - p + r])
        b = dN[r] / (knots[s + r + 1] - knots[s - p + r + 1])
        dN[r] = p * (a - b)
    dN[0] = -p * dN[0] / (knots[s + 1] - knots[s - p + 1])


@njit(cache=True, parallel=True)
def evaluate_points(ctrl, ku, kv, kw, p, q, r, spans, pts, out):
    """``out[m] = sum_i N_i(u) sum_j N_j(v) sum_k N_k(w) ctrl[i, j, k]``, any dimension ``d``."""
    m = pts.shape[0]
    d = ctrl.shape[3]
    nchunks = (m + _CHUNK - 1) // _CHUNK
    for c in prange(nchunks):
        Nu = np.empty(p + 1)
        Nv = np.empty(q + 1)
        Nw = np.empty(r + 1)
        pm = max(p, max(q, r)) + 1
        left = np.empty(pm)
        right = np.empty(pm)
        acc = np.empty(d)
        for idx in range(c * _CHUNK, min(m, (c + 1) * _CHUNK)):
            u, v, w = pts[idx, 0], pts[idx, 1], pts[idx, 2]
            su = _span(ku, spans[0], spans[1], u)
            sv = _span(kv, spans[2], spans[3], v)
            sw = _span(kw, spans[4], spans[5], w)
            _basis(ku, p, su, u, Nu, left, right)
            _basis(kv, q, sv, v, Nv, left, right)
            _basis(kw, r, sw, w, Nw, left, right)
            for e in range(d):
                acc[e] = 0.0
            for a in range(p + 1):
                ia = su - p + a
                for b in range(q + 1):
                    ib = sv - q + b
                    wab = Nu[a] * Nv[b]
                    for cc in range(r + 1):
                        ic = sw - r + cc
                        wt = wab * Nw[cc]
                        for e in range(d):
                            acc[e] += wt * ctrl[ia, ib, ic, e]
            for e in range(d):
                out[idx, e] = acc[e]


@njit(cache=True, parallel=True)
def evaluate_points3(ctrl, ku, kv, kw, p, q, r, spans, pts, out):
    """As :func:`evaluate_points` for ``d = 3`` with scalar accumulators and the sum
    nested as ``sum_i N_i (sum_j N_j (sum_k N_k P_ijk))`` (the hot path of mapping)."""
    m = pts.shape[0]
    nchunks = (m + _CHUNK - 1) // _CHUNK
    for c in prange(nchunks):
        Nu = np.empty(p + 1)
        Nv = np.empty(q + 1)
        Nw = np.empty(r + 1)
        pm = max(p, max(q, r)) + 1
        left = np.empty(pm)
        right = np.empty(pm)
        for idx in range(c * _CHUNK, min(m, (c + 1) * _CHUNK)):
            u, v, w = pts[idx, 0], pts[idx, 1], pts[idx, 2]
            su = _span(ku, spans[0], spans[1], u)
            sv = _span(kv, spans[2], spans[3], v)
            sw = _span(kw, spans[4], spans[5], w)
            _basis(ku, p, su, u, Nu, left, right)
            _basis(kv, q, sv, v, Nv, left, right)
            _basis(kw, r, sw, w, Nw, left, right)
            x = 0.0
            y = 0.0
            z = 0.0
            for a in range(p + 1):
                ia = su - p + a
                xa = 0.0
                ya = 0.0
                za = 0.0
                for b in range(q + 1):
                    ib = sv - q + b
                    xb = 0.0
                    yb = 0.0
                    zb = 0.0
                    for cc in range(r + 1):
                        ic = sw - r + cc
                        nw = Nw[cc]
                        xb += nw * ctrl[ia, ib, ic, 0]
                        yb += nw * ctrl[ia, ib, ic, 1]
                        zb += nw * ctrl[ia, ib, ic, 2]
                    nv = Nv[b]
                    xa += nv * xb
                    ya += nv * yb
                    za += nv * zb
                nu = Nu[a]
                x += nu * xa
                y += nu * ya
                z += nu * za
            out[idx, 0] = x
            out[idx, 1] = y
            out[idx, 2] = z


@njit(cache=True, parallel=True)
def derivatives_points(ctrl, ku, kv, kw, p, q, r, spans, pts, out):
    """``out[0..3, m]``: value and partial derivatives d/du, d/dv, d/dw at each point."""
    m = pts.shape[0]
    d = ctrl.shape[3]
    nchunks = (m + _CHUNK - 1) // _CHUNK
    for c in prange(nchunks):
        Nu = np.empty(p + 1)
        Nv = np.empty(q + 1)
        Nw = np.empty(r + 1)
        dNu = np.empty(p + 1)
        dNv = np.empty(q + 1)
        dNw = np.empty(r + 1)
        pm = max(p, max(q, r)) + 1
        left = np.empty(pm)
        right = np.empty(pm)
        acc = np.empty((4, d))
        for idx in range(c * _CHUNK, min(m, (c + 1) * _CHUNK)):
            u, v, w = pts[idx, 0], pts[idx, 1], pts[idx, 2]
            su = _span(ku, spans[0], spans[1], u)
            sv = _span(kv, spans[2], spans[3], v)
            sw = _span(kw, spans[4], spans[5], w)
            _basis_d1(ku, p, su, u, Nu, dNu, left, right)
            _basis_d1(kv, q, sv, v, Nv, dNv, left, right)
            _basis_d1(kw, r, sw, w, Nw, dNw, left, right)
            for k in range(4):
                for e in range(d):
                    acc[k, e] = 0.0
            for a in range(p + 1):
                ia = su - p + a
                for b in range(q + 1):
                    ib = sv - q + b
                    w00 = Nu[a] * Nv[b]
                    w10 = dNu[a] * Nv[b]
                    w01 = Nu[a] * dNv[b]
                    for cc in range(r + 1):
                        ic = sw - r + cc
                        n0 = w00 * Nw[cc]
                        n1 = w10 * Nw[cc]
                        n2 = w01 * Nw[cc]
                        n3 = w00 * dNw[cc]
                        for e in range(d):
                            x = ctrl[ia, ib, ic, e]
                            acc[0, e] += n0 * x
                            acc[1, e] += n1 * x
                            acc[2, e] += n2 * x
                            acc[3, e] += n3 * x
            for k in range(4):
                for e in range(d):
                    out[k, idx, e] = acc[k, e]
