"""Grading fields: how the threshold C, the porosity or the cell size varies through a part.

A grading field is any :class:`~porecad.fields.Field`; these helpers build
the common ones from a recipe's ``[grading]`` table (checked into a :class:`Grading`):

* ``{"kind": "constant", "value": v}``
* ``{"kind": "linear", "axis": "z", "start": a, "end": b, "from": v0, "to": v1}``:
  axial ramp between two coordinates, clamped outside;
* ``{"kind": "radial", "centre": [x, y, z], "axes": "xy", "r0": 0, "r1": R, "from": v0, "to": v1}``:
  ramp with the distance from a centre (in the given axes), clamped;
* ``{"kind": "expression", "expr": "0.5 + 0.3 * dn"}``: a numpy expression in
  ``x, y, z`` and, inside a body, ``d`` (depth below the body surface in mm,
  positive inside) and ``dn = d / max_depth`` (0 at the surface, 1 at the
  deepest point). Names: numpy functions, ``pi``; no builtins;
* ``{"kind": "distance", "from": v_surface, "to": v_core, "d0": 0, "d1": D, "exponent": 1}``:
  Yoo's distance-field grading (Yoo 2012, cited in 001):
  ``v = from + (to - from) * clip((d - d0) / (d1 - d0), 0, 1) ** exponent``
  (``d1`` defaults to the body's largest depth);
* ``{"kind": "points", "points": [[x, y, z, v], ...]}`` or ``{"kind": "points", "file": "p.csv"}``:
  values at scattered points interpolated by a thin-plate spline RBF (Yoo
  2012), clamped to the range of the given values (thin plates overshoot);
* ``{"kind": "image", "path": "map.nii.gz", "scale": 1, "offset": 0}``: a
  voxel map, ``v = offset + scale * I(p)`` trilinear in the image's physical
  coordinates (nearest edge value outside it).

A spec may give ``porosity`` values instead of thresholds (``"of": "porosity"``):
the porosity field is then converted point-wise to thresholds through the
type's calibration curve (:func:`porecad.calibration.threshold_for_porosity`),
so a porosity gradient is exact cell by cell. Costly fields (depth, RBF,
images) are sampled on a coarse grid (an eighth of a cell) and interpolated
(:mod:`porecad.fields.gridded`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..fields.base import Constant, Field

_AXES = {"x": 0, "y": 1, "z": 2}
#: the variables of a grading expression (``d`` and ``dn`` need a body)
GRADING_VARIABLES = ("x", "y", "z", "d", "dn")


class Ramp(Field):
    """``from + (to - from) * clamp((s - start) / (end - start), 0, 1)`` with ``s`` a coordinate or a radius."""

    def __init__(self, value_from, value_to, start, end, axes=(2,), centre=None):
        if end == start:
            raise InputError("a ramp needs end != start")
        self.v0, self.v1 = float(value_from), float(value_to)
        self.s0, self.s1 = float(start), float(end)
        self.axes = tuple(axes)
        self.centre = None if centre is None else np.asarray(centre, dtype=float)

    def _s(self, p):
        if self.centre is None:
            return p[:, self.axes[0]]
        d = p[:, self.axes] - self.centre[list(self.axes)]
        return np.linalg.norm(d, axis=1)

    def evaluate(self, p):
        t = np.clip((self._s(p) - self.s0) / (self.s1 - self.s0), 0.0, 1.0)
        return self.v0 + (self.v1 - self.v0) * t


class PorosityToThreshold(Field):
    """Threshold field from a porosity field through a type's calibration curve."""

    def __init__(self, porosity: Field, tpms_type: str, structure: str):
        from ..calibration import threshold_for_porosity
        self.porosity = porosity
        ps = np.linspace(0.005, 0.995, 397)
        self._p = ps
        self._c = np.asarray(threshold_for_porosity(tpms_type, structure, ps))

    def _convert(self, p):
        p = np.clip(np.asarray(p, dtype=np.float64), self._p[0], self._p[-1])
        return np.interp(p, self._p, self._c)

    def evaluate(self, pts):
        return self._convert(self.porosity(pts))

    def sample_grid(self, xs, ys, zs):
        return self._convert(self.porosity.sample_grid(xs, ys, zs)).astype(np.float32)


class GradingContext:
    """What a grading spec may refer to: the design box and, for a body, its depth field.

    Parameters
    ----------
    box_min, box_max : (3,) float
        The box the coarse caches cover.
    coarse_spacing : float
        Spacing of coarse caches (mm).
    depth : callable, optional
        ``depth() -> BodyDepth``, called once on first use (it costs a pass
        over the body).
    """

    def __init__(self, box_min, box_max, coarse_spacing: float, depth=None):
        self.box_min = np.asarray(box_min, dtype=float)
        self.box_max = np.asarray(box_max, dtype=float)
        self.coarse_spacing = float(coarse_spacing)
        self._depth_factory = depth
        self._depth = None

    @property
    def has_body(self) -> bool:
        return self._depth_factory is not None

    def depth(self):
        if self._depth_factory is None:
            raise InputError("depth d (and dn, distance grading) needs a body domain")
        if self._depth is None:
            self._depth = self._depth_factory()
        return self._depth


