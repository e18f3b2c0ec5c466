"""Field algebra: Boolean combinations, offsets, shells and smooth blends.

All operators keep the convention *negative inside*. Sharp Booleans use
min/max (Ricci 1973); the smooth union is the polynomial smooth minimum
``min(a, b) - h^2 k / 4`` with ``h = max(k - |a - b|, 0) / k`` (Quilez), whose
blend radius is ``k`` mm. Document 003's shape-preserving blend plugs in here
with the vascular issue: see :mod:`porecad.fields.blends` (Li's C^n union
``g_uni_{n,δ}``, sharp, soft max and R-functions; ``BlendUnion``).
"""

from __future__ import annotations

import numpy as np

from .base import Field


class _Binary(Field):
    def __init__(self, a: Field, b: Field):
        self.a, self.b = a, b


class Union(_Binary):
    """``min(a, b)``: inside either."""

    def evaluate(self, points):
        return np.minimum(self.a(points), self.b(points))

    def sample_grid(self, xs, ys, zs):
        return np.minimum(self.a.sample_grid(xs, ys, zs), self.b.sample_grid(xs, ys, zs))


class Intersection(_Binary):
    """``max(a, b)``: inside both."""

    def evaluate(self, points):
        return np.maximum(self.a(points), self.b(points))

    def sample_grid(self, xs, ys, zs):
        return np.maximum(self.a.sample_grid(xs, ys, zs), self.b.sample_grid(xs, ys, zs))


class Negate(Field):
    """``-f``: the complement."""

    def __init__(self, a: Field):
        self.a = a

    def evaluate(self, points):
        return -self.a(points)

    def sample_grid(self, xs, ys, zs):
        return np.negative(self.a.sample_grid(xs, ys, zs))


class Offset(Field):
    """``f - d``: grows the inside by ``d`` for a distance field."""

    def __init__(self, a: Field, d: float):
        self.a, self.d = a, float(d)

    def evaluate(self, points):
        return self.a(points) - self.d

    def sample_grid(self, xs, ys, zs):
        return self.a.sample_grid(xs, ys, zs) - np.float32(self.d)


class Shell(Field):
    """``|f| - t/2``: a wall of thickness ``t`` around ``f = 0`` for a distance field."""

    def __init__(self, a: Field, thickness: float):
        self.a, self.t = a, float(thickness)

    def evaluate(self, points):
        return np.abs(self.a(points)) - 0.5 * self.t

    def sample_grid(self, xs, ys, zs):
        return np.abs(self.a.sample_grid(xs, ys, zs)) - np.float32(0.5 * self.t)


class SmoothUnion(_Binary):
    """Polynomial smooth minimum with blend radius ``k`` (mm)."""

    def __init__(self, a: Field, b: Field, k: float):
        super().__init__(a, b)
        self.k = float(k)

    @staticmethod
    def _blend(a, b, k):
        h = np.maximum(k - np.abs(a - b), 0.0) / k
        return np.minimum(a, b) - h * h * k * 0.25

    def evaluate(self, points):
        return self._blend(self.a(points), self.b(points), self.k)

    def sample_grid(self, xs, ys, zs):
        return self._blend(self.a.sample_grid(xs, ys, zs), self.b.sample_grid(xs, ys, zs),
                           np.float32(self.k)).astype(np.float32)
