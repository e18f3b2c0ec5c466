"""The numba kernels of the ARBF interpolant: generalised distances, system matrices, evaluation.

The generalised distance ``‖·‖_L`` of document 000 §5.2 (point–point,
point–segment, segment–segment as the smallest endpoint distance) and the
basis functions of 000 Table 5.1, by their codes in
:data:`porecad.fields.rbf.BASES` (0 gaussian, 1 mq, 2 imq, 3 tps), compiled
with numba and parallel over rows or points. The arrays are those of a
:class:`~porecad.fields.rbf_centres.Centres`: ``a, b (N, 3)`` float64 and
``seg (N,)`` bool. Every kernel writes into ``out`` and returns nothing; the
checked entry points are in :mod:`porecad.fields.rbf`.
"""

from __future__ import annotations

import math

from numba import njit, prange

__all__ = ["fill_distance_matrix", "fill_system", "eval_global", "eval_local"]


@njit(cache=True, inline="always")
def _phi(r, basis, c):
    if basis == 0:
        s = c * r
        return math.exp(-s * s)
    if basis == 1:
        return math.sqrt(r * r + c * c)
    if basis == 2:
        return 1.0 / math.sqrt(r * r + c * c)
    s = c * r
    if s <= 0.0:
        return 0.0
    return s * s * math.log(s)


@njit(cache=True, inline="always")
def _dist_x(x0, x1, x2, a, b, seg, j):
    """Generalised distance from the point ``x`` to centre ``j``."""
    ax, ay, az = a[j, 0], a[j, 1], a[j, 2]
    if not seg[j]:
        return math.sqrt((x0 - ax) ** 2 + (x1 - ay) ** 2 + (x2 - az) ** 2)
    dx, dy, dz = b[j, 0] - ax, b[j, 1] - ay, b[j, 2] - az
    L2 = dx * dx + dy * dy + dz * dz
    t = 0.0
    if L2 > 0.0:
        t = ((x0 - ax) * dx + (x1 - ay) * dy + (x2 - az) * dz) / L2
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    return math.sqrt((x0 - ax - t * dx) ** 2 + (x1 - ay - t * dy) ** 2 + (x2 - az - t * dz) ** 2)


@njit(cache=True, inline="always")
def _pp(a, i, b, j):
    return math.sqrt((a[i, 0] - b[j, 0]) ** 2 + (a[i, 1] - b[j, 1]) ** 2 + (a[i, 2] - b[j, 2]) ** 2)


@njit(cache=True, inline="always")
def _dist_cc(i, j, a, b, seg):
    """Generalised distance between centres ``i`` and ``j`` (000 §5.2)."""
    if seg[i] and seg[j]:
        return min(min(_pp(a, i, a, j), _pp(a, i, b, j)), min(_pp(b, i, a, j), _pp(b, i, b, j)))
    if seg[j]:
        return _dist_x(a[i, 0], a[i, 1], a[i, 2], a, b, seg, j)
    return _dist_x(a[j, 0], a[j, 1], a[j, 2], a, b, seg, i)


@njit(cache=True, parallel=True)
def fill_distance_matrix(idx, a, b, seg, out):
    """Fill ``out (n, n)`` with the generalised distances between the centres ``idx (n,)`` (mm).

    ``a, b (N, 3)`` are the centres' ends and ``seg (N,)`` marks the segments; returns nothing.
    """
    n = idx.shape[0]
    for p in prange(n):
        for q in range(n):
            out[p, q] = _dist_cc(idx[p], idx[q], a, b, seg)


@njit(cache=True, parallel=True)
def fill_system(idx, a, b, seg, basis, c, inv_h, out):
    """Fill ``out (n, n)`` with ``A_pq = φ(‖l_p − l_q‖_L / h)`` over the centres ``idx (n,)``.

    ``basis`` is the kernel code (:data:`porecad.fields.rbf.BASES`), ``c`` the shape, ``inv_h``
    ``1 / h``; the matrix is symmetric (each pair computed once); returns nothing.
    """
    n = idx.shape[0]
    for p in prange(n):
        for q in range(p, n):
            v = _phi(_dist_cc(idx[p], idx[q], a, b, seg) * inv_h, basis, c)
            out[p, q] = v
            out[q, p] = v


@njit(cache=True, parallel=True)
def eval_global(X, a, b, seg, w, basis, c, inv_h, out):
    """Fill ``out (n,)`` with ``Φ`` at the points ``X (n, 3)``: weights ``w`` of every centre.

    Returns nothing; ``O(points × centres)``, parallel over the points.
    """
    n = X.shape[0]
    m = w.shape[0]
    for i in prange(n):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        s = 0.0
        for j in range(m):
            s += w[j] * _phi(_dist_x(x0, x1, x2, a, b, seg, j) * inv_h, basis, c)
        out[i] = s


@njit(cache=True, parallel=True)
def eval_local(X, cell, start, items, w, a, b, seg, basis, c, inv_h, out):
    """Fill ``out (n,)`` with ``Φ`` at the points ``X (n, 3)`` from the patch of each point's cell.

    ``cell (n,)`` is the cell of each point; cell ``k``'s centres are
    ``items[start[k]:start[k + 1]]`` with the weights ``w`` at the same positions. Returns nothing.
    """
    n = X.shape[0]
    for i in prange(n):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        k = cell[i]
        s = 0.0
        for q in range(start[k], start[k + 1]):
            s += w[q] * _phi(_dist_x(x0, x1, x2, a, b, seg, items[q]) * inv_h, basis, c)
        out[i] = s
