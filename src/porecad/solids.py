"""Volume structures from a TPMS value φ and a threshold C (document 001, section 3.1).

=========  =====================  ====================================
structure  material where         field (negative inside material)
=========  =====================  ====================================
pore       φ ≥ C                  C − φ
rod        φ ≤ C                  φ − C
sheet      |φ| ≤ C                |φ| − C
surface    the open level set     φ − C  (not a solid; not printable)
=========  =====================  ====================================

``C`` is a number or a field (a callable of x, y, z or a :class:`Field`):
a threshold distribution field grades porosity through the part. The
porosity of a structure is its void volume fraction.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError
from .fields.base import Constant, Field, as_field

STRUCTURES = ("pore", "rod", "sheet", "surface")
SOLID_STRUCTURES = ("pore", "rod", "sheet")


def check_structure(structure: str) -> str:
    s = str(structure).strip().lower()
    if s not in STRUCTURES:
        raise InputError(f"unknown structure {structure!r}; choose one of {', '.join(STRUCTURES)}")
    return s


class StructureField(Field):
    """The material field of a structure: negative where there is material.

    Parameters
    ----------
    phi : Field
        The TPMS value (or any level-set function).
    structure : {'pore', 'rod', 'sheet', 'surface'}
    threshold : float, callable or Field
        ``C``; for ``sheet`` the half-width of the band ``|φ - m| ≤ C`` (must be > 0).
    sheet_level : float, optional
        ``m``, the level the sheet is centred on: the TPMS type's ``sheet_level``
        when ``phi`` is a :class:`~porecad.fields.tpms.TPMSField` (0 for every
        type but the Lidinoid), else 0.
    """

    def __init__(self, phi: Field, structure: str, threshold=0.0, sheet_level: float | None = None):
        self.phi = phi
        self.structure = check_structure(structure)
        if sheet_level is None:
            sheet_level = getattr(getattr(phi, "type", None), "sheet_level", 0.0)
        self.sheet_level = float(sheet_level)
        self.threshold = as_field(threshold)
        if self.structure == "sheet" and isinstance(self.threshold, Constant) and self.threshold.value <= 0:
            raise InputError("a sheet needs a positive threshold C (material where |φ| ≤ C)")

    @property
    def closed(self) -> bool:
        """Whether the structure is a solid (to be capped and closed)."""
        return self.structure != "surface"

    def _combine(self, phi, c):
        if self.structure == "pore":
            return c - phi
        if self.structure == "sheet":
            return np.abs(phi - self.sheet_level) - c
        return phi - c

    def evaluate(self, points):
        return self._combine(self.phi(points), self.threshold(points))

    def sample_grid(self, xs, ys, zs):
        phi = self.phi.sample_grid(xs, ys, zs)
        if isinstance(self.threshold, Constant):
            c = np.float32(self.threshold.value)
        else:
            c = self.threshold.sample_grid(xs, ys, zs)
        if self.structure == "pore":
            np.subtract(c, phi, out=phi)
        elif self.structure == "sheet":
            if self.sheet_level:
                np.subtract(phi, np.float32(self.sheet_level), out=phi)
            np.abs(phi, out=phi)
            np.subtract(phi, c, out=phi)
        else:
            np.subtract(phi, c, out=phi)
        return phi
