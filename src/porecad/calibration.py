"""Porosity <-> threshold calibration and the valid threshold range per type and structure.

The porosity of a TPMS structure over whole cells is a function of the
threshold alone. It is measured on one period sampled with an
endpoint-exclusive ``n^3`` grid (the convention that reproduces 002 Table 3,
see ``../shared/reference/seed-000-dissertation-notes.md`` section 9.1):

* pore  (material φ ≥ C): porosity = P(φ < C)
* rod   (material φ ≤ C): porosity = P(φ > C)
* sheet (material |φ − m| ≤ C, m the type's ``sheet_level``, 0 except for
  the Lidinoid): porosity = 1 − P(|φ − m| ≤ C)

so the threshold for a porosity is a quantile of the sorted samples. A type is
given by name or alias, or as the :class:`~porecad.fields.tpms.TPMSType` itself.

The *valid range* of each (type, structure) is the threshold interval in which
the structure is a usable scaffold: every piece of material percolates
through the part (no floating islands; two interwoven networks, as in the
Lidinoid pore or I2-Y** rod structures, are allowed), the pore space is
interconnected (closed pores hold under 5 % of the void), and neither phase
falls below 2 % of the volume (no vanishing walls). It is computed by :func:`compute_valid_range`
(``python -m porecad.calibration`` regenerates ``data/valid_ranges.json``) on a
3x3x3 tiling of cells sampled at 32 samples per cell, with the interval edges
refined by bisection to 1e-3 of the value range.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources

import numpy as np

from .errors import InputError, RangeError
from .fields.tpms import CATALOGUE, TPMSField, get_type
from .solids import SOLID_STRUCTURES, check_structure

MIN_PHASE_FRACTION = 0.02
_OVERRIDE = "; `allow_closed_pores` builds it anyway"


@lru_cache(maxsize=64)
def phi_samples(type_name: str, n: int = 128) -> np.ndarray:
    """Sorted φ over one period on an endpoint-exclusive ``n^3`` grid (float64)."""
    t = np.arange(n, dtype=np.float64) / n
    vals = TPMSField(type_name, 1.0).sample_grid(t, t, t).astype(np.float64).ravel()
    vals.sort()
    return vals


@lru_cache(maxsize=64)
def abs_phi_samples(type_name: str, n: int = 128) -> np.ndarray:
    """Sorted ``|φ - sheet_level|`` (the sheet's distance variable) over one period."""
    v = np.abs(phi_samples(type_name, n) - get_type(type_name).sheet_level)
    v.sort()
    return v


def porosity_of_threshold(tpms_type: str, structure: str, threshold) -> np.ndarray | float:
    """Porosity (void fraction, 0-1) of whole cells at threshold(s) ``C``."""
    name = get_type(tpms_type).name
    s = check_structure(structure)
    c = np.asarray(threshold, dtype=np.float64)
    if s == "pore":
        v = phi_samples(name)
        p = np.searchsorted(v, c, side="left") / v.size
    elif s == "rod":
        v = phi_samples(name)
        p = 1.0 - np.searchsorted(v, c, side="right") / v.size
    elif s == "sheet":
        v = abs_phi_samples(name)
        p = 1.0 - np.searchsorted(v, c, side="right") / v.size
    else:
        raise InputError("a bare surface has no porosity")
    return float(p) if np.ndim(p) == 0 else p


def _sorted_quantile(v: np.ndarray, q):
    """``np.quantile(v, q)`` (its default, linear method) of an already sorted ``v``, without sorting again."""
    q = np.asarray(q, dtype=np.float64)
    x = q * (v.size - 1)
    i = np.clip(np.floor(x).astype(np.int64), 0, v.size - 1)
    j = np.minimum(i + 1, v.size - 1)
    return v[i] + (x - i) * (v[j] - v[i])


def threshold_for_porosity(tpms_type: str, structure: str, porosity):
    """Threshold ``C`` giving the porosity (scalar or array) over whole cells."""
    name = get_type(tpms_type).name
    s = check_structure(structure)
    p = np.asarray(porosity, dtype=np.float64)
    if np.any(~np.isfinite(p)) or np.any(p <= 0) or np.any(p >= 1):
        raise RangeError(f"porosity must lie strictly between 0 and 1, got {porosity}")
    if s == "pore":
        c = _sorted_quantile(phi_samples(name), p)
    elif s == "rod":
        c = _sorted_quantile(phi_samples(name), 1.0 - p)
    elif s == "sheet":
        c = _sorted_quantile(abs_phi_samples(name), 1.0 - p)
    else:
        raise InputError("a bare surface has no porosity; give a `threshold`")
    return float(c) if np.ndim(c) == 0 else c


# ---------------------------------------------------------------- valid ranges
@lru_cache(maxsize=1)
def _valid_table() -> dict:
    with resources.files("porecad").joinpath("data/valid_ranges.json").open(encoding="utf-8") as fh:
        return json.load(fh)


def checked_range(tpms_type, structure: str, key: str) -> list:
    """The valid ``key`` ('threshold' or 'porosity') interval, or a RangeError if there is none."""
    t = get_type(tpms_type)
    r = valid_range(t, structure)[key]
    if r is None:
        raise RangeError(f"{t.name} {structure} has no valid range: its pores are closed at every "
                         f"threshold; use another structure{_OVERRIDE}")
    return r


def valid_range(tpms_type: str, structure: str) -> dict:
    """``{'threshold': [lo, hi], 'porosity': [lo, hi]}`` for a type and solid structure."""
    name = get_type(tpms_type).name
    s = check_structure(structure)
    if s == "surface":
        v = phi_samples(name)
        return {"threshold": [float(v[0]), float(v[-1])], "porosity": None}
    try:
        return _valid_table()["ranges"][name][s]
    except KeyError:
        raise InputError(f"no valid range computed for {name} {s}") from None


def _fmt(a, b):
    return f"[{a:.4g}, {b:.4g}]"


def check_threshold(tpms_type: str, structure: str, threshold: float) -> float:
    """Raise :class:`RangeError` if ``threshold`` is outside the valid range."""
    c = float(threshold)
    t = get_type(tpms_type)
    r = checked_range(t, structure, "threshold")
    if not np.isfinite(c) or c < r[0] or c > r[1]:
        raise RangeError(f"threshold {c:g} is outside the valid range {_fmt(*r)} of {t.name} {structure} "
                         f"(both phases connected, no closed pores){_OVERRIDE}")
    return c


def check_porosity(tpms_type: str, structure: str, porosity: float) -> float:
    p = float(porosity)
    t = get_type(tpms_type)
    s = check_structure(structure)
    if s == "surface":
        raise InputError("a bare surface has no porosity; give a `threshold`")
    r = checked_range(t, s, "porosity")
    if not np.isfinite(p) or p < r[0] or p > r[1]:
        raise RangeError(f"porosity {p:g} is outside the valid range {_fmt(*r)} of {t.name} {s} "
                         f"(both phases connected, no closed pores){_OVERRIDE}")
    return p


def within_range(check, tpms_type: str, structure: str, value: float, allow: bool) -> bool:
    """Run a valid-range ``check`` (:func:`check_threshold`, :func:`check_porosity`); ``allow``: report, not refuse."""
    try:
        check(tpms_type, structure, value)
    except RangeError:
        if not allow:
            raise
        return False
    return True


def check_one_of(threshold, porosity) -> None:
    """The rule of a design's parameters: exactly one of ``threshold`` or ``porosity`` (a recipe's: its schema)."""
    if (threshold is None) == (porosity is None):
        raise InputError("give exactly one of `threshold` or `porosity`")


def constant_threshold(tpms_type: str, structure: str, threshold=None, porosity=None,
                       allow_closed_pores: bool = False) -> tuple[float, dict]:
    """The threshold of a design given exactly one of ``threshold`` or ``porosity`` (numbers), range-checked.

    The valid-range check of a constant design (:func:`check_one_of` its parameters' rule). Returns ``(threshold, info)``:
    ``info`` has ``threshold``, ``target_porosity`` (if one was given) and
    ``in_valid_range`` (False only with ``allow_closed_pores``, which builds
    outside the valid range instead of refusing). A bare surface takes a
    threshold inside the type's value range.
    """
    check_one_of(threshold, porosity)
    if porosity is not None:
        p = float(porosity)
        if not 0 < p < 1:
            raise RangeError(f"`porosity` must lie strictly between 0 and 1, got {p:g}")
        ok = within_range(check_porosity, tpms_type, structure, p, allow_closed_pores)
        c = float(threshold_for_porosity(tpms_type, structure, p))
        return c, {"threshold": c, "target_porosity": p, "in_valid_range": ok}
    c = float(threshold)
    if check_structure(structure) == "surface":
        r = valid_range(tpms_type, "surface")["threshold"]
        if not r[0] < c < r[1]:
            raise RangeError(f"threshold {c:g} is outside the value range ({r[0]:.4g}, {r[1]:.4g}) of "
                             f"{get_type(tpms_type).name}: the surface would be empty")
        return c, {"threshold": c}
    ok = within_range(check_threshold, tpms_type, structure, c, allow_closed_pores)
    return c, {"threshold": c, "in_valid_range": ok}


# ---------------------------------------------------------------- computing the ranges


def structure_is_valid(tpms_type: str, structure: str, threshold: float, n: int = 32) -> bool:
    """Connectivity test of one threshold on a 3x3x3 tiling (see module docstring).

    Valid when each phase holds at least ``MIN_PHASE_FRACTION`` of the volume,
    every material component that reaches the centre cell percolates through
    the tiling along x, y and z (no floating islands; interwoven networks are
    allowed), and the percolating void components hold at least 95 % of the
    void (closed pores below 5 % of the pore volume).
    """
    from scipy import ndimage

    from .solids import StructureField
    t = np.arange(3 * n, dtype=np.float64) / n
    f = StructureField(TPMSField(tpms_type, 1.0), structure, threshold).sample_grid(t, t, t)
    material = f < 0
    centre = (slice(n, 2 * n),) * 3
    frac = material[centre].mean()
    if frac < MIN_PHASE_FRACTION or frac > 1 - MIN_PHASE_FRACTION:
        return False

    def percolating(lab):
        ok = np.ones(lab.max() + 1, dtype=bool)
        for ax in range(3):
            lo = np.unique(np.take(lab, 0, axis=ax))
            hi = np.unique(np.take(lab, lab.shape[ax] - 1, axis=ax))
            touch = np.zeros_like(ok)
            touch[np.intersect1d(lo, hi)] = True
            ok &= touch
        return ok

    lab, _ = ndimage.label(material)
    ids = np.unique(lab[centre])
    ids = ids[ids > 0]
    if not percolating(lab)[ids].all():
        return False
    lab, _ = ndimage.label(~material)
    counts = np.bincount(lab[centre].ravel(), minlength=lab.max() + 1)
    counts[0] = 0
    open_void = counts[percolating(lab)].sum()
    return open_void >= 0.95 * counts.sum()


def compute_valid_range(tpms_type: str, structure: str, scan: int = 41, n: int = 32) -> dict:
    """Largest threshold interval of valid structures around the 50 %-porosity threshold."""
    name = get_type(tpms_type).name
    if structure == "sheet":
        lo_c, hi_c = 0.0, float(abs_phi_samples(name)[-1])
    else:
        v = phi_samples(name)
        lo_c, hi_c = float(v[0]), float(v[-1])
    cs = np.linspace(lo_c, hi_c, scan)[1:-1]
    ok = np.array([structure_is_valid(name, structure, c, n) for c in cs])
    if not ok.any():
        return {"threshold": None, "porosity": None}
    # the longest run of valid thresholds
    best, run_start, best_len = None, None, 0
    for i, flag in enumerate(list(ok) + [False]):
        if flag and run_start is None:
            run_start = i
        if not flag and run_start is not None:
            if i - run_start > best_len:
                best, best_len = (run_start, i - 1), i - run_start
            run_start = None
    i0, i1 = best
    tol = 1e-3 * (hi_c - lo_c)

    def refine(good, bad):
        while abs(good - bad) > tol:
            mid = 0.5 * (good + bad)
            if structure_is_valid(name, structure, mid, n):
                good = mid
            else:
                bad = mid
        return good

    c_lo = refine(cs[i0], cs[i0 - 1] if i0 > 0 else lo_c)
    c_hi = refine(cs[i1], cs[i1 + 1] if i1 + 1 < len(cs) else hi_c)
    p = sorted(float(porosity_of_threshold(name, structure, c)) for c in (c_lo, c_hi))
    return {"threshold": [round(c_lo, 5), round(c_hi, 5)], "porosity": [round(p[0], 5), round(p[1], 5)]}


def _main():  # pragma: no cover - regeneration script
    import sys
    from pathlib import Path
    out = {"method": "3x3x3 tiling, 32 samples per cell; every material component percolates, "
                     "closed pores < 5 % of the void, each phase >= 2 % of the volume",
           "ranges": {}}
    for name in CATALOGUE:
        out["ranges"][name] = {}
        for s in SOLID_STRUCTURES:
            out["ranges"][name][s] = compute_valid_range(name, s)
            print(name, s, out["ranges"][name][s], file=sys.stderr, flush=True)
    path = Path(__file__).parent / "data" / "valid_ranges.json"
    path.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":  # pragma: no cover
    _main()
