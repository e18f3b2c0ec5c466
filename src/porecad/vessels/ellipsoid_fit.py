"""003's direct RBF fit with an ellipsoid constraint (003 Eqs. 3.5–3.6, after Li et al. 2004b).

A segment's closed boundary cloud ``P_1 .. P_n`` is fitted by

    f(X) = Σ_i γ_i φ(|X − P_i|) + Σ_j β_j ψ_j(X)                      (003 Eq. 3.5)

with ``φ(r) = r³`` and the ten quadric monomials ``ψ = (x², y², z², 2yz, 2xz,
2xy, 2x, 2y, 2z, 1)``. Interpolation ``f(P_i) = 0`` (the first block row of
003 Eq. 3.6) gives ``γ = −Φ⁻¹ Ψ β``; the quadric's coefficients then minimise
the spline's energy ``γᵀΦγ = βᵀ (ΨᵀΦ⁻¹Ψ) β`` under Li and Griffiths' ellipsoid
constraint ``4J − I² = 1`` (``I = a + b + c``, ``J = ab + bc + ca − f² − g² − h²``):
the small generalised eigenproblem ``(ΨᵀΦ⁻¹Ψ) β = λ C β`` of 10 × 10
matrices, whose eigenvector of least ``λ`` with ``βᵀCβ > 0`` is taken; as
Li and Griffiths do for elongated data, the constraint's ``k`` (4 above) is
raised (8, 16, ... 128) while the solution stays an ellipsoid. No
normals, no off-surface points; the points are interpolated exactly (to
round-off), and far from them the ellipsoid bounds the shape.

For blending, the fit is normalised to a first-order distance ``f / |∇f|``
(both analytic) and, like the thin-plate fit, guarded by the segment's swept
tube (``max(f, f_tube − r̄/2)``, :func:`porecad.vessels.model._task`), so no
blob away from the vessel can survive in the segment's box.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

#: Li and Griffiths' k: kJ − I² > 0 is an ellipsoid for k = 4
K_ELLIPSOID = 4.0


def _quadric(X):
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    one = np.ones(len(X))
    return np.stack([x * x, y * y, z * z, 2 * y * z, 2 * x * z, 2 * x * y, 2 * x, 2 * y, 2 * z, one], axis=1)


def _quadric_grad(X):
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    o, n = np.ones(len(X)), np.zeros(len(X))
    gx = np.stack([2 * x, n, n, n, 2 * z, 2 * y, 2 * o, n, n, n], axis=1)
    gy = np.stack([n, 2 * y, n, 2 * z, n, 2 * x, n, 2 * o, n, n], axis=1)
    gz = np.stack([n, n, 2 * z, 2 * y, 2 * x, n, n, n, 2 * o, n], axis=1)
    return gx, gy, gz


def _constraint(k=K_ELLIPSOID):
    C = np.zeros((10, 10))
    C[:3, :3] = k / 2.0 - 1.0
    np.fill_diagonal(C[:3, :3], -1.0)
    C[3, 3] = C[4, 4] = C[5, 5] = -k
    return C


#: support of the Wendland kernel, in units of the cloud's RMS distance from its centroid
SUPPORT = 1.0


def kernel(r):
    """Wendland's φ_{3,1}(r) = (1 − r/ρ)⁴₊ (4 r/ρ + 1): positive definite in 3-D (so the energy is a norm)."""
    t = np.minimum(r / SUPPORT, 1.0)
    return (1.0 - t) ** 4 * (4.0 * t + 1.0)


def kernel_dr_over_r(r):
    """φ'(r) / r."""
    t = np.minimum(r / SUPPORT, 1.0)
    return -20.0 * (1.0 - t) ** 3 / SUPPORT ** 2


#: the k tried in turn (k = 4: an ellipsoid whose short axis is at least half its long one; larger k admit
#: longer ones, but also other quadrics, so the search stops at the first k whose solution is not an ellipsoid)
K_SEQUENCE = (4.0, 8.0, 16.0, 32.0, 64.0, 128.0)


