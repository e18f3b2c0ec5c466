"""Matrix-free periodic voxel finite elements and their geometric multigrid (numba kernels).

A periodic grid of ``nz × ny × nx`` cubic voxels has one node per voxel
(node ``(k, j, i)`` is the lower corner of voxel ``(k, j, i)``; indices wrap).
Vectors are float64 arrays of shape ``(nz, ny, nx, 3, m)``: three
displacement components for ``m`` right-hand sides solved together (the six
macro strains of a homogenisation). Voxel ``e`` has the 24 × 24 stiffness
``emat[eidx[e]]``, or none when ``eidx[e] < 0`` (void); node and element
ordering as in :mod:`porecad.simulate.hex8`.

The operator is applied element by element (never assembled: an assembled
matrix of a 128³ cell would need about 6 GB); voxels are swept in two
colours of z-slabs so that the two halves can run in parallel without write
conflicts.

Multigrid: trilinear prolongation ``P`` between grids of ``n`` and ``2n``
voxels per axis, restriction ``Pᵀ``, and exact Galerkin coarse operators
``Pᵀ K P``. Because trilinear interpolation inside a coarse voxel only uses
that voxel's eight nodes, ``Pᵀ K P`` is assembled from coarse *element*
matrices ``K_C = Σ_c P_cᵀ K_c P_c`` over the eight children ``c``; they are
stored per active coarse voxel (float32). This is the multigrid-preconditioned
CG of Amir, Aage & Lazarov (2014) on a periodic grid, with damped-Jacobi
smoothing.

References
----------
O. Amir, N. Aage, B. S. Lazarov, "On multigrid-CG for efficient topology
optimization", *Struct. Multidiscip. Optim.* 49 (2014) 815–829.
W. L. Briggs, V. E. Henson, S. F. McCormick, *A Multigrid Tutorial*, 2nd ed.,
SIAM 2000, ch. 3 (V-cycle, full weighting as the transpose of interpolation)
and ch. 8 (Galerkin coarse operators).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["apply_operator", "operator_diagonal", "scatter_element_loads", "element_energy",
           "prolong", "restrict", "coarse_element_matrices", "child_interpolation",
           "coldot", "axpy", "xpby"]


@njit(cache=True, inline="always")
def _gather(x, k, j, i, nz, ny, nx, m, xe):
    for a in range(8):
        kk = k + (a >> 2)
        if kk >= nz:
            kk -= nz
        jj = j + ((a >> 1) & 1)
        if jj >= ny:
            jj -= ny
        ii = i + (a & 1)
        if ii >= nx:
            ii -= nx
        for c in range(3):
            for q in range(m):
                xe[q, 3 * a + c] = x[kk, jj, ii, c, q]


@njit(cache=True, inline="always")
def _scatter(y, k, j, i, nz, ny, nx, m, ye):
    for a in range(8):
        kk = k + (a >> 2)
        if kk >= nz:
            kk -= nz
        jj = j + ((a >> 1) & 1)
        if jj >= ny:
            jj -= ny
        ii = i + (a & 1)
        if ii >= nx:
            ii -= nx
        for c in range(3):
            for q in range(m):
                y[kk, jj, ii, c, q] += ye[q, 3 * a + c]


@njit(cache=True, fastmath=True)
def _apply_plane(x, eidx, emat, y, k, xe, ye):
    nz, ny, nx = eidx.shape
    m = x.shape[4]
    for j in range(ny):
        for i in range(nx):
            e = eidx[k, j, i]
            if e < 0:
                continue
            K = emat[e]
            _gather(x, k, j, i, nz, ny, nx, m, xe)
            for q in range(m):
                for r in range(24):
                    acc = 0.0
                    for col in range(24):
                        acc += K[r, col] * xe[q, col]
                    ye[q, r] = acc
            _scatter(y, k, j, i, nz, ny, nx, m, ye)


@njit(parallel=True, cache=True)
def _apply_colour(x, eidx, emat, y, start):
    nz = eidx.shape[0]
    m = x.shape[4]
    n = (nz - start + 1) // 2
    for s in prange(n):
        xe = np.empty((m, 24))
        ye = np.empty((m, 24))
        _apply_plane(x, eidx, emat, y, start + 2 * s, xe, ye)


@njit(cache=True)
def _apply_serial(x, eidx, emat, y):
    m = x.shape[4]
    xe = np.empty((m, 24))
    ye = np.empty((m, 24))
    for k in range(eidx.shape[0]):
        _apply_plane(x, eidx, emat, y, k, xe, ye)


def apply_operator(x, eidx, emat, out=None):
    """``y = K x`` for the periodic voxel operator (element by element).

    Parameters
    ----------
    x : (nz, ny, nx, 3, m) float64
    eidx : (nz, ny, nx) int32
        Matrix index of each voxel in ``emat``, ``-1`` for void.
    emat : (M, 24, 24) float array
    out : array like ``x``, optional

    Returns
    -------
    (nz, ny, nx, 3, m) float64
    """
    y = np.zeros_like(x) if out is None else out
    if out is not None:
        y[...] = 0.0
    nz = eidx.shape[0]
    if nz % 2 == 0:
        _apply_colour(x, eidx, emat, y, 0)
        _apply_colour(x, eidx, emat, y, 1)
    else:  # an odd periodic layer count cannot be two-coloured
        _apply_serial(x, eidx, emat, y)
    return y


@njit(cache=True)
def operator_diagonal(eidx, emat):
    """(nz, ny, nx, 3) diagonal of the operator (zero at nodes of void voxels only)."""
    nz, ny, nx = eidx.shape
    d = np.zeros((nz, ny, nx, 3))
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                e = eidx[k, j, i]
                if e < 0:
                    continue
                for a in range(8):
                    kk = (k + (a >> 2)) % nz
                    jj = (j + ((a >> 1) & 1)) % ny
                    ii = (i + (a & 1)) % nx
                    for c in range(3):
                        d[kk, jj, ii, c] += emat[e, 3 * a + c, 3 * a + c]
    return d


@njit(cache=True)
def scatter_element_loads(eidx, loads, m):
    """Assemble per-matrix element load vectors ``loads[eidx[e]]`` (24, m) into a node vector."""
    nz, ny, nx = eidx.shape
    y = np.zeros((nz, ny, nx, 3, m))
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                e = eidx[k, j, i]
                if e >= 0:
                    _scatter(y, k, j, i, nz, ny, nx, m, loads[e].T)
    return y


@njit(parallel=True, cache=True)
def element_energy(x, eidx, emat, uaff):
    """``Σ_e (uaff + x_e)ᵀ K_e (uaff + x_e)`` as an (m, m) matrix (``uaff`` (24, m) per voxel)."""
    nz, ny, nx = eidx.shape
    m = x.shape[4]
    part = np.zeros((nz, m, m))
    for k in prange(nz):
        xe = np.empty((m, 24))
        ke = np.empty((m, 24))
        for j in range(ny):
            for i in range(nx):
                e = eidx[k, j, i]
                if e < 0:
                    continue
                _gather(x, k, j, i, nz, ny, nx, m, xe)
                for r in range(24):
                    for q in range(m):
                        xe[q, r] += uaff[r, q]
                K = emat[e]
                for q in range(m):
                    for r in range(24):
                        s = 0.0
                        for col in range(24):
                            s += K[r, col] * xe[q, col]
                        ke[q, r] = s
                for p in range(m):
                    for q in range(m):
                        s = 0.0
                        for r in range(24):
                            s += xe[p, r] * ke[q, r]
                        part[k, p, q] += s
    return part.sum(axis=0)


def prolong(xc):
    """Trilinear interpolation of a periodic node vector to the grid of twice the voxels per axis."""
    out = xc
    for ax in range(3):
        n = out.shape[ax]
        shape = list(out.shape)
        shape[ax] = 2 * n
        f = np.empty(shape, dtype=out.dtype)
        even = [slice(None)] * out.ndim
        odd = [slice(None)] * out.ndim
        even[ax] = slice(0, None, 2)
        odd[ax] = slice(1, None, 2)
        f[tuple(even)] = out
        f[tuple(odd)] = 0.5 * (out + np.roll(out, -1, axis=ax))
        out = f
    return out


def restrict(xf):
    """The transpose of :func:`prolong` (full weighting times 8)."""
    out = xf
    for ax in range(3):
        even = [slice(None)] * out.ndim
        odd = [slice(None)] * out.ndim
        even[ax] = slice(0, None, 2)
        odd[ax] = slice(1, None, 2)
        o = out[tuple(odd)]
        out = out[tuple(even)] + 0.5 * (o + np.roll(o, 1, axis=ax))
    return out


def child_interpolation() -> np.ndarray:
    """(8, 8, 8): ``N[c, b, A]``, the weight of coarse node ``A`` at node ``b`` of child voxel ``c``."""
    N = np.zeros((8, 8, 8))
    for c in range(8):
        co = (c & 1, (c >> 1) & 1, c >> 2)
        for b in range(8):
            t = [co[0] + (b & 1), co[1] + ((b >> 1) & 1), co[2] + (b >> 2)]  # in [0, 2]
            for A in range(8):
                Ao = (A & 1, (A >> 1) & 1, A >> 2)
                w = 1.0
                for d in range(3):
                    w *= t[d] / 2.0 if Ao[d] else 1.0 - t[d] / 2.0
                N[c, b, A] = w
    return N


@njit(cache=True)
def _triple(K, N, out):
    """out += (N ⊗ I3)ᵀ K (N ⊗ I3) with N (8, 8) and K (24, 24)."""
    tmp = np.zeros((24, 24))
    for r in range(24):
        for B in range(8):
            for j in range(3):
                s = 0.0
                for b in range(8):
                    s += K[r, 3 * b + j] * N[b, B]
                tmp[r, 3 * B + j] = s
    for A in range(8):
        for i in range(3):
            for col in range(24):
                s = 0.0
                for a in range(8):
                    s += N[a, A] * tmp[3 * a + i, col]
                out[3 * A + i, col] += s


@njit(cache=True)
def _coarse_index(eidx):
    nz, ny, nx = eidx.shape
    cz, cy, cx = nz // 2, ny // 2, nx // 2
    cidx = np.full((cz, cy, cx), -1, dtype=np.int32)
    n = 0
    for k in range(cz):
        for j in range(cy):
            for i in range(cx):
                act = False
                for c in range(8):
                    if eidx[2 * k + (c >> 2), 2 * j + ((c >> 1) & 1), 2 * i + (c & 1)] >= 0:
                        act = True
                if act:
                    cidx[k, j, i] = n
                    n += 1
    return cidx, n


@njit(parallel=True, cache=True)
def _coarse_from_table(eidx, cidx, n, table):
    """Coarse element matrices as sums of precomputed child contributions ``table[c, fine matrix]``."""
    cz, cy, cx = cidx.shape
    out = np.zeros((n, 24, 24), dtype=np.float32)
    for k in prange(cz):
        acc = np.empty((24, 24))
        for j in range(cy):
            for i in range(cx):
                E = cidx[k, j, i]
                if E < 0:
                    continue
                acc[:, :] = 0.0
                for c in range(8):
                    e = eidx[2 * k + (c >> 2), 2 * j + ((c >> 1) & 1), 2 * i + (c & 1)]
                    if e >= 0:
                        acc += table[c, e]
                out[E] = acc.astype(np.float32)
    return out


@njit(parallel=True, cache=True)
def _coarse_from_fine(eidx, emat, cidx, n, N):
    cz, cy, cx = cidx.shape
    out = np.zeros((n, 24, 24), dtype=np.float32)
    for k in prange(cz):
        acc = np.empty((24, 24))
        Kf = np.empty((24, 24))
        for j in range(cy):
            for i in range(cx):
                E = cidx[k, j, i]
                if E < 0:
                    continue
                acc[:, :] = 0.0
                for c in range(8):
                    e = eidx[2 * k + (c >> 2), 2 * j + ((c >> 1) & 1), 2 * i + (c & 1)]
                    if e >= 0:
                        for r in range(24):
                            for s in range(24):
                                Kf[r, s] = emat[e, r, s]
                        _triple(Kf, N[c], acc)
                out[E] = acc.astype(np.float32)
    return out


def coarse_element_matrices(eidx, emat):
    """Galerkin element matrices of the grid with half the voxels per axis.

    Parameters
    ----------
    eidx : (nz, ny, nx) int32, every dimension even
    emat : (M, 24, 24) float array

    Returns
    -------
    cidx : (nz/2, ny/2, nx/2) int32
        Index of each coarse voxel's matrix, ``-1`` where all eight children are void.
    cmat : (n, 24, 24) float32
        ``K_C = Σ_c P_cᵀ K_c P_c`` over the children ``c`` (exact Galerkin).
    """
    N = child_interpolation()
    cidx, n = _coarse_index(eidx)
    if len(emat) <= 16:  # a few material phases: tabulate each child's contribution once
        table = np.zeros((8, len(emat), 24, 24))
        for c in range(8):
            for e in range(len(emat)):
                _triple(np.ascontiguousarray(emat[e], dtype=np.float64), N[c], table[c, e])
        return cidx, _coarse_from_table(eidx, cidx, n, table)
    return cidx, _coarse_from_fine(eidx, emat, cidx, n, N)


@njit(parallel=True, cache=True)
def coldot(a, b):
    """Column-wise dot products of two ``(..., m)`` arrays given as 2-D ``(rows, m)`` views."""
    rows, m = a.shape
    nb = 64
    part = np.zeros((nb, m))
    step = (rows + nb - 1) // nb
    for t in prange(nb):
        lo = t * step
        hi = min(rows, lo + step)
        for r in range(lo, hi):
            for q in range(m):
                part[t, q] += a[r, q] * b[r, q]
    return part.sum(axis=0)


@njit(parallel=True, cache=True)
def axpy(y, alpha, x):
    """``y[:, q] += alpha[q] * x[:, q]`` in place (2-D views)."""
    rows, m = y.shape
    for r in prange(rows):
        for q in range(m):
            y[r, q] += alpha[q] * x[r, q]


@njit(parallel=True, cache=True)
def xpby(x, beta, p):
    """``p[:, q] = x[:, q] + beta[q] * p[:, q]`` in place (2-D views)."""
    rows, m = p.shape
    for r in prange(rows):
        for q in range(m):
            p[r, q] = x[r, q] + beta[q] * p[r, q]
