"""Tetrahedral implicit surfaces (TIS): periodic implicit functions inside tetrahedra.

Document 002 (§3.1) gives each tetrahedron ABCD four coordinates, one per face,

    θ_α = 2π λ_α d_α / h_α,   θ_β = 2π λ_β d_β / h_β,   θ_γ = ...,   θ_δ = ...      (002 eq. 2)

with ``d`` the distance of the point to the face (BCD, ACD, ABD, ABC) and ``h``
the tetrahedron's height onto it. ``d_α / h_α`` is exactly the barycentric
coordinate of the point with respect to vertex A (the ratio of the volume of
PBCD to ABCD), so ``θ = 2πλ · b`` with ``b`` the barycentric coordinates
(``Σ b = 1``; notes on 000 §4.2). The TIS functions (002 eq. 3) combine the
coordinates like the TPMS combine x, y, z:

    P:  cos α + cos β + cos γ + cos δ + cos α cos β cos γ cos δ
    D:  Σ_i sin θ_i Π_{j≠i} cos θ_j + cos α cos β cos γ cos δ
    G:  cos α sin β + cos β sin γ + cos γ sin δ + cos δ sin α + cos α cos β cos γ cos δ

Erratum (G). 002 eq. 3 prints ``cos α sin β + cos γ sin δ + cos α sin β +
cos γ sin δ + Π cos`` (the first two terms repeated). That form does not
reproduce 002 Table 3: on one regular tetrahedron (λ = 1, exact min/max) it
gives porosities 40.1 / 49.2 / 58.4 / 65.4 / 71.3 % at the five relative
thresholds 0.431 … 0.627, against the table's 44.03 / 57.29 / 67.76 / 76.09 /
84.04 % (errors up to 12.8 points). The cyclic form above gives 43.8 / 57.6 /
67.7 / 76.3 / 83.9 % (within 0.31 points), like P (≤ 0.17) and D (≤ 0.45); see
``tests/fields/test_tis.py`` and ``docs/tis.md``.

The relative threshold (002 eq. 7) maps ``R ∈ [0, 1]`` into the sampled range:
``C = min + R (max − min)``, min and max over the computed samples (the text's
"max and min are the minimum and maximum" has the words swapped).

Each function is stored as a sum of products of per-coordinate factors
(1, cos, sin), so values, gradients and Hessians in θ come from one generic
routine, like the TPMS Fourier terms of :mod:`porecad.fields.derivatives`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError


# factor codes: 0 -> 1, 1 -> cos, 2 -> sin
_TERMS = {
    "P": ((1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1), (1, 1, 1, 1)),
    "D": ((2, 1, 1, 1), (1, 2, 1, 1), (1, 1, 2, 1), (1, 1, 1, 2), (1, 1, 1, 1)),
    "G": ((1, 2, 0, 0), (0, 1, 2, 0), (0, 0, 1, 2), (2, 0, 0, 1), (1, 1, 1, 1)),
    # 002 eq. 3 as printed (duplicated terms) - kept only as evidence for the erratum
    "G-printed": ((1, 2, 0, 0), (0, 0, 1, 2), (1, 2, 0, 0), (0, 0, 1, 2), (1, 1, 1, 1)),
}

TIS_TYPES = ("P", "D", "G")
TYPE_CODES = {"P": 0, "D": 1, "G": 2}

#: Connected ranges of the relative threshold for one period in a regular
#: tetrahedron (002 §4, "ideal threshold range"; also the rows of Table 3).
RELATIVE_RANGES = {"P": (0.118, 0.275), "D": (0.569, 0.765), "G": (0.431, 0.627)}


def check_type(name: str) -> str:
    t = str(name).strip().upper()
    if t not in TIS_TYPES:
        raise InputError(f"unknown TIS type {name!r}; choose one of {', '.join(TIS_TYPES)}")
    return t


def check_lambda(lam) -> np.ndarray:
    """λ as a float array (scalar, per axis (4,), per tet (T,) or (T, 4)); every entry > 0."""
    a = np.asarray(lam, dtype=np.float64)
    if a.size == 0 or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"lambda (periods per tetrahedron) must be positive, got {lam!r}")
    return a


def _factors(theta, code, order):
    """``order``-th θ-derivative of the factor ``code`` (1, cos, sin)."""
    if code == 0:
        return np.ones_like(theta) if order == 0 else np.zeros_like(theta)
    k = order % 4
    if code == 1:  # cos, -sin, -cos, sin
        return (np.cos(theta), -np.sin(theta), -np.cos(theta), np.sin(theta))[k]
    return (np.sin(theta), np.cos(theta), -np.sin(theta), -np.cos(theta))[k]


def tis_terms(kind: str):
    """The product terms of a TIS type (factor codes per coordinate: 0=1, 1=cos, 2=sin)."""
    if kind not in _TERMS:
        raise InputError(f"unknown TIS type {kind!r}; choose one of {', '.join(TIS_TYPES)}")
    return _TERMS[kind]


def tis_value(theta, kind: str) -> np.ndarray:
    """TIS function of 002 eq. 3 (cyclic G) at coordinates ``theta`` (..., 4)."""
    th = np.asarray(theta, dtype=np.float64)
    out = np.zeros(th.shape[:-1])
    for term in tis_terms(kind):
        f = np.ones(th.shape[:-1])
        for i, code in enumerate(term):
            if code:
                f = f * _factors(th[..., i], code, 0)
        out += f
    return out


def tis_derivatives(theta, kind: str):
    """Value, gradient (..., 4) and Hessian (..., 4, 4) of a TIS function in θ."""
    th = np.asarray(theta, dtype=np.float64)
    shape = th.shape[:-1]
    val = np.zeros(shape)
    grad = np.zeros(shape + (4,))
    hess = np.zeros(shape + (4, 4))
    for term in tis_terms(kind):
        f = [[_factors(th[..., i], term[i], o) for o in range(3)] for i in range(4)]
        val += f[0][0] * f[1][0] * f[2][0] * f[3][0]
        for i in range(4):
            for j in range(4):
                prod = np.ones(shape)
                for k in range(4):
                    o = (k == i) + (k == j)
                    prod = prod * f[k][o]
                hess[..., i, j] += prod
            prod = np.ones(shape)
            for k in range(4):
                prod = prod * f[k][int(k == i)]
            grad[..., i] += prod
    return val, grad, hess


@njit(cache=True, inline="always")
def tis_scalar(code, a, b, c, d):
    """One TIS value (code 0 = P, 1 = D, 2 = G cyclic) at coordinates (α, β, γ, δ)."""
    ca, cb, cc, cd = np.cos(a), np.cos(b), np.cos(c), np.cos(d)
    prod = ca * cb * cc * cd
    if code == 0:
        return ca + cb + cc + cd + prod
    sa, sb, sc, sd = np.sin(a), np.sin(b), np.sin(c), np.sin(d)
    if code == 1:
        return sa * cb * cc * cd + ca * sb * cc * cd + ca * cb * sc * cd + ca * cb * cc * sd + prod
    return ca * sb + cb * sc + cc * sd + cd * sa + prod


def relative_threshold(values, relative: float) -> float:
    """002 eq. 7: ``C = min + R (max − min)`` over the computed TIS values."""
    r = float(relative)
    if not np.isfinite(r) or r < 0.0 or r > 1.0:
        raise InputError(f"relative threshold must lie in [0, 1], got {relative!r}")
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise InputError("no TIS samples to take a relative threshold from")
    lo, hi = float(v.min()), float(v.max())
    return lo + r * (hi - lo)
