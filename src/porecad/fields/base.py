"""The field abstraction and its algebra (Booleans, offsets, shells, smooth union).

A field maps an ``(N, 3)`` array of points (mm) to ``(N,)`` values.
Convention everywhere in porecad: **negative inside material, positive
outside, zero on the surface** (the signed-distance convention). Fields
compose like fogleman/sdf's operators: ``a | b`` union (min), ``a & b``
intersection (max), ``a - b`` difference, ``-a`` complement, plus offset,
shell and the smooth union here; document 003's blends in
:mod:`porecad.fields.blends`.

Sharp Booleans use min/max (Ricci 1973); the smooth union is the polynomial
smooth minimum ``min(a, b) - h^2 k / 4`` with ``h = max(k - |a - b|, 0) / k``
(Quilez), whose blend radius is ``k`` mm.

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

    @property
    def bounds(self):
        """``(lo, hi)`` of a box holding the inside (material), or None when it is unbounded (a lattice)."""
        return None

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

    def evaluate_lattice(self, points) -> np.ndarray:
        """Values at a curvilinear lattice of points ``(n1, n2, n3, 3)`` (a mapped grid) as ``(n1, n2, n3)``
        float64; fields that can use the lattice's order (:class:`porecad.bodies.mesh.MeshBody`) override it."""
        p = np.asarray(points, dtype=np.float64)
        return np.asarray(self(p.reshape(-1, 3)), dtype=np.float64).reshape(p.shape[:3])

    # ---- algebra -------------------------------------------------------
    def __or__(self, other):
        return Union(self, as_field(other))

    def __and__(self, other):
        return Intersection(self, as_field(other))

    def __sub__(self, other):
        return Intersection(self, Negate(as_field(other)))

    def __neg__(self):
        return Negate(self)

    def offset(self, d: float):
        """Grow (d > 0) or shrink the inside by ``d``: ``f - d``."""
        return Offset(self, d)

    def shell(self, thickness: float):
        """Thin wall of the given thickness around the surface: ``|f| - t/2``."""
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


def lattice_values(field, points) -> np.ndarray:
    """``field`` (a :class:`Field` or a callable of ``(N, 3)`` points) at a lattice ``(n1, n2, n3, 3)``."""
    p = np.asarray(points, dtype=np.float64)
    if isinstance(field, Field):
        return field.evaluate_lattice(p)
    return np.asarray(field(p.reshape(-1, 3)), dtype=np.float64).reshape(p.shape[:3])


def as_field(obj) -> Field:
    """Turn a number, a callable ``f(x, y, z)`` or a Field into a Field."""
    if isinstance(obj, Field):
        return obj
    if isinstance(obj, (int, float, np.floating, np.integer)):
        return Constant(float(obj))
    if callable(obj):
        return FunctionField(obj)
    raise InputError(f"cannot use {type(obj).__name__} as a field")


class _Binary(Field):
    def __init__(self, a: Field, b: Field):
        self.a, self.b = a, b


class Union(_Binary):
    """``min(a, b)``: inside either."""

    @property
    def bounds(self):
        ba, bb = self.a.bounds, self.b.bounds
        if ba is None or bb is None:
            return None
        return np.minimum(ba[0], bb[0]), np.maximum(ba[1], bb[1])

    def evaluate(self, points):
        return np.minimum(self.a(points), self.b(points))

    def sample_grid(self, xs, ys, zs):
        return np.minimum(self.a.sample_grid(xs, ys, zs), self.b.sample_grid(xs, ys, zs))


class Intersection(_Binary):
    """``max(a, b)``: inside both."""

    @property
    def bounds(self):
        ba, bb = self.a.bounds, self.b.bounds
        if ba is None or bb is None:
            return ba if bb is None else bb
        return np.maximum(ba[0], bb[0]), np.minimum(ba[1], bb[1])

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

    @property
    def bounds(self):
        b = self.a.bounds
        return None if b is None else (b[0] - max(self.d, 0.0), b[1] + max(self.d, 0.0))

    def evaluate(self, points):
        return self.a(points) - self.d

    def sample_grid(self, xs, ys, zs):
        return self.a.sample_grid(xs, ys, zs) - np.float32(self.d)


class Shell(Field):
    """``|f| - t/2``: a wall of thickness ``t`` around ``f = 0`` for a distance field."""

    def __init__(self, a: Field, thickness: float):
        self.a, self.t = a, float(thickness)

    @property
    def bounds(self):
        b = self.a.bounds
        return None if b is None else (b[0] - 0.5 * self.t, b[1] + 0.5 * self.t)

    def evaluate(self, points):
        return np.abs(self.a(points)) - 0.5 * self.t

    def sample_grid(self, xs, ys, zs):
        return np.abs(self.a.sample_grid(xs, ys, zs)) - np.float32(0.5 * self.t)
