"""Threshold fields: how the threshold C (and so the porosity) varies through a part.

A threshold field is any :class:`~porecad.fields.Field`; these helpers build
the common ones from small specs (used by recipes):

* ``{"kind": "constant", "value": C}``
* ``{"kind": "linear", "axis": "z", "start": a, "end": b, "from": C0, "to": C1}``:
  linear ramp of C along an axis between two coordinates, clamped outside;
* ``{"kind": "radial", "centre": [x, y, z], "axes": "xy", "r0": 0, "r1": R, "from": C0, "to": C1}``:
  ramp with the distance from a centre (in the given axes), clamped;
* ``{"kind": "expression", "expr": "0.3 + 0.02 * z"}``: a numpy expression in
  x, y, z (names: numpy functions, ``pi``; no builtins).

A spec may give ``porosity`` values instead of thresholds (``"of": "porosity"``):
the porosity field is then converted point-wise to thresholds through the
type's calibration curve (:func:`porecad.calibration.threshold_for_porosity`),
so a porosity gradient is exact cell by cell.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..fields.base import Constant, Field, FunctionField

_AXES = {"x": 0, "y": 1, "z": 2}
_SAFE = {k: getattr(np, k) for k in ("sin", "cos", "tan", "exp", "log", "sqrt", "abs", "minimum",
                                        "maximum", "clip", "where", "tanh", "arctan2", "hypot")}
_SAFE["pi"] = np.pi


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
        self.decreasing = structure in ("rod", "sheet")

    def _convert(self, p):
        p = np.clip(np.asarray(p, dtype=np.float64), self._p[0], self._p[-1])
        return np.interp(p, self._p, self._c)

    def evaluate(self, pts):
        return self._convert(self.porosity(pts))

    def sample_grid(self, xs, ys, zs):
        return self._convert(self.porosity.sample_grid(xs, ys, zs)).astype(np.float32)


def field_from_spec(spec) -> tuple[Field, str]:
    """Build a field from a spec dict; returns ``(field, of)`` with of in {'threshold', 'porosity'}."""
    if isinstance(spec, (int, float)):
        return Constant(float(spec)), "threshold"
    if not isinstance(spec, dict):
        raise InputError(f"a grading spec must be a table, got {type(spec).__name__}")
    of = str(spec.get("of", "threshold"))
    if of not in ("threshold", "porosity"):
        raise InputError("grading 'of' must be 'threshold' or 'porosity'")
    kind = str(spec.get("kind", "constant"))
    try:
        if kind == "constant":
            return Constant(float(spec["value"])), of
        if kind == "linear":
            ax = _AXES[str(spec.get("axis", "z")).lower()]
            return Ramp(spec["from"], spec["to"], spec["start"], spec["end"], axes=(ax,)), of
        if kind == "radial":
            axes = tuple(_AXES[c] for c in str(spec.get("axes", "xyz")).lower())
            return Ramp(spec["from"], spec["to"], spec.get("r0", 0.0), spec["r1"], axes=axes,
                        centre=spec.get("centre", (0.0, 0.0, 0.0))), of
        if kind == "expression":
            expr = str(spec["expr"])
            code = compile(expr, "<grading expression>", "eval")
            for name in code.co_names:
                if name not in _SAFE and name not in ("x", "y", "z"):
                    raise InputError(f"grading expression uses unknown name {name!r}")

            def func(x, y, z, _code=code):
                return eval(_code, {"__builtins__": {}}, {**_SAFE, "x": x, "y": y, "z": z})
            return FunctionField(func, name=expr), of
    except KeyError as exc:
        raise InputError(f"grading spec {kind!r} is missing {exc.args[0]!r}") from None
    except SyntaxError as exc:
        raise InputError(f"grading expression is not valid: {exc.msg}") from None
    raise InputError(f"unknown grading kind {kind!r}; use constant, linear, radial or expression")
