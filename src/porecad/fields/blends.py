"""Blending operators of document 003 §2.4.5 (Definition 2.3 and Eqs. 2.7–2.12).

A blending operator is a map ``g: R^2 -> R`` applied to two field values
(003 Def. 2.3). With the porecad convention *negative inside* and objects
``O_i = {f_i <= 0}``, every operator is given in its *intersection* form
``g`` and the other Booleans follow from 003 Eq. 2.8::

    g_int(f0, f1) = g(f0, f1)
    g_uni(f0, f1) = -g(-f0, -f1)
    g_sub(f0, f1) = g(f0, -f1)          # O0 minus O1

Operators (all vectorised over numpy arrays):

``sharp``   Ricci 1974: ``g = max(f0, f1)`` (C0).
``softmax`` log-sum-exp: ``g = ln(exp(k f0) + exp(k f1)) / k`` (003 §2.4.5;
            C-infinity, moves the whole surface by up to ``ln 2 / k``).
``rfunc``   Rvachev R-function: ``g = (f0 + f1 + sqrt(f0^2 + f1^2 - 2 a f0 f1)) / (1 + a)``,
            ``a`` in (-1, 1] (a = 1 gives ``max``; a = 0 the C1 form of Pasko 1995).
``li``      Li's C^n shape-preserving blend (003 Eqs. 2.9–2.12):
            ``max_{n,d}(x, y) = (x + y + |x - y|_{n,d}) / 2`` with the smoothed
            absolute value ``|t|_{n,d} = (d/n) |n t / d|_n`` and
            ``|t|_0 = |t|``, ``|t|_n = [(n - t)|1 - t|_{n-1} + (n + t)|1 + t|_{n-1}] / (2(n+1))``.
            ``|t|_{n,d} = |t|`` exactly for ``|t| >= d``, so the blend only
            acts where ``|f0 - f1| < d`` (shape preserving). The smoothed
            ``|0|_{n,d}`` is ``d/2`` (n = 1), ``d/3`` (n = 2), ``13 d/48``
            (n = 3), so the blend moves the field by at most **half** that,
            at ``f0 = f1``: ``d/4``, ``d/6``, ``13 d/96``. (The reference notes
            state ``δ/3`` for the n = 2 union; that is the deviation of
            ``|t|_{2,δ}``, not of the union — Eq. 2.9 halves it; checked
            numerically in ``tests/vessels/test_vessels.py``.)

The thesis uses ``li`` with n = 2, δ = 0.2 for vessels (003 §3, Fig. 3.5).
Barthe's and Gourmel's blends are only cited in 003 (no formulas) and are
not offered.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError

BLENDS = ("li", "sharp", "softmax", "rfunc")


#: Li's blend span delta when none is given (mm)
LI_DELTA = 0.2


def smooth_abs(t, n: int, delta: float):
    """Li's smoothed absolute value ``|t|_{n,δ}`` (003 Eqs. 2.10–2.11).

    Implemented with the recursion of Eq. 2.11 on ``s = n t / δ`` for
    ``|t| < δ`` (exactly ``|t|`` outside, which the recursion reproduces:
    ``|s|_n = |s|`` for ``|s| >= n``). Closed forms used in the tests:
    n = 1: ``(t^2 + δ^2) / (2δ)``; n = 2: ``-|t|^3/(3δ^2) + t^2/δ + δ/3``.
    """
    n = int(n)
    t = np.asarray(t, dtype=np.float64)
    if n == 0:
        return np.abs(t)
    s = n * t / float(delta)

    def rec(x, m):
        if m == 0:
            return np.abs(x)
        return ((m - x) * rec(1.0 - x, m - 1) + (m + x) * rec(1.0 + x, m - 1)) / (2.0 * (m + 1))

    out = np.abs(t)
    band = np.abs(t) < delta
    if np.any(band):
        out = out.copy() if out.ndim else out
        out[band] = (delta / n) * rec(s[band], n)
    return out


def check_blend(kind: str, n=2, delta=LI_DELTA, k=10.0, alpha=0.0):
    """Validate blend parameters; raise InputError with a one-line message."""
    if kind not in BLENDS:
        raise InputError(f"unknown blend {kind!r}; use one of {', '.join(BLENDS)}")
    if kind == "li":
        if isinstance(n, bool) or int(n) != n or int(n) < 0 or int(n) > 6:
            raise InputError(f"blend degree n must be an integer 0..6, got {n!r}")
        if not np.isfinite(delta) or delta <= 0:
            raise InputError(f"blend span delta must be positive, got {delta!r}")
    if kind == "softmax" and (not np.isfinite(k) or k <= 0):
        raise InputError(f"soft-max sharpness k must be positive, got {k!r}")
    if kind == "rfunc" and not (-1.0 < alpha <= 1.0):
        raise InputError(f"R-function alpha must lie in (-1, 1], got {alpha!r}")


@dataclasses.dataclass(frozen=True)
class Blend:
    """A blending operator of :data:`BLENDS` and the parameters given for it (None: the operator's default),
    checked when made (:func:`check_blend`)."""

    kind: str
    n: int | None = None        # li: degree
    delta: float | None = None  # li: span
    k: float | None = None      # softmax: sharpness
    alpha: float | None = None  # rfunc

    def __post_init__(self):
        check_blend(**self.keywords())

    def keywords(self) -> dict:
        """``kind`` and the parameters given: the keywords of :func:`g_union` (and a report's form)."""
        return {f: v for f, v in dataclasses.asdict(self).items() if v is not None}

    @property
    def span(self) -> float:
        """The width (mm) of the band where the blend departs from the sharp union: Li's ``delta`` (as
        :func:`g_intersection` takes it when not given), 0 for the others."""
        if self.kind != "li":
            return 0.0
        return float(LI_DELTA if self.delta is None else self.delta)

    def union(self, f0, f1):
        """``g_uni(f0, f1)`` of this blend (003 Eq. 2.8)."""
        return g_union(f0, f1, **self.keywords())


def g_intersection(f0, f1, kind: str = "li", n: int = 2, delta: float = LI_DELTA, k: float = 10.0,
                   alpha: float = 0.0):
    """The intersection form ``g(f0, f1)`` of a blend (003 Eqs. 2.7, 2.9, 2.12)."""
    f0 = np.asarray(f0, dtype=np.float64)
    f1 = np.asarray(f1, dtype=np.float64)
    if kind == "sharp":
        return np.maximum(f0, f1)
    if kind == "li":
        return 0.5 * (f0 + f1 + smooth_abs(f0 - f1, n, delta))
    if kind == "softmax":
        m = np.maximum(f0, f1)  # stable log-sum-exp
        return m + np.log(np.exp(k * (f0 - m)) + np.exp(k * (f1 - m))) / k
    if kind == "rfunc":
        return (f0 + f1 + np.sqrt(np.maximum(f0 * f0 + f1 * f1 - 2.0 * alpha * f0 * f1, 0.0))) / (1.0 + alpha)
    raise InputError(f"unknown blend {kind!r}")


def g_union(f0, f1, **kw):
    """``g_uni(f0, f1) = -g(-f0, -f1)`` (003 Eq. 2.8)."""
    return -g_intersection(-np.asarray(f0, dtype=np.float64), -np.asarray(f1, dtype=np.float64), **kw)
