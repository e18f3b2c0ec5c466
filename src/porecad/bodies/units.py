"""Units of a body mesh: scale one given in another unit on load, and say when its size is implausible.

Meshes carry no unit; porecad works in millimetres. CAD exports are often in
metres (a femur 0.47 long), micro-CT surfaces in micrometres, some in inches.
A body whose smallest extent holds fewer than two cells, or whose largest
extent is over a metre, is very likely in another unit: :func:`units_finding`
names the likely one.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..findings import Finding

#: millimetres per unit
UNITS = {"mm": 1.0, "m": 1000.0, "um": 0.001, "in": 25.4}
NAMES = {"m": "metres", "um": "micrometres (µm)", "in": "inches", "mm": "millimetres"}
#: the largest plausible body extent in mm, and the fewest cells across its smallest extent
MAX_EXTENT_MM = 1000.0
MIN_CELLS = 2.0


def unit_scale(units: str) -> float:
    """Millimetres per ``units`` (``mm``, ``m``, ``um``, ``in``)."""
    try:
        return UNITS[str(units)]
    except KeyError:
        raise InputError(f"unknown units {units!r}; use one of {', '.join(UNITS)}") from None


def _plausible(ext, cell) -> bool:
    return float(ext.max()) <= MAX_EXTENT_MM and float(ext.min()) >= MIN_CELLS * cell


def units_finding(extent, cell: float, units: str = "mm"):
    """A ``units`` Finding when a body of ``extent`` (mm) is implausible for cells of ``cell`` mm, else None."""
    ext = np.asarray(extent, np.float64)
    cell = float(cell)
    if _plausible(ext, cell):
        return None
    likely = next((u for u in ("m", "um", "in") if _plausible(ext * UNITS[u] / UNITS.get(units, 1.0), cell)), None)
    size = f"{ext.min():.3g}–{ext.max():.3g} mm"
    why = (f"it is {size}, larger than a metre" if ext.max() > MAX_EXTENT_MM
           else f"it is {size}, under {MIN_CELLS:g} cells of {cell:g} mm across")
    hint = (f"; it is probably in {NAMES[likely]}: give its units (units = \"{likely}\")" if likely
            else "; check its units and the cell size")
    return Finding("units", f"the body's size is implausible for its cells: {why}{hint}",
                   {"extent_min_mm": float(ext.min()), "extent_max_mm": float(ext.max()), "cell_mm": cell,
                    "likely_units": likely})
