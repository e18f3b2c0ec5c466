"""The field abstraction and its algebra.

A field maps an ``(N, 3)`` array of points (mm) to ``(N,)`` values.
Convention everywhere in porecad: **negative inside material, positive
outside, zero on the surface** (the signed-distance convention). Fields
compose like fogleman/sdf's operators: ``a | b`` union (min), ``a & b``
intersection (max), ``a - b`` difference, ``-a`` complement, plus offset,
shell and smooth blends in :mod:`porecad.fields.csg`.

Every field can also be sampled on a tensor grid (:meth:`Field.sample_grid`),
which is what the chunked polygoniser calls; fields with structure (the
separable TPMS sums) override it with fast kernels.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


class Field:
    """Base class: subclasses implement :meth:`evaluate` and may override :meth:`sample_grid`."""

    def evaluate(self, points: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def __call__(self, points) -> np.ndarray:
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"a field takes an (N, 3) array of points, got shape {pts.shape}")
        return np.asarray(self.evaluate(pts), dtype=np.float64).reshape(len(pts))

    def sample_grid(self, xs, ys, zs) -> np.ndarray:
        """Values on the tensor grid ``zs x ys x xs`` as ``(len(zs), len(ys), len(xs))`` float32.

        The default evaluates plane by plane (memory: one plane of points).
        """
        xs = np.asarray(xs, dtype=np.float64)
        ys = np.asarray(ys, dtype=np.float64)
        zs = np.asarray(zs, dtype=np.float64)
        out = np.empty((len(zs), len(ys), len(xs)), dtype=np.float32)
        gx, gy = np.meshgrid(xs, ys)
        pts = np.empty((gx.size, 3), dtype=np.float64)
        pts[:, 0] = gx.ravel()
        pts[:, 1] = gy.ravel()
        for k, z in enumerate(zs):
            pts[:, 2] = z
            out[k] = self.evaluate(pts).reshape(len(ys), len(xs))
        return out

    # ---- algebra -------------------------------------------------------
    def __or__(self, other):
        from .csg import Union
        return Union(self, as_field(other))

    def __and__(self, other):
        from .csg import Intersection
        return Intersection(self, as_field(other))

    def __sub__(self, other):
        from .csg import Intersection, Negate
        return Intersection(self, Negate(as_field(other)))

    def __neg__(self):
        from .csg import Negate
        return Negate(self)

    def offset(self, d: float):
        """Grow (d > 0) or shrink the inside by ``d``: ``f - d``."""
        from .csg import Offset
        return Offset(self, d)

    def shell(self, thickness: float):
        """Thin wall of the given thickness around the surface: ``|f| - t/2``."""
        from .csg import Shell
        return Shell(self, thickness)


class FunctionField(Field):
    """A field from a Python callable ``f(x, y, z) -> values`` on numpy arrays."""

    def __init__(self, func, name: str | None = None):
        if not callable(func):
            raise InputError("a function field needs a callable f(x, y, z)")
        self.func = func
        self.name = name or getattr(func, "__name__", "function")

    def evaluate(self, points):
        return np.broadcast_to(
            np.asarray(self.func(points[:, 0], points[:, 1], points[:, 2]), dtype=np.float64),
            (len(points),))

    def sample_grid(self, xs, ys, zs):
        z = np.asarray(zs, dtype=np.float64)[:, None, None]
        y = np.asarray(ys, dtype=np.float64)[None, :, None]
        x = np.asarray(xs, dtype=np.float64)[None, None, :]
        val = np.asarray(self.func(x, y, z), dtype=np.float32)
        return np.ascontiguousarray(np.broadcast_to(val, (len(zs), len(ys), len(xs))))


class Constant(Field):
    """A constant field (used for constant thresholds)."""

    def __init__(self, value: float):
        self.value = float(value)

    def evaluate(self, points):
        return np.full(len(points), self.value)

    def sample_grid(self, xs, ys, zs):
        return np.full((len(zs), len(ys), len(xs)), self.value, dtype=np.float32)


def as_field(obj) -> Field:
    """Turn a number, a callable ``f(x, y, z)`` or a Field into a Field."""
    if isinstance(obj, Field):
        return obj
    if isinstance(obj, (int, float, np.floating, np.integer)):
        return Constant(float(obj))
    if callable(obj):
        return FunctionField(obj)
    raise InputError(f"cannot use {type(obj).__name__} as a field")
