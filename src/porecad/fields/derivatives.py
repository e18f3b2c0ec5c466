"""Exact first and second derivatives of fields, for curvature and projection.

A catalogue TPMS (:mod:`porecad.fields.tpms`) is a sum of separable terms

.. math:: \\varphi = c_0 + \\sum_t a_t \\prod_{i=1}^{3} f_{t,i}(k_{t,i}\\,\\theta_i),
          \\qquad \\theta_i = \\omega_i (x_i - o_i),\\quad \\omega_i = 2\\pi / L_i,

with ``f`` one of ``cos``, ``sin``, ``1``. Each factor is differentiated in
closed form: ``d/dx_i f(kθ_i) = k ω_i f'(kθ_i)`` (``cos' = -sin``,
``sin' = cos``) and ``d²/dx_i² f(kθ_i) = -(k ω_i)² f(kθ_i)``; the gradient and
Hessian are then sums of products of per-axis values and derivatives, e.g.
``∂²φ/∂x∂y = Σ_t a_t f'_x f'_y f_z``. No finite differences are involved, so
the derivatives are exact to rounding for all 13 catalogue types (and any
type added to the catalogue in the same term form).

Other fields fall back to central finite differences
(:func:`finite_difference_derivatives`); :func:`field_derivatives` also
understands the thin wrappers a TPMS travels in (``StructureField`` with a
constant threshold, :class:`~porecad.fields.base.Negate`,
:class:`~porecad.fields.base.Offset`), so the level set of a ``pore``/``rod``/
``surface`` structure is still differentiated exactly.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .tpms import TPMSField


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"derivatives take an (N, 3) array of points, got shape {p.shape}")
    return p


def _factor_derivs(fn: str, k: int, theta: np.ndarray, w: float):
    """Value, first and second x-derivative of ``fn(k * theta)`` with ``theta = w x + const``."""
    if fn == "1":
        one = np.ones_like(theta)
        zero = np.zeros_like(theta)
        return one, zero, zero
    kw = k * w
    c = np.cos(k * theta)
    s = np.sin(k * theta)
    if fn == "cos":
        return c, -kw * s, -kw * kw * c
    if fn == "sin":
        return s, kw * c, -kw * kw * s
    raise ValueError(f"unknown factor {fn!r}")  # pragma: no cover - catalogue is parsed


def tpms_derivatives(field: TPMSField, points, order: int = 2):
    """Value, gradient and Hessian of a :class:`TPMSField` at ``points``, analytically.

    Parameters
    ----------
    field : TPMSField
    points : (m, 3) array_like
        Points in mm.
    order : {1, 2}
        ``1`` skips the Hessian (returned as None).

    Returns
    -------
    value : (m,) float64
    grad : (m, 3) float64
        ``∂φ/∂x_i`` in 1/mm.
    hess : (m, 3, 3) float64 or None
        ``∂²φ/∂x_i∂x_j`` in 1/mm², symmetric.
    """
    p = _points(points)
    m = len(p)
    w = 2.0 * np.pi / field.cell_size
    theta = [field.angles(p[:, a], a) for a in range(3)]
    cache = {}

    def fac(a, fn, k):
        key = (a, fn, k)
        if key not in cache:
            cache[key] = _factor_derivs(fn, k, theta[a], w[a])
        return cache[key]

    value = np.full(m, float(field.type.constant))
    grad = np.zeros((m, 3))
    hess = np.zeros((m, 3, 3)) if order >= 2 else None
    for term in field.type.terms:
        f = [fac(a, fn, k) for a, (fn, k) in enumerate(term.funcs)]
        v = [f[a][0] for a in range(3)]
        d1 = [f[a][1] for a in range(3)]
        c = term.coef
        value += c * v[0] * v[1] * v[2]
        grad[:, 0] += c * d1[0] * v[1] * v[2]
        grad[:, 1] += c * v[0] * d1[1] * v[2]
        grad[:, 2] += c * v[0] * v[1] * d1[2]
        if hess is not None:
            d2 = [f[a][2] for a in range(3)]
            hess[:, 0, 0] += c * d2[0] * v[1] * v[2]
            hess[:, 1, 1] += c * v[0] * d2[1] * v[2]
            hess[:, 2, 2] += c * v[0] * v[1] * d2[2]
            hess[:, 0, 1] += c * d1[0] * d1[1] * v[2]
            hess[:, 0, 2] += c * d1[0] * v[1] * d1[2]
            hess[:, 1, 2] += c * v[0] * d1[1] * d1[2]
    if hess is not None:
        hess[:, 1, 0] = hess[:, 0, 1]
        hess[:, 2, 0] = hess[:, 0, 2]
        hess[:, 2, 1] = hess[:, 1, 2]
    return value, grad, hess


def finite_difference_derivatives(field, points, h: float = 1e-4):
    """Value, gradient and Hessian by central differences with step ``h`` (mm).

    Truncation error O(h²); rounding error about ``eps |f| / h²`` in the
    Hessian, so ``h ≈ 1e-4 × (feature size)`` is a good choice for float64
    fields. The fallback for fields without analytic derivatives.
    """
    p = _points(points)
    m = len(p)
    f0 = field(p)
    grad = np.zeros((m, 3))
    hess = np.zeros((m, 3, 3))
    e = np.eye(3) * h
    fp = [field(p + e[a]) for a in range(3)]
    fm = [field(p - e[a]) for a in range(3)]
    for a in range(3):
        grad[:, a] = (fp[a] - fm[a]) / (2 * h)
        hess[:, a, a] = (fp[a] - 2 * f0 + fm[a]) / (h * h)
        for b in range(a + 1, 3):
            d = (field(p + e[a] + e[b]) - field(p + e[a] - e[b])
                 - field(p - e[a] + e[b]) + field(p - e[a] - e[b])) / (4 * h * h)
            hess[:, a, b] = hess[:, b, a] = d
    return f0, grad, hess


def _unwrap(field):
    """``(inner TPMSField, sign, shift)`` with ``field = sign * (inner - shift)``, or None.

    Recognises ``StructureField`` (pore, rod, surface; constant threshold),
    ``Negate`` and ``Offset`` around a :class:`TPMSField`. Sheets (``|φ - m| - C``)
    are not smooth at ``φ = m`` and are handled by :func:`field_derivatives` directly.
    """
    from ..solids import StructureField
    from .base import Constant
    from .base import Negate, Offset
    sign, shift = 1.0, 0.0
    f = field
    for _ in range(32):
        if isinstance(f, TPMSField):
            return f, sign, shift
        if isinstance(f, Negate):   # s (-a - shift) = -s (a + shift)
            sign, shift, f = -sign, -shift, f.a
            continue
        if isinstance(f, Offset):   # s (a - d - shift) = s (a - (shift + d))
            shift, f = shift + f.d, f.a
            continue
        if isinstance(f, StructureField) and isinstance(getattr(f, "threshold", None), Constant):
            c = float(f.threshold.value)
            if f.structure == "pore":      # s (C - φ - shift) = -s (φ - (C - shift))
                sign, shift, f = -sign, c - shift, f.phi
                continue
            if f.structure in ("rod", "surface"):   # φ - C
                shift, f = shift + c, f.phi
                continue
        return None
    return None


def field_derivatives(field, points, fd_step: float | None = None, order: int = 2):
    """Value, gradient and Hessian of any field at ``points``: exact where possible.

    Analytic for a :class:`TPMSField` and for the wrappers listed in
    :func:`_unwrap`, and for a ``sheet`` ``StructureField`` over a TPMS
    (``|φ - m| - C``: the derivatives of ``±(φ - m)``, sign taken per point);
    central finite differences otherwise (step ``fd_step`` mm, default 1e-4
    times the field's cell size if it has one, else 1e-4 mm).

    Returns ``(value (m,), grad (m, 3), hess (m, 3, 3))`` in the field's units;
    with ``order=1`` the Hessian may be None (analytic paths skip it).
    """
    p = _points(points)
    un = _unwrap(field)
    if un is not None:
        inner, sign, shift = un
        v, g, H = tpms_derivatives(inner, p, order=order)
        return sign * (v - shift), sign * g, (None if H is None else sign * H)
    from ..solids import StructureField
    from .base import Constant
    if (isinstance(field, StructureField) and field.structure == "sheet"
            and isinstance(field.threshold, Constant)):
        un = _unwrap(field.phi)
        if un is not None:
            inner, sign, shift = un
            v, g, H = tpms_derivatives(inner, p, order=order)
            d = sign * (v - shift) - field.sheet_level
            s = np.where(d < 0, -1.0, 1.0) * sign
            return (np.abs(d) - float(field.threshold.value), g * s[:, None],
                    None if H is None else H * s[:, None, None])
    if fd_step is None:
        L = getattr(field, "cell_size", None)
        fd_step = 1e-4 * (float(np.min(L)) if L is not None else 1.0)
    return finite_difference_derivatives(field, p, h=fd_step)
