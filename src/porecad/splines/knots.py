"""Clamped knot vectors: construction and validation.

A knot vector of a degree-``p`` B-spline with ``n`` control points has
``n + p + 1`` non-decreasing knots. It is *clamped* (Bézier end condition,
Piegl & Tiller 1997, §2.2) when its first ``p + 1`` knots are equal and its
last ``p + 1`` knots are equal, so the spline interpolates its end control
points. porecad uses clamped knot vectors on ``[0, 1]`` throughout.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def clamped_uniform_knots(n_ctrl: int, degree: int) -> np.ndarray:
    """Uniform clamped knot vector on [0, 1] for ``n_ctrl`` control points.

    ``[0]*(p+1) + [1/(n-p), ..., (n-p-1)/(n-p)] + [1]*(p+1)``; needs ``n_ctrl > degree``.
    """
    n, p = int(n_ctrl), int(degree)
    if p < 0:
        raise InputError(f"B-spline degree must be >= 0, got {degree}")
    if n <= p:
        raise InputError(f"a degree-{p} B-spline needs more than {p} control points, got {n}")
    interior = np.arange(1, n - p, dtype=np.float64) / (n - p)
    return np.concatenate([np.zeros(p + 1), interior, np.ones(p + 1)])


def validate_knots(knots, degree: int, n_ctrl: int, name: str = "knot vector") -> np.ndarray:
    """Check a clamped knot vector; return it as float64 or raise :class:`InputError`.

    Checks: length ``n_ctrl + degree + 1``, finite values, non-decreasing,
    first ``degree + 1`` and last ``degree + 1`` knots equal (clamped), a
    non-empty domain, and no interior knot of multiplicity above ``degree``.
    """
    p, n = int(degree), int(n_ctrl)
    k = np.asarray(knots, dtype=np.float64).ravel()
    if p < 0:
        raise InputError(f"{name}: degree must be >= 0, got {degree}")
    if n <= p:
        raise InputError(f"{name}: a degree-{p} B-spline needs more than {p} control points, got {n}")
    if k.size != n + p + 1:
        raise InputError(f"{name}: expected {n + p + 1} knots for {n} control points of degree {p}, got {k.size}")
    if not np.all(np.isfinite(k)):
        raise InputError(f"{name}: knots must be finite numbers")
    bad = np.nonzero(np.diff(k) < 0)[0]
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{name}: knots decrease at position {i + 1} ({k[i]:g} > {k[i + 1]:g})")
    if np.any(k[: p + 1] != k[0]) or np.any(k[-(p + 1):] != k[-1]):
        raise InputError(f"{name}: not clamped (the first and last {p + 1} knots must be equal)")
    if not k[-1] > k[0]:
        raise InputError(f"{name}: empty parameter domain [{k[0]:g}, {k[-1]:g}]")
    inner = k[p + 1: n]
    if inner.size:
        _, counts = np.unique(inner, return_counts=True)
        if counts.max() > p:
            raise InputError(f"{name}: an interior knot repeats more than {p} times")
    return k