def _solve(A, C):
    """The eigenvector of ``A β = λ C β`` with ``βᵀCβ = 1`` and the least ``βᵀAβ``, or None."""
    w, V = linalg.eig(A, C)
    best, beta = np.inf, None
    for lam, v in zip(w, V.T):
        v = np.real(v)
        cc = float(v @ C @ v)
        if np.isfinite(lam) and abs(np.imag(lam)) < 1e-9 * (1 + abs(lam)) and cc > 1e-12:
            val = float(v @ A @ v) / cc
            if val < best:
                best, beta = val, v / np.sqrt(cc)
    return beta


def _is_ellipsoid(b) -> bool:
    a, bb, c, f, g, h = b[:6]
    M = np.array([[a, h, g], [h, bb, f], [g, f, c]])
    e = np.linalg.eigvalsh(M)
    return bool(e[0] > 0 or e[-1] < 0)


class EllipsoidRBF:
    """The fitted implicit of one cloud; ``self(X)`` is ``f / |∇f|`` (mm, negative inside)."""

    def __init__(self, points, inside=None):
        P = np.asarray(points, float).reshape(-1, 3)
        self.centre = P.mean(axis=0)
        self.scale = float(np.sqrt(((P - self.centre) ** 2).sum(axis=1).mean())) or 1.0
        Q = (P - self.centre) / self.scale
        Phi = kernel(linalg.norm(Q[:, None, :] - Q[None, :, :], axis=2))
        Psi = _quadric(Q)
        lu = linalg.lu_factor(Phi)
        A = Psi.T @ linalg.lu_solve(lu, Psi)
        A = 0.5 * (A + A.T)
        beta, self.k = None, None
        for k in K_SEQUENCE:  # Li and Griffiths: the largest k whose solution is still an ellipsoid
            b = _solve(A, _constraint(k))
            if b is None or not _is_ellipsoid(b):
                break
            beta, self.k = b, k
        if beta is None:
            raise ValueError("no ellipsoid solution")
        self.Q, self.beta = Q, beta
        self.gamma = -linalg.lu_solve(lu, Psi @ beta)
        self.sign = 1.0
        if inside is not None and np.median(self.raw(np.asarray(inside, float).reshape(-1, 3))) > 0:
            self.sign = -1.0

    def raw(self, X, grad: bool = False, chunk: int = 4096):
        """``f`` (and ``∇f``) at ``X (N, 3)`` mm (in the normalised units of the fit)."""
        X = (np.asarray(X, float).reshape(-1, 3) - self.centre) / self.scale
        f = np.empty(len(X))
        g = np.empty((len(X), 3)) if grad else None
        for a in range(0, len(X), chunk):
            x = X[a:a + chunk]
            d = x[:, None, :] - self.Q[None, :, :]
            r = np.sqrt((d * d).sum(axis=2))
            f[a:a + chunk] = kernel(r) @ self.gamma + _quadric(x) @ self.beta
            if grad:
                g[a:a + chunk] = np.einsum("ij,ijk->ik", kernel_dr_over_r(r) * self.gamma[None, :], d) + \
                    np.stack([q @ self.beta for q in _quadric_grad(x)], axis=1)
        return (self.sign * f, self.sign * g) if grad else self.sign * f

    def __call__(self, X):
        f, g = self.raw(X, grad=True)
        return f / np.maximum(np.linalg.norm(g, axis=1), 1e-12) * self.scale


def fit_segment(P, R, boundary, max_points: int = 600, seed: int = 0):
    """The ellipsoid-constrained fit of one segment's cloud, as ``(evaluator, 1.0)`` for
    :func:`porecad.vessels.rbf_fit.segment_values`, or None when there are too few points."""
    from .rbf_fit import MIN_POINTS
    B = np.asarray(boundary, float).reshape(-1, 3)
    if len(B) < MIN_POINTS:
        return None
    if len(B) > max_points:
        B = B[np.sort(np.random.default_rng(seed).choice(len(B), max_points, replace=False))]
    try:
        fit = EllipsoidRBF(B, inside=P)
    except (ValueError, linalg.LinAlgError):
        return None
    return fit, 1.0