class ExpressionField(Field):
    """A numpy expression in ``x, y, z`` and (with a body) ``d, dn``.

    Parsed and checked by the safe evaluator :mod:`porecad.expressions`
    (numbers, these variables, arithmetic, comparisons and a whitelist of
    numpy functions; nothing is ``eval``-ed).
    """

    def __init__(self, expr: str, context: GradingContext | None):
        from ..expressions import ExpressionError, compile_expression
        try:
            self.compiled = compile_expression(expr, GRADING_VARIABLES)
        except ExpressionError as exc:
            raise InputError(f"grading expression is not valid: {exc}") from None
        names = self.compiled.names
        if names & {"d", "dn"} and not (context is not None and context.has_body):
            raise InputError("grading expression uses depth below the body surface: d and dn need a body")
        self.expr = expr
        self.depth = context.depth() if names & {"d", "dn"} else None

    def _eval(self, x, y, z, d):
        env = {"x": x, "y": y, "z": z}
        if d is not None:
            env["d"] = d
            env["dn"] = d / max(self.depth.max_depth, 1e-12)
        val = self.compiled(**env)
        if not np.all(np.isfinite(val)):
            raise InputError("grading expression gives non-finite values in the domain (division by zero, "
                             "overflow, or a logarithm or square root of a negative number)")
        return val

    def evaluate(self, points):
        d = None if self.depth is None else self.depth.evaluate(points)
        val = self._eval(points[:, 0], points[:, 1], points[:, 2], d)
        return np.broadcast_to(np.asarray(val, dtype=np.float64), (len(points),))

    def sample_grid(self, xs, ys, zs):
        d = None if self.depth is None else self.depth.sample_grid(xs, ys, zs).astype(np.float64)
        val = self._eval(np.asarray(xs, dtype=np.float64)[None, None, :], np.asarray(ys, dtype=np.float64)[None, :, None],
                         np.asarray(zs, dtype=np.float64)[:, None, None], d)
        return np.ascontiguousarray(np.broadcast_to(np.asarray(val, dtype=np.float32),
                                                    (len(zs), len(ys), len(xs))))

class DepthRamp(Field):
    """Yoo's distance-field grading: ``v0 + (v1 - v0) * clip((d - d0) / (d1 - d0), 0, 1) ** e``."""

    def __init__(self, depth, v0, v1, d0=0.0, d1=None, exponent=1.0):
        self.depth = depth
        self.v0, self.v1 = float(v0), float(v1)
        self.d0 = float(d0)
        self.d1 = float(depth.max_depth if d1 is None else d1)
        self.exponent = float(exponent)
        if self.d1 <= self.d0:
            raise InputError(f"distance grading needs d1 > d0 (d1 = {self.d1:g} mm)")
        if self.exponent <= 0:
            raise InputError("distance grading exponent must be positive")

    def _map(self, d):
        t = np.clip((d - self.d0) / (self.d1 - self.d0), 0.0, 1.0) ** self.exponent
        return self.v0 + (self.v1 - self.v0) * t

    def evaluate(self, points):
        return self._map(self.depth.evaluate(points))

    def sample_grid(self, xs, ys, zs):
        return self._map(self.depth.sample_grid(xs, ys, zs)).astype(np.float32)


#: distinct points a global thin-plate spline takes (a 2,000 x 2,000 dense system: 32 MB, about a second)
GLOBAL_POINTS = 2000
#: nearest points each value is interpolated from beyond that
LOCAL_NEIGHBOURS = 64


def check_spread(p) -> None:
    """Refuse grading points that lie in one plane or on one line (the spline's system is then singular)."""
    c = np.asarray(p, np.float64) - np.mean(p, axis=0)
    sv = np.linalg.svd(c, compute_uv=False)
    if sv[0] == 0.0 or sv[-1] <= 1e-9 * sv[0]:
        shape = "on one line" if sv[1] <= 1e-9 * sv[0] else "in one plane"
        raise InputError(f"point grading: the {len(p)} points lie {shape}; a spline in x, y, z needs points "
                         "spread in all three directions: add points off it (or grade with an expression)")


