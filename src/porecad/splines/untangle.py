"""Untangling a fitted TBSS control net against its Jacobian (issue 20; cf. the hex grid untangling of 000 ch.3).

A least-squares TBSS fit of sampled body points (a radial map of a
star-shaped body, or the hexahedral cube parameterisation of any genus-0
body) can fold where the samples are noisy or where the cube's edges land on
the smooth surface (the map is singular there, see
:mod:`porecad.splines.construct`). Rather than refuse, the control points are
moved to minimise

.. math::

    E(P) = \\frac{1}{\\ell^2} \\sum_{b \\in \\partial} |x(t_b) - q_b|^2
         + \\frac{\\alpha}{\\ell^2} \\sum_{i} |x(t_i) - q_i|^2
         + \\kappa \\sum_s (\\mu - J_s)_+^2

over all control points: the fit of the boundary samples ``q_b`` (they lie on
the body's surface), a weak fit ``α`` of the interior samples (which may be
folded themselves), and a barrier on the scaled Jacobian

.. math:: J_s = \\frac{x_u \\cdot (x_v \\times x_w)}{|x_u|\\,|x_v|\\,|x_w|}

at the samples ``s`` of :meth:`porecad.splines.TBSS.check_jacobian`'s kind
(uniform, knots and Gauss points per span), ``ℓ`` the mean sample spacing.
``x`` is linear in ``P``, so the fit terms are quadratic; the barrier's
gradient follows from ``∂J/∂x_u = (x_v × x_w)/(|x_u||x_v||x_w|) − J x_u/|x_u|²``
(cyclically) and the tensor-product basis (001 eq. 2). L-BFGS (Nocedal &
Wright, *Numerical Optimization*, 2nd ed., §7.2), in rounds that add the
samples of the Jacobian check where it still fails.

The result either passes :meth:`~porecad.splines.TBSS.check_jacobian` or
the one-line reason says why not (iterations or time limit, min scaled
Jacobian left).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
from numba import njit

from ..errors import InputError
from .basis import basis_matrix
from .volume import TBSS, tensor_apply

__all__ = ["UntangleResult", "min_scaled_jacobian", "scaled_jacobian_samples", "untangle_tbss"]

#: barrier level on the scaled Jacobian
MU = 0.03
#: weight of the samples on the cube's edges and corners relative to the other boundary samples
EDGE_WEIGHT = 0.2


class UntangleResult(dict):
    """``tbss``, ``converged``, ``reason``, ``iterations``, ``rounds``, ``min_scaled_jacobian``, ``time_s``, ``moved``."""


def _axis_samples(tb, axis, count):
    return tb.sample_params(axis, count)


def _bases(tb, axes):
    B0 = [basis_matrix(tb.knots[a], tb.degrees[a], axes[a], 0) for a in range(3)]
    B1 = [basis_matrix(tb.knots[a], tb.degrees[a], axes[a], 1) for a in range(3)]
    return B0, B1


def _derivs(P, B0, B1):
    du = tensor_apply([B1[0], B0[1], B0[2]], P)
    dv = tensor_apply([B0[0], B1[1], B0[2]], P)
    dw = tensor_apply([B0[0], B0[1], B1[2]], P)
    return du, dv, dw


def scaled_jacobian_samples(tb: TBSS, axes=None):
    """Scaled Jacobian ``det J / (|x_u| |x_v| |x_w|)`` on a tensor grid of parameters (default: the check's samples)."""
    if axes is None:
        axes = [_axis_samples(tb, a, max(4 * tb.n_ctrl[a], 16)) for a in range(3)]
    B0, B1 = _bases(tb, axes)
    du, dv, dw = _derivs(tb.control, B0, B1)
    n = (np.linalg.norm(du, axis=-1) * np.linalg.norm(dv, axis=-1) * np.linalg.norm(dw, axis=-1))
    det = np.einsum("...i,...i->...", du, np.cross(dv, dw))
    return det / np.maximum(n, 1e-300)


def min_scaled_jacobian(tb: TBSS) -> float:
    """Minimum scaled Jacobian over the samples of :meth:`TBSS.check_jacobian` (1 for a box, ≤ 0 folds)."""
    return float(scaled_jacobian_samples(tb).min())


def untangle_tbss(tb: TBSS, samples, params, boundary_weight: float = 1.0, interior_weight: float = 0.01,
                  mu: float = MU, kappa: float = 1e4, max_iterations: int = 2000, time_limit: float = 120.0,
                  progress=None) -> UntangleResult:
    """Move the control points of ``tb`` until its Jacobian is positive, keeping its fit to ``samples``.

    Parameters
    ----------
    tb : TBSS
        The least-squares fit (its knots and degrees are kept).
    samples : (n1, n2, n3, 3) float
        The sampled points the fit was made to; the six boundary slices lie
        on the body's surface.
    params : three 1-D arrays
        Their parameters along u, v, w (``samples[i, j, k]`` at ``(params[0][i], ...)``).
    boundary_weight, interior_weight : float
        Weights of the fit of the boundary and of all samples (in squared mean spacings).
    mu, kappa : float
        Barrier level and weight on the scaled Jacobian.
    max_iterations : int
        L-BFGS iterations in all (bounded before work starts: 1..100,000).
    time_limit : float
        Seconds; the descent stops at the first iteration past it.
    progress : callable, optional
        ``progress(done, total)`` in iterations.

    Returns
    -------
    UntangleResult
        ``tbss`` (the untangled solid; ``tb`` itself when it already passed),
        ``converged`` (it passes :meth:`TBSS.check_jacobian`), ``reason``
        (one line when not), ``iterations``, ``rounds``,
        ``min_scaled_jacobian`` (before and after), ``moved`` (largest control
        point move / mean spacing), ``time_s``.
    """
    _check_limits(max_iterations, time_limit)
    run = _Run(max_iterations, time_limit, progress)
    tg = _targets(tb, samples, params, boundary_weight, interior_weight)
    axes_full = [_axis_samples(tb, a, max(4 * tb.n_ctrl[a], 16)) for a in range(3)]
    P0 = np.array(tb.control, np.float64)
    sj0 = float(scaled_jacobian_samples(tb, axes_full).min())
    res = UntangleResult(tbss=tb, converged=sj0 > 0, reason="", iterations=0, rounds=0,
                         min_scaled_jacobian_before=sj0, min_scaled_jacobian=sj0, moved=0.0, time_s=0.0)
    if sj0 > mu and _passes(tb):
        res["time_s"] = run.elapsed()
        return res
    (cand, sj), reason, rounds = _rounds(tb, tg, axes_full, mu, kappa, run)
    ok = sj > 0 and _passes(cand)
    res.update(tbss=cand, converged=ok, reason="" if ok else f"the TBSS still folds: {reason}",
               iterations=run.iterations, rounds=rounds, min_scaled_jacobian=sj,
               moved=float(np.linalg.norm(cand.control - P0, axis=-1).max() / tg.ell),
               time_s=run.elapsed())
    return res


def _check_limits(max_iterations, time_limit):
    """Refuse an iteration limit outside 1..100,000 or a time limit (s) that is not positive; returns None."""
    if isinstance(max_iterations, bool) or int(max_iterations) != max_iterations or \
            not 1 <= int(max_iterations) <= 100_000:
        raise InputError(f"untangle iterations must be a whole number in 1..100000, got {max_iterations!r}")
    if not (np.isfinite(time_limit) and time_limit > 0):
        raise InputError(f"the untangle time limit must be a positive number of seconds, got {time_limit!r}")


class _Run:
    """The descent's limits and counters: ``t0`` (its start), ``time_limit`` (s), ``max_iterations``,
    ``progress``, ``iterations`` (L-BFGS iterations so far, all rounds) and ``min_j`` (the min scaled
    Jacobian at the last evaluation of the energy)."""

    def __init__(self, max_iterations, time_limit, progress):
        self.t0 = time.perf_counter()
        self.max_iterations, self.time_limit, self.progress = max_iterations, time_limit, progress
        self.iterations = 0
        self.min_j = -1.0

    def elapsed(self) -> float:
        """Seconds since the start."""
        return time.perf_counter() - self.t0


class _Targets(NamedTuple):
    """The samples the fit terms keep: ``Q`` (n1, n2, n3, 3), ``Bs`` (their collocation matrices per axis),
    ``w`` (n1, n2, n3, 1: weight per sample over ``ℓ²``) and ``ell`` (``ℓ``, the mean sample spacing)."""
    Q: np.ndarray
    Bs: list
    w: np.ndarray
    ell: float


def _targets(tb, samples, params, boundary_weight, interior_weight) -> _Targets:
    """The fit terms' samples, collocation matrices and weights (:class:`_Targets`): every sample weighs
    ``interior_weight``, a face sample ``boundary_weight`` more, an edge or corner sample
    :data:`EDGE_WEIGHT` times that more."""
    Q = np.asarray(samples, np.float64)
    shape = Q.shape[:3]
    Bs = [basis_matrix(tb.knots[a], tb.degrees[a], np.asarray(params[a], float), 0) for a in range(3)]
    ell = float(np.mean([np.linalg.norm(np.diff(Q, axis=a), axis=-1).mean() for a in range(3)]))
    ell2 = ell * ell
    wmask = np.full(shape, interior_weight)
    on = np.zeros(shape, np.int64)
    for a in range(3):
        sl = [slice(None)] * 3
        sl[a] = [0, -1]
        on[tuple(sl)] += 1
    wmask[on == 1] += boundary_weight
    wmask[on > 1] += EDGE_WEIGHT * boundary_weight
    # the samples on the cube's edges and corners are fitted weakly: where the faces on both sides land on one
    # smooth surface the map is singular there (module docstring of :mod:`porecad.splines.construct`), and
    # the barrier makes the slight crease that a positive Jacobian needs
    w = wmask[..., None] / ell2
    return _Targets(Q, Bs, w, ell)


def _rounds(tb, tg, axes_full, mu, kappa, run):
    """Up to three rounds of L-BFGS from ``tb``'s control net, each adding the check's samples (``axes_full``)
    along the parameter lines that still hold a low scaled Jacobian; stops at the first candidate that
    passes, the time limit or the iteration limit. Returns ``((tbss, min scaled Jacobian), reason, rounds)``
    (``reason``: why the last round did not pass; ``rounds``: descents run)."""
    x = np.array(tb.control, np.float64).ravel().copy()
    best = None
    reason = ""
    rounds = 0
    axes = [_axis_samples(tb, a, 2) for a in range(3)]  # knots, ends and 3 Gauss points per span
    for rnd in range(3):
        if rnd:  # add the check's samples along the parameter lines that still hold a low one
            axes = _low_lines(tb, x, axes, axes_full, mu)
        fun = _energy(tb, axes, tg, mu, kappa, run)
        budget = int(run.max_iterations) - run.iterations
        if rnd == 0:
            budget = max(1, budget // 2)
        if budget <= 0:
            reason = f"stopped after {run.iterations} iterations (the limit)"
            break
        x = _descend(fun, x, budget, mu, run)
        rounds = rnd + 1
        best = _candidate(x, tb, axes_full)
        cand, sj = best
        if sj > 0 and _passes(cand):
            reason = ""
            break
        if run.elapsed() > run.time_limit:
            reason = f"stopped at the time limit of {run.time_limit:g} s"
            break
        reason = f"min scaled Jacobian {sj:.3g} after {run.iterations} iterations"
    return best, reason, rounds


def _low_lines(tb, x, axes, axes_full, mu):
    """The optimisation's sample axes ``axes`` with those of ``axes_full`` added along which the net ``x``
    (flat) has a scaled Jacobian below ``2 mu``: three 1-D arrays."""
    cur = TBSS(x.reshape(tb.control.shape), tb.degrees, tb.knots, periodic=tb.periodic)
    low = np.argwhere(scaled_jacobian_samples(cur, axes_full) < 2.0 * mu)
    return [np.union1d(axes[a], axes_full[a][np.unique(low[:, a])]) for a in range(3)]


@njit(cache=True, nogil=True)
def barrier(du, dv, dw, mu, gu, gv, gw):
    """The Jacobian barrier at ``N`` samples in one pass: ``du, dv, dw`` (N, 3) the map's derivatives.

    Returns ``(sum (mu - J)_+^2, min J)`` with ``J`` the scaled Jacobian and
    writes ``d/dx_u`` (``gu``; ``gv``, ``gw`` alike) of ``-2 (mu - J)_+``
    times ``J`` (module docstring): zero where ``J >= mu``. One compiled loop
    instead of twenty array temporaries per energy evaluation (the fit of a
    body calls it hundreds of times).
    """
    total, jmin = 0.0, np.inf
    for i in range(du.shape[0]):
        a0, a1, a2 = du[i, 0], du[i, 1], du[i, 2]
        b0, b1, b2 = dv[i, 0], dv[i, 1], dv[i, 2]
        c0, c1, c2 = dw[i, 0], dw[i, 1], dw[i, 2]
        nu = max(np.sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-300)
        nv = max(np.sqrt(b0 * b0 + b1 * b1 + b2 * b2), 1e-300)
        nw = max(np.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-300)
        x0, x1, x2 = b1 * c2 - b2 * c1, b2 * c0 - b0 * c2, b0 * c1 - b1 * c0  # x_v × x_w
        y0, y1, y2 = c1 * a2 - c2 * a1, c2 * a0 - c0 * a2, c0 * a1 - c1 * a0  # x_w × x_u
        z0, z1, z2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0  # x_u × x_v
        den = nu * nv * nw
        J = (a0 * x0 + a1 * x1 + a2 * x2) / den
        jmin = min(jmin, J)
        viol = mu - J
        if viol <= 0.0:
            for k in range(3):
                gu[i, k] = gv[i, k] = gw[i, k] = 0.0
            continue
        total += viol * viol
        c = -2.0 * viol
        ju, jv, jw = J / (nu * nu), J / (nv * nv), J / (nw * nw)
        gu[i, 0], gu[i, 1], gu[i, 2] = c * (x0 / den - ju * a0), c * (x1 / den - ju * a1), c * (x2 / den - ju * a2)
        gv[i, 0], gv[i, 1], gv[i, 2] = c * (y0 / den - jv * b0), c * (y1 / den - jv * b1), c * (y2 / den - jv * b2)
        gw[i, 0], gw[i, 1], gw[i, 2] = c * (z0 / den - jw * c0), c * (z1 / den - jw * c1), c * (z2 / den - jw * c2)
    return total, jmin


def _energy(tb, axes, tg, mu, kappa, run):
    """``fun(x) -> (E, dE/dx)``: the energy of the module docstring over the flat control net ``x``, its
    barrier on the scaled Jacobian at the tensor grid ``axes``; each call sets ``run.min_j``."""
    nshape = tb.control.shape
    Q, Bs, w = tg.Q, tg.Bs, tg.w
    B0, B1 = _bases(tb, axes)

    B0T, B1T = [b.T.tocsr() for b in B0], [b.T.tocsr() for b in B1]
    BsT = [b.T.tocsr() for b in Bs]
    grid_shape = tuple(b.shape[0] for b in B0)

    def fun(x):
        P = x.reshape(nshape)
        X = tensor_apply(Bs, P)
        r = X - Q
        E = float(np.sum(w * r * r))
        G = tensor_apply(BsT, 2.0 * w * r)
        du, dv, dw = (np.ascontiguousarray(d).reshape(-1, 3) for d in _derivs(P, B0, B1))
        gu, gv, gw = np.empty_like(du), np.empty_like(dv), np.empty_like(dw)
        bar, run.min_j = barrier(du, dv, dw, mu, gu, gv, gw)
        E += kappa * bar
        if bar > 0:
            shape = grid_shape + (3,)
            gu, gv, gw = (kappa * g.reshape(shape) for g in (gu, gv, gw))
            G = G + tensor_apply([B1T[0], B0T[1], B0T[2]], gu) + tensor_apply([B0T[0], B1T[1], B0T[2]], gv) \
                + tensor_apply([B0T[0], B0T[1], B1T[2]], gw)
        return E, G.ravel()

    return fun


def _descend(fun, x, budget, mu, run):
    """One L-BFGS descent of ``fun`` from the flat net ``x`` for at most ``budget`` iterations, stopped
    early once 20 iterations are done with every sample above half the barrier, or past the time limit;
    counts ``run.iterations`` and reports ``run.progress``. Returns the new flat net."""
    from scipy.optimize import minimize

    start = run.iterations

    def cb(xk):
        run.iterations += 1
        if run.iterations - start >= 20 and run.min_j > 0.5 * mu:
            raise StopIteration  # every sample above the barrier: the rest would only polish the fit
        if run.progress is not None:
            run.progress(run.iterations, int(run.max_iterations))
        if run.elapsed() > run.time_limit:
            raise StopIteration

    try:
        out = minimize(fun, x, jac=True, method="L-BFGS-B", callback=cb,
                       options={"maxiter": budget, "maxcor": 30, "ftol": 1e-12, "gtol": 1e-9})
        x = out.x
    except StopIteration:  # pragma: no cover - older scipy re-raises the callback's StopIteration
        pass
    return x


def _candidate(x, tb, axes_full):
    """The solid of the flat net ``x`` (its edges opened where it fails the Jacobian check, :func:`_creased`)
    and its min scaled Jacobian over ``axes_full``: ``(tbss, float)``."""
    cand = TBSS(x.reshape(tb.control.shape), tb.degrees, tb.knots, periodic=tb.periodic)
    if not _passes(cand):
        cand = _creased(x.reshape(tb.control.shape), tb)
    sj = float(scaled_jacobian_samples(cand, axes_full).min())
    return cand, sj


def _creased(P, tb):
    """The net with its edges opened (:func:`porecad.splines.construct.finish_tbss`), or as it is where that fails."""
    from .construct import finish_tbss
    try:
        return finish_tbss(P, tb.degrees, tb.knots, tb.periodic)[0]
    except InputError:
        return TBSS(P, tb.degrees, tb.knots, periodic=tb.periodic)


def _passes(tb) -> bool:
    try:
        tb.check_jacobian()
    except InputError:
        return False
    return True
