"""Umbrella-operator (Laplacian) and Taubin smoothing of triangle meshes.

Both smoothers only move vertices; the faces array is never touched, so the
connectivity, and with it closedness, manifoldness and orientation, is exactly
that of the input.  (Geometry can still degrade: many strong iterations on a
coarse mesh may flip thin triangles; check with
:func:`porecad.mesh.validate.self_intersections` when that matters, and
smooth a solid with :func:`smooth_solid`, which stops before a step folds it.)

The uniform one-ring Laplacian (umbrella operator) of vertex ``i`` with
neighbours ``N(i)`` (vertices sharing an edge with ``i``) is

.. math:: \\Delta v_i = \\frac{1}{|N(i)|} \\sum_{j \\in N(i)} v_j - v_i ,

and one smoothing step moves every vertex a fraction ``lambda`` of the way to
its neighbours' centroid,

.. math:: v_i \\leftarrow v_i + \\lambda \\, \\Delta v_i, \\qquad 0 < \\lambda < 1

(document 004, eqs. 4-5; [1]_).  Repeated steps shrink the mesh.  Taubin's
``lambda|mu`` scheme ([2]_) alternates a shrinking step ``lambda > 0`` with an
inflating step ``mu < -lambda``; it is a low-pass filter with pass-band
frequency ``k_PB = 1/lambda + 1/mu`` (> 0), which removes noise without the
shrinkage.

References
----------
.. [1] J. Vollmer, R. Mencl, H. Müller, "Improved Laplacian smoothing of noisy
   surface meshes", Computer Graphics Forum 18(3), 1999.
.. [2] G. Taubin, "A signal processing approach to fair surface design",
   SIGGRAPH 1995, pp. 351-358.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from porecad.errors import InputError
from porecad.mesh.operators import edge_cotangent_weights, edge_index

__all__ = ["umbrella_matrix", "laplacian_smooth", "taubin_smooth", "smooth_solid", "curvature_smooth"]


def _check(vertices, faces, fixed):
    v = np.asarray(vertices)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"vertices must have shape (V, 3), got {v.shape}")
    v = np.array(v, dtype=np.float64)  # always a copy: the input is not modified
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must have shape (F, 3), got {f.shape}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise InputError(f"faces must be integers, got dtype {f.dtype}")
    f = f.astype(np.int64, copy=False)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise InputError("faces reference vertices outside 0..V-1")
    if fixed is None:
        movable = np.ones(len(v), bool)
    else:
        fx = np.asarray(fixed)
        if fx.dtype != bool or fx.shape != (len(v),):
            raise InputError(f"fixed must be a boolean mask of shape ({len(v)},)")
        movable = ~fx
    return v, f, movable


def _prepare(vertices, faces, iterations, lam, fixed):
    """Shared argument checks: ``(v, f, movable, iterations)``; iterations 0 means nothing to do."""
    if not 0.0 < lam < 1.0:
        raise InputError(f"lam must lie in (0, 1), got {lam}")
    iterations = _check_iterations(iterations)
    v, f, movable = _check(vertices, faces, fixed)
    return v, f, movable, (0 if len(f) == 0 else iterations)


def _check_iterations(iterations):
    if int(iterations) != iterations or iterations < 0:
        raise InputError(f"iterations must be a non-negative integer, got {iterations}")
    return int(iterations)


def umbrella_matrix(faces, n_vertices):
    """Row-stochastic one-ring averaging matrix ``W`` (CSR).

    ``W[i, j] = 1/|N(i)|`` for every edge neighbour ``j`` of ``i``, so that
    ``(W @ V - V)[i]`` is the umbrella Laplacian ``Delta v_i``.  Built
    vectorised: the three edges of every face in both directions form a COO
    matrix, duplicates (edges shared by two faces) are merged by setting every
    stored value to 1, and rows are scaled by the inverse degree.  Rows of
    isolated vertices are zero.

    Parameters
    ----------
    faces : (F, 3) int array
    n_vertices : int

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n_vertices, n_vertices)
    """
    f = np.asarray(faces, dtype=np.int64)
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    keep = i != j  # degenerate faces contribute no self loops
    a = sp.csr_matrix(
        (np.ones(int(keep.sum())), (i[keep], j[keep])), shape=(n_vertices, n_vertices)
    )
    a.sum_duplicates()
    a.data[:] = 1.0
    deg = np.diff(a.indptr).astype(np.float64)
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    return sp.csr_matrix(sp.diags(inv) @ a)


def _step_factors(faces, n_vertices, movable):
    w = umbrella_matrix(faces, n_vertices)
    # isolated and fixed vertices do not move (for isolated ones W v - v = -v)
    movable = movable & (np.diff(w.indptr) > 0)
    return w, movable.astype(np.float64)[:, None]


def laplacian_smooth(vertices, faces, iterations=10, lam=0.5, fixed=None):
    """Uniform Laplacian (umbrella) smoothing.

    Applies ``iterations`` times ``v_i <- v_i + lam * Delta v_i`` with the
    umbrella operator ``Delta v_i = mean_{j in N(i)} v_j - v_i`` (document
    004, eqs. 4-5), all vertices at once (Jacobi).  Only vertices move; the
    faces, hence topology and closedness, are unchanged.  The mesh shrinks
    with every step; see :func:`taubin_smooth`.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
    iterations : int
        Number of steps (0 returns a copy).
    lam : float
        Smoothing weight, ``0 < lam < 1``.
    fixed : (V,) bool array, optional
        Vertices that must not move (e.g. those on the flat caps of a box).

    Returns
    -------
    (V, 3) float64 array
        New vertex positions; the input is not modified.
    """
    v, f, movable, iterations = _prepare(vertices, faces, iterations, lam, fixed)
    if iterations == 0:
        return v
    w, m = _step_factors(f, len(v), movable)
    return _iterate(v, w, (lam * m,), iterations)[0]


def taubin_smooth(vertices, faces, iterations=10, lam=0.5, mu=-0.53, fixed=None):
    """Taubin lambda|mu smoothing, without shrinkage.

    Each iteration is a shrinking umbrella step with ``lam`` followed by an
    inflating one with ``mu``:

    .. math:: v \\leftarrow v + \\lambda \\Delta v, \\qquad v \\leftarrow v + \\mu \\Delta v,

    with ``0 < lam < 1`` and ``mu < -lam`` (Taubin 1995, [2]_).  The transfer
    function ``(1 - lam k)(1 - mu k)`` per iteration passes low frequencies
    ``k < k_PB = 1/lam + 1/mu`` (0.113 for the defaults) and damps high ones.
    Only vertices move; the faces, hence topology and closedness, are
    unchanged.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
    iterations : int
        Number of lambda|mu pairs.
    lam : float
        Positive (shrinking) weight, ``0 < lam < 1``.
    mu : float
        Negative (inflating) weight, ``-1 < mu < -lam``.
    fixed : (V,) bool array, optional
        Vertices that must not move.

    Returns
    -------
    (V, 3) float64 array
        New vertex positions; the input is not modified.
    """
    v, f, movable, iterations = _prepare(vertices, faces, iterations, lam, fixed)
    if not (mu < -lam and mu > -1.0):
        raise InputError(f"mu must satisfy -1 < mu < -lam = {-lam}, got {mu}")
    if iterations == 0:
        return v
    w, m = _step_factors(f, len(v), movable)
    return _iterate(v, w, (lam * m, mu * m), iterations)[0]


def smooth_solid(vertices, faces, method: str = "taubin", iterations: int = 10, fixed=None, lam=0.5, mu=-0.53):
    """:func:`taubin_smooth` or :func:`laplacian_smooth` (``method``) of a closed solid, stopped before it folds.

    The steps run one at a time and each is kept only while no face has
    turned against its starting orientation and the enclosed volume stays
    positive: many Taubin steps do fold a surface (its transfer function
    exceeds 1 by up to ``(lam + mu)² / (-4 lam mu)`` inside the pass band,
    so those frequencies grow without bound). Returns ``(vertices, steps)``,
    the new positions and the number of iterations kept (fewer than
    ``iterations`` when the next would have folded the solid).

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(2)
    >>> v, steps = smooth_solid(s.vertices, s.faces, "taubin", iterations=5)
    >>> steps
    5
    """
    if method not in ("taubin", "laplacian"):
        raise InputError(f"smoothing method must be taubin or laplacian, got {method!r}")
    v, f, movable, iterations = _prepare(vertices, faces, iterations, lam, fixed)
    if method == "taubin" and not -1.0 < mu < -lam:
        raise InputError(f"mu must satisfy -1 < mu < -lam = {-lam}, got {mu}")
    if iterations == 0:
        return v, 0
    w, m = _step_factors(f, len(v), movable)
    start = _face_normals(v, f)

    def unfolded(x):
        n = _face_normals(x, f)
        return bool(np.einsum("ij,ij->i", n, start).min() >= 0 and np.einsum("ij,ij->", x[f[:, 0]], n) > 0)

    return _iterate(v, w, (lam * m, mu * m) if method == "taubin" else (lam * m,), iterations, unfolded)


def _face_normals(v, f):
    """Unnormalised face normals (twice the areas), ``(F, 3)``."""
    return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])


def _iterate(v, w, factors, iterations: int, keep=None):
    """``iterations`` times the umbrella steps ``v += a * (W v - v)``, one per factor ``a`` (a per-vertex column);
    with ``keep(v) -> bool``, stop before the first iteration whose result it refuses. Returns ``(v, done)``."""
    for done in range(iterations):
        new = v.copy() if keep is not None else v
        for a in factors:
            new += a * (w @ new - new)
        if keep is not None and not keep(new):
            return v, done
        v = new
    return v, iterations


def curvature_smooth(vertices, faces, iterations=5, lam=0.5, fixed=None):
    """Curvature-based smoothing: explicit mean-curvature flow with cotangent weights.

    ``v_i <- v_i + lam * (Σ_j w_ij v_j / Σ_j w_ij - v_i)`` with the cotangent
    weights ``w_ij = (cot α_ij + cot β_ij) / 2`` (Pinkall & Polthier 1993;
    :func:`porecad.mesh.operators.edge_cotangent_weights`), negative ones
    (obtuse angles) clipped to zero so each step is a convex combination,
    recomputed every step; a vertex whose weights are all clipped stays. The cotangent
    Laplacian is ``-2 H n`` times the vertex area, so the step moves a vertex
    along its normal by its mean curvature and (unlike the umbrella operator)
    hardly slides it tangentially (Desbrun et al., SIGGRAPH 1999). Used with
    :func:`taubin_smooth` for the TIS networks of 002 §4 ("Laplacian smoothing
    and curvature-based smoothing"). Only vertices move.
    """
    v, f, movable, iterations = _prepare(vertices, faces, iterations, lam, fixed)
    if iterations == 0:
        return v
    m = lam * movable.astype(np.float64)[:, None]
    n = len(v)
    index = edge_index(f, n)  # the edges once; only their weights change from step to step
    i, j = index[:2]
    for _ in range(iterations):
        w = np.maximum(edge_cotangent_weights(v, f, index)[2], 0.0)
        s = np.bincount(i, w, n) + np.bincount(j, w, n)
        mean = np.column_stack([np.bincount(i, w * v[j, c], n) + np.bincount(j, w * v[i, c], n) for c in range(3)])
        has = s > 0
        v += m * has[:, None] * (mean / np.where(has, s, 1.0)[:, None] - v)
    return v