class ThinPlateField(Field):
    """Thin-plate spline RBF through scattered values (scipy's ``RBFInterpolator``), clamped to their range."""

    def __init__(self, points, values, smoothing: float = 0.0):
        from scipy.interpolate import RBFInterpolator

        p = np.asarray(points, dtype=np.float64)
        v = np.asarray(values, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) != len(v) or len(p) < 4:
            raise InputError("point grading needs at least 4 points given as x, y, z, value")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise InputError("point grading values must be finite numbers")
        # repeated positions make the spline's system singular: one point each, with the mean value
        p, inverse = np.unique(p, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        v = np.bincount(inverse, weights=v) / np.bincount(inverse)
        if len(p) < 4:
            raise InputError("point grading needs at least 4 distinct points")
        # a global spline solves a dense n x n system (n^2 memory, n^3 time): beyond GLOBAL_POINTS distinct
        # points each value comes from its LOCAL_NEIGHBOURS nearest points (scipy's local RBF mode)
        neighbours = None if len(p) <= GLOBAL_POINTS else LOCAL_NEIGHBOURS
        check_spread(p)
        try:
            self.rbf = RBFInterpolator(p, v, kernel="thin_plate_spline", smoothing=float(smoothing), degree=1,
                                       neighbors=neighbours)
        except (ValueError, np.linalg.LinAlgError) as exc:  # say what about the points caused it
            raise InputError(f"point grading: the spline through the {len(p)} points cannot be solved "
                             f"(SciPy: {str(exc).split('.')[0]}); points nearly in one plane or nearly on top "
                             "of each other cause this: spread them in x, y and z, or merge close ones") from None
        self.lo, self.hi = float(v.min()), float(v.max())

    def evaluate(self, points):
        out = np.empty(len(points))
        for a in range(0, len(points), 65536):
            out[a:a + 65536] = self.rbf(points[a:a + 65536])
        return np.clip(out, self.lo, self.hi)


def _read_points(g: Grading) -> np.ndarray:
    if g.points is not None:
        arr = np.asarray(g.points, dtype=float)
    else:
        from ..fields.rbf_centres import read_points
        path = g.file
        if not os.path.isfile(path):
            raise InputError(f"{path}: no such file (point grading CSV)")
        # bounded, one-line errors that name the line, never quote it
        pts, vals = read_points(path)
        arr = np.column_stack([pts, vals])
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError("point grading needs rows of x, y, z, value")
    return arr


class ImageMapField(Field):
    """``offset + scale * I(p)``: an image's values, trilinear in its physical coordinates."""

    def __init__(self, path, scale=1.0, offset=0.0):
        from ..bodies.image import read_image
        self.array, self.geometry = read_image(path)
        self.array = self.array.astype(np.float32)
        self.scale, self.offset = float(scale), float(offset)

    def evaluate(self, points):
        from scipy import ndimage

        from ..bodies.image import physical_to_index
        ijk = physical_to_index(points, self.geometry)
        vals = ndimage.map_coordinates(self.array, ijk.T, order=1, mode="nearest")
        return self.offset + self.scale * vals.astype(np.float64)


@dataclass(frozen=True)
class Grading:
    """A checked ``[grading]`` table: its kind's keys (the others None); ``value_from``/``value_to`` are its
    ``from``/``to``. The fields are in the order of each kind's keys in the table (:meth:`table`)."""

    kind: str
    of: str  # "threshold" or "porosity"
    value: float | None = None
    axis: str | None = None
    start: float | None = None
    end: float | None = None
    axes: str | None = None
    centre: list | None = None
    r0: float | None = None
    r1: float | None = None
    d0: float | None = None
    exponent: float | None = None
    value_from: float | None = None
    value_to: float | None = None
    d1: float | None = None
    expr: str | None = None
    file: str | None = None
    points: list | None = None
    smoothing: float | None = None
    path: str | None = None
    scale: float | None = None
    offset: float | None = None

    def table(self) -> dict:
        """The table's keys given (the report's ``grading``)."""
        names = {"value_from": "from", "value_to": "to"}
        return {names.get(k, k): v for k, v in vars(self).items() if v is not None}


def field_from_spec(g: Grading, context: GradingContext | None = None) -> tuple[Field, str]:
    """Build the field of a checked grading; returns ``(field, of)`` with of in {'threshold', 'porosity'}."""
    from ..fields.gridded import cache_on_grid

    of, kind = g.of, g.kind

    def cached(field):
        if context is None:
            return field
        return cache_on_grid(field, context.box_min, context.box_max, context.coarse_spacing)
    try:
        if kind == "constant":
            return Constant(float(g.value)), of
        if kind == "linear":
            return Ramp(g.value_from, g.value_to, g.start, g.end, axes=(_AXES[g.axis],)), of
        if kind == "radial":
            return Ramp(g.value_from, g.value_to, g.r0, g.r1, axes=tuple(_AXES[c] for c in g.axes),
                        centre=g.centre), of
        if kind == "expression":
            return ExpressionField(g.expr, context), of
        if kind == "distance":
            if context is None or not context.has_body:
                raise InputError("distance grading needs a body domain")
            return DepthRamp(context.depth(), g.value_from, g.value_to, g.d0, g.d1, g.exponent), of
        if kind == "points":
            arr = _read_points(g)
            return cached(ThinPlateField(arr[:, :3], arr[:, 3], g.smoothing)), of
        if kind == "image":
            return cached(ImageMapField(g.path, g.scale, g.offset)), of
    except (TypeError, ValueError) as exc:
        raise InputError(f"grading spec {kind!r}: {exc}") from None
    raise InputError(f"unknown grading kind {kind!r}; use constant, linear, radial, expression, distance, "
                     "points or image")
