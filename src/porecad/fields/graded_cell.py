"""TPMS with a cell size graded along an axis, keeping the lattice continuous.

Scaling the coordinates by a varying cell size, ``φ(x / L(x))``, tears the
lattice apart where ``L`` changes fast (the phase ``x / L`` is not the
integral of the frequency). Here the phase along the grading axis ``s`` is
the integral of the local frequency,

.. math:: \\psi(s) = \\int_{s_0}^{s} \\frac{ds'}{L(s')},\\qquad
          L(s) = L_0 + (L_1 - L_0)\\,\\mathrm{clip}\\!\\left(\\frac{s - s_0}{s_1 - s_0}, 0, 1\\right),

which for the linear ramp is ``ln(L(s) / L_0) / k`` with ``k = (L_1 - L_0) /
(s_1 - s_0)`` (and ``(s - s_0) / L`` on the constant parts), and the phase
across it is ``(x_b - c_b) / L(s)`` about a centre ``c`` (the part's centre,
so the shear ``x_b L'(s) / L`` stays small). Every cell is a smooth, locally
affine image of the unit cell, so the lattice is continuous and the local
porosity is that of the threshold (volume fractions are affine-invariant) —
the form used for cell-size grading by Yoo (2012) and in 001's parameter
domain.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .base import Field
from .tpms import TPMSField

_AXES = {"x": 0, "y": 1, "z": 2}


class GradedCellTPMS(Field):
    """TPMS φ whose cell size ramps from ``L0`` at ``s = start`` to ``L1`` at ``s = end`` along ``axis``."""

    def __init__(self, tpms_type: str, L0: float, L1: float, axis="z", start=0.0, end=1.0,
                 centre=(0.0, 0.0, 0.0)):
        self.unit = TPMSField(tpms_type, 1.0)
        self.type = self.unit.type
        self.axis = _AXES[axis] if isinstance(axis, str) else int(axis)
        self.L0, self.L1 = float(L0), float(L1)
        self.s0, self.s1 = float(start), float(end)
        if not (np.isfinite(self.L0) and np.isfinite(self.L1)) or self.L0 <= 0 or self.L1 <= 0:
            raise InputError(f"graded cell sizes must be positive, got {L0} and {L1}")
        if self.s1 == self.s0:
            raise InputError("a cell-size ramp needs end != start")
        self.k = (self.L1 - self.L0) / (self.s1 - self.s0)
        self.centre = np.asarray(centre, dtype=float).reshape(3)

    @property
    def name(self) -> str:
        return self.type.name

    def cell_size_at(self, s):
        t = np.clip((np.asarray(s, dtype=float) - self.s0) / (self.s1 - self.s0), 0.0, 1.0)
        return self.L0 + (self.L1 - self.L0) * t

    def phase(self, s):
        """ψ(s) = ∫ ds / L(s) from ``start`` (in cells)."""
        s = np.asarray(s, dtype=float)
        lo, hi = min(self.s0, self.s1), max(self.s0, self.s1)
        sc = np.clip(s, lo, hi)
        if abs(self.k) * (hi - lo) < 1e-9 * self.L0:
            inner = (sc - self.s0) / self.L0
        else:
            inner = np.log(self.cell_size_at(sc) / self.L0) / self.k
        return inner + (s - sc) / self.cell_size_at(s)

    def mapped(self, points):
        p = np.asarray(points, dtype=float)
        s = p[:, self.axis]
        L = self.cell_size_at(s)
        u = (p - self.centre) / L[:, None]
        u[:, self.axis] = self.phase(s)
        return u

    def evaluate(self, points):
        return self.unit.evaluate(self.mapped(points))
