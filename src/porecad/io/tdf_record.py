"""The TDF record: a whole heterogeneous TPMS scaffold as plain arrays, and its checks.

:class:`TDFRecord` holds what a TDF file stores (Hu & Lin, document 001,
§3.4 and Appendix): the TPMS type and structure, the period coefficients,
the threshold distribution field and the trivariate B-spline solid. Building
one converts and checks every field, so an invalid record never exists; the
limits here (:data:`MAX_DEGREE`, :data:`MAX_PER_AXIS`, :data:`MAX_VALUES`)
also bound what :func:`porecad.io.tdf_file.read_tdf` allocates. Reading and
writing the file is :mod:`porecad.io.tdf_file`.
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..splines.knots import validate_knots

__all__ = ["TDF_VERSION", "TDFRecord", "STRUCTURES", "MIN_DEGREE", "MAX_DEGREE", "MAX_PER_AXIS", "MAX_VALUES",
           "AXES", "check_degrees", "check_resolution"]

TDF_VERSION = 1
STRUCTURES = ("pore", "rod", "sheet")
MIN_DEGREE, MAX_DEGREE = 1, 7
MAX_PER_AXIS = 4096  # control points per axis
MAX_VALUES = 50_000_000  # numbers in one control array (TDF values, TBSS coordinates)

#: the parametric directions, in the order of every triple
AXES = ("u", "v", "w")
_META_KEY = re.compile(r"[A-Za-z0-9_.\-]+")


def _as_int3(value, name: str) -> tuple[int, int, int]:
    try:
        items = tuple(value)
    except TypeError:
        raise InputError(f"{name} must be 3 integers, got {value!r}") from None
    if len(items) != 3:
        raise InputError(f"{name} must be 3 integers, got {len(items)}")
    out = []
    for x in items:
        if isinstance(x, (bool, np.bool_)):
            raise InputError(f"{name} must be integers, got {x!r}")
        try:
            out.append(operator.index(x))
        except TypeError:
            raise InputError(f"{name} must be integers, got {x!r}") from None
    return tuple(out)


def check_degrees(degrees, name: str) -> str | None:
    """Why the degrees ``(p_u, p_v, p_w)`` of spline `name` are refused (outside 1..7), or None."""
    for ax, p in zip(AXES, degrees):
        if not MIN_DEGREE <= p <= MAX_DEGREE:
            return f"{name} in {ax} must be {MIN_DEGREE}..{MAX_DEGREE}, got {p}"
    return None


def check_resolution(shape, degrees, ncomp: int, name: str) -> str | None:
    """Why a control grid shape is refused (before anything is allocated), or None.

    `shape` is ``(n_u, n_v, n_w)``, `degrees` ``(p_u, p_v, p_w)``, `ncomp` the numbers per
    control point (1 for the TDF, 3 for the TBSS); `name` starts the message.
    """
    for ax, n, p in zip(AXES, shape, degrees):
        if n < 1:
            return f"{name} control grid size in {ax} must be positive, got {n}"
        if n < p + 1:
            return f"{name} control grid has {n} points in {ax}, a degree-{p} B-spline needs at least {p + 1}"
        if n > MAX_PER_AXIS:
            return f"{name} control grid has {n} points in {ax}, more than the limit of {MAX_PER_AXIS} per axis"
    total = math.prod(shape) * ncomp
    if total > MAX_VALUES:
        return f"{name} control grid {shape[0]}x{shape[1]}x{shape[2]} needs {total} values, more than the limit of {MAX_VALUES}"
    return None


def _check_metadata(meta) -> dict[str, str]:
    if not isinstance(meta, dict):
        raise InputError(f"metadata must be a dict of str to str, got {type(meta).__name__}")
    out = {}
    for k, v in meta.items():
        if not isinstance(k, str) or not _META_KEY.fullmatch(k):
            raise InputError(f"metadata key {k!r} must be letters, digits, '_', '.' or '-'")
        if not isinstance(v, str):
            raise InputError(f"metadata value of {k!r} must be a str, got {type(v).__name__}")
        if any(ord(c) < 32 or ord(c) == 127 for c in v):
            raise InputError(f"metadata value of {k!r} must be one line without control characters")
        if v != v.strip():
            raise InputError(f"metadata value of {k!r} must not start or end with whitespace")
        out[k] = v
    return out


@dataclass(eq=False)
class TDFRecord:
    """A whole heterogeneous scaffold as stored in a TDF file (plain arrays).

    Attributes
    ----------
    tpms_type : str
        TPMS type name, one token (porecad names such as ``"P"``, ``"G"``,
        ``"D"``, ``"IWP"``; checked against the TPMS tables elsewhere).
    structure : str
        ``"pore"``, ``"rod"`` or ``"sheet"``.
    periods : tuple of 3 float
        Period coefficients (rho_u, rho_v, rho_w): number of TPMS periods
        along u, v, w of the parametric domain; finite and > 0.
    tdf_degrees, tdf_knots, tdf_control
        The threshold distribution field: degrees (p_u, p_v, p_w) in 1..7,
        three clamped knot vectors, control values of shape (m1, m2, m3);
        ``tdf_control[i, j, k]`` belongs to u-index i, v-index j, w-index k.
    tbss_degrees, tbss_knots, tbss_control
        The trivariate B-spline solid: degrees, knots, control points of
        shape (n1, n2, n3, 3) holding x, y, z; index (i, j, k) <-> (u, v, w).
    tbss_periodic : tuple of 3 bool
        Whether the solid closes on itself in u, v, w (its first and last
        control layers coincide, e.g. the angular direction of a tube). The
        knot vectors stay clamped; the flag tells the generator to treat the
        direction as closed.
    metadata : dict of str to str
        Free one-line annotations, e.g. ``{"units": "mm"}``.
    version : int
        Format version, :data:`TDF_VERSION`.

    Construction converts arrays to float64 and checks everything
    (:meth:`validate`); an invalid record raises :class:`InputError`.
    """

    tpms_type: str
    structure: str
    periods: tuple
    tdf_degrees: tuple
    tdf_knots: tuple
    tdf_control: np.ndarray
    tbss_degrees: tuple
    tbss_knots: tuple
    tbss_control: np.ndarray
    tbss_periodic: tuple = (False, False, False)
    metadata: dict = field(default_factory=dict)
    version: int = TDF_VERSION

    def __post_init__(self):
        try:
            periods = tuple(float(x) for x in self.periods)
        except (TypeError, ValueError):
            raise InputError(f"periods must be 3 numbers, got {self.periods!r}") from None
        self.periods = periods
        self.tdf_degrees = _as_int3(self.tdf_degrees, "tdf_degrees")
        self.tbss_degrees = _as_int3(self.tbss_degrees, "tbss_degrees")
        for name in ("tdf_knots", "tbss_knots"):
            kv = getattr(self, name)
            try:
                kv = tuple(np.asarray(k, dtype=np.float64).ravel() for k in kv)
            except (TypeError, ValueError):
                raise InputError(f"{name} must be 3 arrays of numbers") from None
            setattr(self, name, kv)
        for name in ("tdf_control", "tbss_control"):
            try:
                setattr(self, name, np.asarray(getattr(self, name), dtype=np.float64))
            except (TypeError, ValueError):
                raise InputError(f"{name} must be an array of numbers") from None
        try:
            flags = tuple(self.tbss_periodic)
        except TypeError:
            raise InputError(f"tbss_periodic must be 3 booleans, got {self.tbss_periodic!r}") from None
        if len(flags) != 3 or not all(isinstance(f, (bool, np.bool_)) or f in (0, 1) for f in flags):
            raise InputError(f"tbss_periodic must be 3 booleans, got {self.tbss_periodic!r}")
        self.tbss_periodic = tuple(bool(f) for f in flags)
        self.metadata = _check_metadata(self.metadata)
        self.validate()

    def validate(self) -> None:
        """Check the record; raise :class:`InputError` (one line) if it is invalid."""
        if isinstance(self.version, bool) or self.version != TDF_VERSION:
            raise InputError(f"unsupported TDF version {self.version!r} (porecad writes version {TDF_VERSION})")
        t = self.tpms_type
        if not isinstance(t, str) or len(t.split()) != 1 or t != t.strip() or t.startswith("#"):
            raise InputError(f"tpms_type must be one non-empty token, got {t!r}")
        if self.structure not in STRUCTURES:
            raise InputError(f"structure must be 'pore', 'rod' or 'sheet', got {self.structure!r}")
        if len(self.periods) != 3:
            raise InputError(f"expected 3 period coefficients, got {len(self.periods)}")
        if not all(math.isfinite(x) and x > 0 for x in self.periods):
            raise InputError(f"period coefficients must be finite and > 0, got {self.periods}")
        for name, degs, ctrl, knots, ncomp in (
            ("TDF", self.tdf_degrees, self.tdf_control, self.tdf_knots, 1),
            ("TBSS", self.tbss_degrees, self.tbss_control, self.tbss_knots, 3),
        ):
            msg = check_degrees(degs, f"{name} degree")
            if msg:
                raise InputError(msg)
            want_ndim = 3 if ncomp == 1 else 4
            if ctrl.ndim != want_ndim or (ncomp == 3 and ctrl.shape[-1] != 3):
                want = "(m1, m2, m3)" if ncomp == 1 else "(n1, n2, n3, 3)"
                raise InputError(f"{name} control array must have shape {want}, got {ctrl.shape}")
            msg = check_resolution(ctrl.shape[:3], degs, ncomp, name)
            if msg:
                raise InputError(msg)
            if not np.all(np.isfinite(ctrl)):
                raise InputError(f"{name} control values must be finite")
            if len(knots) != 3:
                raise InputError(f"{name} needs 3 knot vectors (u, v, w), got {len(knots)}")
            for ax, kv, p, n in zip(AXES, knots, degs, ctrl.shape[:3]):
                validate_knots(kv, p, n, f"{name} knot vector {ax}")
