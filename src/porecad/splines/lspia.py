"""Fitting trivariate B-splines to grid data: LSPIA, direct least squares, local LSPIA.

LSPIA, the least-squares progressive-iterative approximation of Deng & Lin
(2014, *Computer-Aided Design* 47, 32-44), as used by 001 §3.2, eqs. (6)-(10):
with data ``Q_j`` at the grid vertices ``j`` of parameters ``t_j`` and the
spline ``P^k(t) = Σ_i B_i(t) P^k_i`` after ``k`` steps,

.. math::

    δ^k_j = Q_j - P^k(t_j), \\qquad
    Δ^k_i = \\frac{\\sum_{j \\in I_i} B_i(t_j) δ^k_j}{\\sum_{j \\in I_i} B_i(t_j)}, \\qquad
    P^{k+1}_i = P^k_i + Δ^k_i,

where ``I_i`` are the vertices at which ``B_i`` is non-zero. In matrix form
``P^{k+1} = P^k + D^{-1} B^T (Q - B P^k)`` with ``D = diag(column sums of B)``.
Because the basis is a partition of unity, the rows of ``D^{-1} B^T B`` sum
to 1, its eigenvalues lie in ``[0, 1]``, the residual norm never increases,
and the iteration converges to the least-squares fit (Deng & Lin, Thm. 2).

On a grid ``B = B^u ⊗ B^v ⊗ B^w`` and ``D = D^u ⊗ D^v ⊗ D^w``, so both
products are applied one axis at a time (:func:`~porecad.splines.volume.tensor_apply`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .basis import basis_functions, basis_matrix, greville, tensor_basis_matrix
from .knots import clamped_uniform_knots
from .volume import BSplineVolume, as3, tensor_apply

__all__ = ["FitReport", "fit_envelope", "fit_grid", "fit_grid_lstsq", "local_lspia"]

_AXES = ("u", "v", "w")


@dataclass
class FitReport:
    """Outcome of an LSPIA fit.

    Attributes
    ----------
    iterations : int
        LSPIA steps taken.
    converged : bool
        The relative decrease of the rms residual fell below ``tol`` (or the
        residual vanished) before ``max_iter`` steps.
    rms_history : list of float
        rms of ``|δ_j|`` over the fitted vertices, before the first step and after every step.
    max_error : float
        Largest ``|δ_j|`` after the last step.
    rms : float
        Final rms (``rms_history[-1]``).
    """

    iterations: int
    converged: bool
    rms_history: list = field(default_factory=list)
    max_error: float = 0.0
    rms: float = 0.0


# ---------------------------------------------------------------- helpers
def _grid_values(values):
    q = np.asarray(values, dtype=np.float64)
    if q.ndim == 3:
        q = q[..., None]
    if q.ndim != 4:
        raise InputError(f"grid data must be an (N1, N2, N3) or (N1, N2, N3, d) array, got shape {q.shape}")
    if min(q.shape[:3]) < 2:
        raise InputError(f"grid data needs at least 2 vertices per axis, got {q.shape[:3]}")
    if not np.all(np.isfinite(q)):
        raise InputError("grid data has non-finite values")
    return q


def _grid_params(params, shape):
    """Per-axis parameters: default the normalised grid indices ``i / (N - 1)`` (001 §3.2)."""
    if params is None:
        return [np.linspace(0.0, 1.0, n) for n in shape]
    if len(params) != 3:
        raise InputError(f"need 3 parameter arrays (u, v, w), got {len(params)}")
    out = []
    for a, (t, n) in enumerate(zip(params, shape)):
        t = np.asarray(t, dtype=np.float64).ravel()
        if t.size != n:
            raise InputError(f"{n} grid vertices along {_AXES[a]} but {t.size} parameters")
        if not np.all(np.isfinite(t)) or t.min() < 0.0 or t.max() > 1.0:
            raise InputError(f"parameters along {_AXES[a]} must lie in [0, 1]")
        if np.any(np.diff(t) <= 0):
            raise InputError(f"parameters along {_AXES[a]} must be strictly increasing")
        out.append(t)
    return out


def _interp_matrix(t, x):
    """Dense ``(len(x), len(t))`` matrix of piecewise-linear interpolation from nodes ``t`` to ``x``."""
    i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
    f = np.clip((x - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0)
    m = np.zeros((len(x), len(t)))
    rows = np.arange(len(x))
    m[rows, i] = 1.0 - f
    m[rows, i + 1] += f
    return m


def _rms(delta):
    """rms of ``|δ_j|`` over the vertices (sum of squares by one BLAS dot product)."""
    flat = delta.reshape(-1)
    npts = max(1, delta.size // delta.shape[-1])
    return float(np.sqrt(np.dot(flat, flat) / npts))


def _maxerr(delta):
    return float(np.sqrt(np.max(np.sum(delta * delta, axis=-1)))) if delta.size else 0.0


def _setup(values, n_ctrl, degree, params):
    q = _grid_values(values)
    n = as3(n_ctrl, "n_ctrl")
    p = as3(degree, "degree")
    t = _grid_params(params, q.shape[:3])
    knots = [clamped_uniform_knots(n[a], p[a]) for a in range(3)]
    return q, n, p, t, knots


# ---------------------------------------------------------------- global fits
def fit_grid(values, n_ctrl, degree=3, params=None, tol: float = 1e-6, max_iter: int = 500,
             init: str = "interpolate"):
    """Fit a B-spline volume to grid data by LSPIA (001 eqs. (6)-(10)).

    Parameters
    ----------
    values : (N1, N2, N3) or (N1, N2, N3, d) float array
        Data ``Q_j`` at the grid vertices.
    n_ctrl : int or 3 ints
        Control grid resolution.
    degree : int or 3 ints
    params : 3 arrays or None
        Strictly increasing parameters in ``[0, 1]`` per axis; default the
        normalised grid indices (001 §3.2).
    tol : float
        Stop when the relative decrease of the rms residual per step is below ``tol``.
    max_iter : int
    init : {"interpolate", "zero"}
        Initial control values: the data linearly interpolated at the Greville
        abscissae of the control points (001: "produced by linear
        interpolation of the discrete TDF"), or zero.

    Returns
    -------
    volume : BSplineVolume
        Uniform clamped knots; ``d = 1`` for 3-D ``values``.
    report : FitReport
    """
    q, n, p, t, knots = _setup(values, n_ctrl, degree, params)
    if init not in ("interpolate", "zero"):
        raise InputError(f"unknown LSPIA initialisation {init!r}; use 'interpolate' or 'zero'")
    if max_iter < 0:
        raise InputError(f"max_iter must be >= 0, got {max_iter}")
    B = [basis_matrix(knots[a], p[a], t[a]) for a in range(3)]
    BT = [b.T.tocsr() for b in B]
    colsum = [np.asarray(b.sum(axis=0)).ravel() for b in B]
    den = colsum[0][:, None, None] * colsum[1][None, :, None] * colsum[2][None, None, :]
    inv = np.where(den > 0, 1.0 / np.where(den > 0, den, 1.0), 0.0)[..., None]
    if init == "interpolate":
        L = [_interp_matrix(t[a], greville(knots[a], p[a])) for a in range(3)]
        P = tensor_apply(L, q)
    else:
        P = np.zeros(tuple(n) + (q.shape[3],))
    def residual(P):
        delta = tensor_apply(B, P)
        return np.subtract(q, delta, out=delta)

    delta = residual(P)
    hist = [_rms(delta)]
    converged = hist[0] == 0.0
    it = 0
    while not converged and it < max_iter:
        step = tensor_apply(BT, delta)
        step *= inv
        P += step
        delta = residual(P)
        hist.append(_rms(delta))
        it += 1
        prev, cur = hist[-2], hist[-1]
        if cur == 0.0 or (prev - cur) < tol * prev:
            converged = True
    vol = BSplineVolume(P, p, knots)
    return vol, FitReport(iterations=it, converged=bool(converged), rms_history=hist,
                          max_error=_maxerr(delta), rms=hist[-1])


def fit_grid_lstsq(values, n_ctrl, degree=3, params=None) -> BSplineVolume:
    """Least-squares fit of a B-spline volume to grid data, solved per axis.

    Minimises ``Σ_j |Q_j - Σ_i B_i(t_j) P_i|²``. With ``B = B^u ⊗ B^v ⊗ B^w`` of
    full column rank the normal equations factor: ``P = (B^{u+} ⊗ B^{v+} ⊗
    B^{w+}) Q`` with ``B^+ = (B^T B)^{-1} B^T``, so the exact least-squares
    solution costs three small solves (used for construction, where the data
    is an analytic map sampled on a grid).

    Raises
    ------
    InputError
        When an axis has fewer distinct parameters than control points or the
        parameters leave a control point without data (Schoenberg-Whitney
        condition fails).
    """
    q, n, p, t, knots = _setup(values, n_ctrl, degree, params)
    pinv = []
    for a in range(3):
        if len(t[a]) < n[a]:
            raise InputError(f"{len(t[a])} grid vertices along {_AXES[a]} cannot determine "
                             f"{n[a]} control points")
        b = basis_matrix(knots[a], p[a], t[a]).toarray()
        g = b.T @ b
        if np.linalg.cond(g) > 1e12:
            raise InputError(f"the parameters along {_AXES[a]} leave some control points without "
                             "data (Schoenberg-Whitney condition fails)")
        pinv.append(np.linalg.solve(g, b.T))
    return BSplineVolume(tensor_apply(pinv, q), p, knots)


def fit_envelope(values, points, normals, point_params, n_ctrl, degree=3, params=None, weight: float = 1.0,
                 iterations: int = 3, relax: float = 1.0, boundary_weight: float = 1.0, hold=None, cache=None):
    """Least-squares B-spline volume through grid data and scattered surface points, pushed out over the points.

    Minimises ``Σ_j |Q_j - P(t_j)|² + ω Σ_k |X'_k - P(s_k)|²`` over the grid
    data ``Q`` and the targets ``X'`` of the scattered points ``X`` at their
    parameters ``s`` (``ω`` = ``weight`` × the number of grid boundary
    vertices / the number of points, so that the points weigh as much as
    ``weight`` times the grid's boundary). A least-squares fit cuts the
    corners of a body between its samples (a tip, an ear, a condyle); so, an
    ``iterations`` times, the targets of the points the fit passes inside of
    (``(X_k - P(s_k)) · n_k > 0`` with outward unit ``normals``) are moved
    out along their normals by ``relax`` times that depth and the fit is
    solved again (one sparse factorisation, new right-hand sides). Points
    the fit passes outside of keep their targets: concave parts are not
    inflated, so the fit does not overlap itself there as a uniform offset
    does.

    Parameters
    ----------
    values : (N1, N2, N3, 3) float
        Grid data (its boundary slices on the surface).
    points, normals : (m, 3) float
        Surface points and their outward unit normals.
    point_params : (m, 3) float
        Their parameters in ``[0, 1]³``.
    n_ctrl, degree, params
        As :func:`fit_grid_lstsq`.
    weight : float
        Weight of all points together, relative to the grid's boundary vertices.
    boundary_weight : float
        Weight of each grid boundary vertex (interior ones: 1).
    iterations : int
        Push-out steps (0: the plain least-squares fit to grid and points).
    relax : float
        Over-relaxation of each push (1: by the depth the fit passes inside).
    hold : (m,) bool, optional
        Points that stay targets as they are (never pushed out).
    cache : dict, optional
        Kept between calls with the same grid data, points, parameters and
        weights (only ``iterations``, ``relax`` and ``hold`` differ): the
        normal equations are made and factorised once.

    Returns
    -------
    volume : BSplineVolume
    info : dict
        ``undercut_before``, ``undercut`` (largest depth, mm, by which the
        fit passes inside a point, before the pushes and after),
        ``iterations``, ``points``.
    """
    q, n, p, t, knots, X, nrm, S, it_max = _envelope_inputs(values, points, normals, point_params, n_ctrl,
                                                           degree, params, weight, iterations, relax,
                                                           boundary_weight)
    if cache is None or "system" not in cache:
        system = _envelope_system(q, p, t, knots, S, weight, boundary_weight, len(X))
        if cache is not None:
            cache["system"] = system
    lu, rhs_grid, A, w = system if cache is None else cache["system"]
    P, before, under, k = _pushed_out(lu, rhs_grid, A, w, X, nrm, hold, it_max, relax)
    return BSplineVolume(P.reshape(tuple(n) + (3,)), p, knots), {
        "undercut_before": before, "undercut": under, "iterations": k, "points": int(len(X))}


def _envelope_inputs(values, points, normals, point_params, n_ctrl, degree, params, weight, iterations, relax,
                     boundary_weight):
    """:func:`fit_envelope`'s arguments checked: ``(q, n, p, t, knots)`` of :func:`_setup`, the points,
    normals and parameters as ``(m, 3)`` float arrays and the number of pushes (int)."""
    q, n, p, t, knots = _setup(values, n_ctrl, degree, params)
    X = np.asarray(points, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    S = np.asarray(point_params, np.float64).reshape(-1, 3)
    if not (len(X) == len(nrm) == len(S)) or q.shape[3] != 3:
        raise InputError("fit_envelope needs 3-D grid data and as many points, normals and parameters")
    if not (np.all(np.isfinite(S)) and S.min() >= 0.0 and S.max() <= 1.0 and np.all(np.isfinite(X))):
        raise InputError("point parameters must lie in [0, 1] and points be finite")
    it_max = int(iterations)
    if not 0 <= it_max <= 100 or not (np.isfinite(relax) and 0 < relax <= 4) or \
            not (np.isfinite(weight) and weight >= 0) or not (np.isfinite(boundary_weight) and boundary_weight > 0):
        raise InputError("fit_envelope: iterations 0..100, relax in (0, 4], weight >= 0, boundary_weight > 0")
    return q, n, p, t, knots, X, nrm, S, it_max


def _envelope_system(q, p, t, knots, S, weight, boundary_weight, n_points):
    """The normal equations of the fit to the grid data ``q`` and ``n_points`` points at parameters ``S``:
    ``(lu, rhs_grid, A, w)``, the factorised matrix, the grid's right-hand side, the points' collocation
    matrix and their weight ``ω``."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu
    shape = q.shape[:3]
    grid_uvw = np.stack(np.meshgrid(*t, indexing="ij"), axis=-1).reshape(-1, 3)
    on = np.zeros(shape, bool)
    on[[0, -1]] = on[:, [0, -1]] = on[:, :, [0, -1]] = True
    # the grid's boundary nodes sample the surface the points give in full: a weight below 1 lets the pushes
    # move the fit further (and bulge it more between the points it pushes out for)
    gw = np.where(on.ravel(), float(boundary_weight), 1.0)
    Ag = tensor_basis_matrix(knots, p, grid_uvw)
    M = Ag.T @ sp.diags(gw) @ Ag
    rhs_grid = Ag.T @ (gw[:, None] * q.reshape(-1, 3))
    A = tensor_basis_matrix(knots, p, S)
    n_boundary = int(on.sum())
    w = float(weight) * n_boundary / max(n_points, 1)
    try:
        lu = splu((M + w * (A.T @ A)).tocsc())
    except RuntimeError as err:
        raise InputError(f"the envelope fit's normal equations are singular ({err})") from None
    return lu, rhs_grid, A, w


def _pushed_out(lu, rhs_grid, A, w, X, nrm, hold, it_max, relax):
    """Solve, and up to ``it_max`` times move the targets of the points ``X`` the fit passes inside of (not
    those in ``hold``) out along ``nrm`` by ``relax`` times that depth and solve again. Returns ``(P,
    undercut before, undercut after, pushes)``: the control points ``(n, 3)`` and the largest depths (mm)."""
    target = X.copy()
    free = np.ones(len(X)) if hold is None else (~np.asarray(hold, bool).reshape(-1)).astype(np.float64)
    if len(free) != len(X):
        raise InputError("fit_envelope: hold needs one flag per point")
    before = None
    for k in range(it_max + 1):
        rhs = rhs_grid + w * (A.T @ target)
        P = np.stack([lu.solve(rhs[:, c]) for c in range(3)], axis=1)
        depth = np.einsum("ij,ij->i", X - A @ P, nrm)
        under = float(max(depth.max(), 0.0)) if len(depth) else 0.0
        before = under if before is None else before
        if k == it_max or under == 0.0:
            break
        target += (free * relax * np.maximum(depth, 0.0))[:, None] * nrm
    return P, before, under, k


# ---------------------------------------------------------------- local modification
def local_lspia(volume: BSplineVolume, values, edited, params=None, max_iter: int = 200,
                tol: float = 1e-8):
    """Local LSPIA (001 §3.2, "Local modification"): refit only near edited grid vertices.

    The differences ``δ_j`` (eq. (7)) are computed only at the edited
    vertices ``E``; a control point moves only if the difference of some
    edited vertex is distributed to it, i.e. ``B_i(t_j) > 0`` for some
    ``j ∈ E``, by ``Δ_i = Σ_{j∈E} B_i(t_j) δ_j / Σ_{j∈E} B_i(t_j)``. All
    other control points keep their exact values.

    Parameters
    ----------
    volume : BSplineVolume
        The current fit (e.g. from :func:`fit_grid`); not modified.
    values : (N1, N2, N3) or (N1, N2, N3, d) float array
        The full grid data after the edit (only the edited vertices are read).
    edited : (k, 3) int array
        Grid indices of the edited vertices.
    params : 3 arrays or None
        Grid parameters as in :func:`fit_grid`.
    max_iter, tol
        As in :func:`fit_grid`; the rms is over the edited vertices.

    Returns
    -------
    volume : BSplineVolume
        New volume (same class, degrees and knots).
    moved : (n1, n2, n3) bool array
        Control points allowed to move.
    report : FitReport
    """
    q, t, e = _edited_vertices(volume, values, edited, params)
    target = q[e[:, 0], e[:, 1], e[:, 2]]                       # (k, d)
    B, sel, inv_den, moved = _local_basis(volume, t, e)
    ctrl = volume.control.copy()
    flat_ctrl = ctrl.reshape(-1, volume.dim)
    local, delta, hist, it, converged = _local_iterations(B, target, flat_ctrl[sel].copy(), inv_den, max_iter,
                                                          tol)
    flat_ctrl[sel] = local
    return (volume.with_control(ctrl), moved,
            FitReport(iterations=it, converged=bool(converged), rms_history=hist,
                      max_error=_maxerr(delta), rms=hist[-1]))


def _edited_vertices(volume, values, edited, params):
    """:func:`local_lspia`'s arguments checked: ``(q, t, e)``, the grid data ``(N1, N2, N3, d)``, the grid
    parameters per axis and the distinct edited grid indices ``(k, 3)`` (integers)."""
    if not isinstance(volume, BSplineVolume):
        raise InputError("local_lspia needs a BSplineVolume to modify")
    q = _grid_values(values)
    if q.shape[3] != volume.dim:
        raise InputError(f"grid data has dimension {q.shape[3]}, the volume {volume.dim}")
    t = _grid_params(params, q.shape[:3])
    e = np.asarray(edited)
    if e.ndim == 1 and e.size == 3:
        e = e[None, :]
    if e.ndim != 2 or e.shape[1] != 3 or e.shape[0] == 0:
        raise InputError(f"edited vertices must be a non-empty (k, 3) array of grid indices, got shape {e.shape}")
    if not np.issubdtype(e.dtype, np.integer):
        if not np.all(np.equal(np.mod(e, 1), 0)):
            raise InputError("edited vertices must be integer grid indices")
        e = e.astype(np.int64)
    for a in range(3):
        if e[:, a].min() < 0 or e[:, a].max() >= q.shape[a]:
            raise InputError(f"edited vertex index along {_AXES[a]} outside 0..{q.shape[a] - 1}")
    return q, t, np.unique(e, axis=0)


def _local_basis(volume, t, e):
    """The basis values at the edited vertices ``e`` (parameters ``t``) of the control points they reach:
    ``(B, sel, inv_den, moved)``, a sparse (edited vertices x moving control points) matrix, the flat
    indices of those control points, ``1 / Σ_j B_i(t_j)`` for each and the ``(n1, n2, n3)`` mask of them."""
    # local basis of every edited vertex: spans and the (p+1) non-zero values per axis
    idx, val = [], []
    for a in range(3):
        pa = volume.degrees[a]
        spans, b = basis_functions(volume.knots[a], pa, t[a][e[:, a]])
        idx.append(spans[:, None] - pa + np.arange(pa + 1)[None, :])
        val.append(b[0])
    w = val[0][:, :, None, None] * val[1][:, None, :, None] * val[2][:, None, None, :]   # (k, p+1, q+1, r+1)
    I = np.broadcast_to(idx[0][:, :, None, None], w.shape)
    J = np.broadcast_to(idx[1][:, None, :, None], w.shape)
    Kk = np.broadcast_to(idx[2][:, None, None, :], w.shape)
    den = np.zeros(volume.n_ctrl)
    np.add.at(den, (I, J, Kk), w)
    moved = den > 0
    flat_w = w.reshape(len(e), -1)
    lin = np.ravel_multi_index((I, J, Kk), volume.n_ctrl).reshape(len(e), -1)
    sel = np.flatnonzero(moved.ravel())
    inv_den = 1.0 / den.ravel()[sel]
    # compact index: local position of each referenced control point in `sel`
    pos = np.full(int(np.prod(volume.n_ctrl)), -1, np.int64)
    pos[sel] = np.arange(sel.size)
    lpos = pos[lin]                                              # (k, nb); -1 where w == 0
    lpos_safe = np.where(lpos >= 0, lpos, 0)

    # the basis values as a sparse (edited vertices x moving control points) matrix: one product per
    # residual and one per update (a gather and a bincount per iteration cost several times more)
    from scipy.sparse import csr_matrix
    B = csr_matrix((flat_w.ravel(), (np.repeat(np.arange(len(e)), flat_w.shape[1]), lpos_safe.ravel())),
                   shape=(len(e), sel.size))
    return B, sel, inv_den, moved


def _local_iterations(B, target, local, inv_den, max_iter, tol):
    """Local LSPIA steps from the moving control points ``local`` toward ``target`` (as :func:`fit_grid`'s
    loop): ``(local, delta, rms history, iterations, converged)``."""
    BT = B.T.tocsr()

    def residual(local):
        return target - B @ local

    delta = residual(local)
    hist = [_rms(delta)]
    converged = hist[0] == 0.0
    it = 0
    while not converged and it < max_iter:
        local += (BT @ delta) * inv_den[:, None]  # Σ_j B_i(t_j) δ_j per control point, over Σ_j B_i(t_j)
        delta = residual(local)
        hist.append(_rms(delta))
        it += 1
        prev, cur = hist[-2], hist[-1]
        if cur == 0.0 or (prev - cur) < tol * prev:
            converged = True
    return local, delta, hist, it, converged
