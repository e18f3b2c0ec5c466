"""The TDF scaffold file: a whole heterogeneous TPMS scaffold in a few hundred KB.

A TDF file (Hu & Lin, document 001, §3.4 and Appendix) stores everything that
determines a heterogeneous porous scaffold mapped into a trivariate B-spline
solid (TBSS): the TPMS type and structure, the period coefficients, the
threshold distribution field (a scalar trivariate B-spline: degrees, control
grid resolution, control values, knot vectors in u, v, w) and the TBSS itself
(degrees, periodic flags, control grid resolution, control points, knots).
porecad regenerates the scaffold from it at any resolution.

The format is plain text, line oriented, with ``#`` section headers in the
order of 001's appendix, preceded by a ``porecad-tdf 1`` magic/version line.
Floats are written with ``repr`` (shortest round-trip form), so reading a file
back gives bit-identical arrays. The full specification is
``docs/tdf-format.md``.

:func:`read_tdf` is strict: anything wrong raises
:class:`porecad.errors.InputError` with a one-line message
``"<file>:<line>: <what is wrong>"``.

This module only moves plain arrays in and out; it evaluates no splines. The
record and its checks are :mod:`porecad.io.tdf_record`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path

import numpy as np

from ..errors import InputError, one_line
from ..splines.knots import validate_knots
from .atomic import atomic_write
from .tdf_record import (AXES, MAX_DEGREE, MAX_PER_AXIS, MAX_VALUES, STRUCTURES, TDF_VERSION, TDFRecord,
                         check_degrees, check_resolution)

__all__ = [
    "TDF_VERSION",
    "TDFRecord",
    "read_tdf",
    "write_tdf",
    "STRUCTURES",
    "MAX_DEGREE",
    "MAX_PER_AXIS",
    "MAX_VALUES",
]

MAGIC = "porecad-tdf"
MAX_LINE_CHARS = 1 << 20  # bytes; longer lines are refused (binary files without newlines)

_META_LINE = re.compile(r"([A-Za-z0-9_.\-]+)\s*=\s*(.*)")
_INT = re.compile(r"[+-]?[0-9]+")
# Plain decimal / scientific notation only: no '1_000', 'nan', 'inf', '0x1p3'.
_FLOAT = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NONFINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)

# Section keys in file order, with the header text porecad writes.
_HEADERS = {
    "metadata": "#metadata",
    "tpms": "#TPMS type",
    "structure": "#structure type",
    "periods": "#period coefficients (rho_u, rho_v, rho_w)",
    "tdf_degrees": "#degrees of TDF (p_u, p_v, p_w)",
    "tdf_res": "#resolution of the control grid of TDF",
    "tdf_ctrl": "#control points of TDF",
    "tdf_knots_u": "#knot vector in u-direction of TDF",
    "tdf_knots_v": "#knot vector in v-direction of TDF",
    "tdf_knots_w": "#knot vector in w-direction of TDF",
    "tbss_degrees": "#degrees of TBSS (p_u, p_v, p_w)",
    "tbss_periodic": "#periodic flags of TBSS (u, v, w)",
    "tbss_res": "#resolution of the control grid of TBSS",
    "tbss_ctrl": "#control points of TBSS",
    "tbss_knots_u": "#knot vector in u-direction of TBSS",
    "tbss_knots_v": "#knot vector in v-direction of TBSS",
    "tbss_knots_w": "#knot vector in w-direction of TBSS",
    "end": "#end",
}
_ORDER = tuple(_HEADERS)


def _normalise_header(text: str) -> str:
    """Header text without '#', case, parentheses, trailing ',...' / ':...', 'the', hyphens."""
    t = text.lstrip("#").strip().lower()
    t = re.split(r"[(,:]", t, maxsplit=1)[0]
    t = t.replace("-", " ")
    return " ".join(w for w in t.split() if w != "the")


# Normalised header -> key. Accepts 001's appendix wording ("resolution of control
# grid of TDF") and the reference files' ("#TPMS type, m=0: P-type; ...") too.
_HEADER_KEYS = {_normalise_header(h): k for k, h in _HEADERS.items()}


_SAFE_TOKEN = re.compile(r"[A-Za-z0-9_.+\-]{1,16}")


def _quote(token: str) -> str:
    """A token of a file that identified itself as TDF, quoted only when it is short and plain.

    Error messages never echo a file's lines: a file that is not TDF (say
    ``/etc/passwd``) gets no quote at all, and inside a TDF file only a
    token of at most 16 letters, digits and ``_.+-`` is shown (``'abc' is
    not a number``); anything else is described by its length.
    """
    if _SAFE_TOKEN.fullmatch(token):
        return f"'{token}'"
    return f"a {len(token)}-character text"


# --------------------------------------------------------------------- writer


def _fmt(values) -> str:
    # repr(float) is the shortest string that reads back to the same double.
    return " ".join(map(repr, values))


def _render(record: TDFRecord):
    """Yield the file text in chunks (one grid row / point block at a time)."""
    H = _HEADERS
    yield f"{MAGIC} {record.version}\n"
    yield "## porecad TDF scaffold file; specification: docs/tdf-format.md\n"
    if record.metadata:
        yield H["metadata"] + "\n"
        yield "".join(f"{k} = {v}\n" for k, v in record.metadata.items())
    yield f"{H['tpms']}\n{record.tpms_type}\n"
    yield f"{H['structure']}\n{record.structure}\n"
    yield f"{H['periods']}\n{_fmt(record.periods)}\n"
    for name, ctrl, degs, knots in (
        ("tdf", record.tdf_control, record.tdf_degrees, record.tdf_knots),
        ("tbss", record.tbss_control, record.tbss_degrees, record.tbss_knots),
    ):
        yield f"{H[name + '_degrees']}\n{degs[0]} {degs[1]} {degs[2]}\n"
        if name == "tbss":
            yield f"{H['tbss_periodic']}\n" + " ".join(str(int(f)) for f in record.tbss_periodic) + "\n"
        n1, n2, n3 = ctrl.shape[:3]
        yield f"{H[name + '_res']}\n{n1} {n2} {n3}\n"
        yield H[name + "_ctrl"] + "\n"
        for i in range(n1):
            block = ctrl[i].tolist()  # C order: k fastest
            if name == "tdf":  # one line per (i, j): the m3 values along w
                yield "".join(_fmt(row) + "\n" for row in block)
            else:  # one line per control point: x y z
                yield "".join(_fmt(pt) + "\n" for row in block for pt in row)
        for ax, kv in zip(AXES, knots):
            yield f"{H[name + '_knots_' + ax]}\n{_fmt(kv.tolist())}\n"
    yield H["end"] + "\n"


def write_tdf(path, record: TDFRecord, force: bool = False) -> Path:
    """Write `record` to a TDF file atomically; return the path.

    Refuses to replace an existing file unless `force` (raises
    :class:`porecad.errors.OutputError`, like every porecad output). The
    record is validated first (:class:`InputError` if it is invalid), so a
    written file always reads back with :func:`read_tdf` to identical arrays.
    """
    if not isinstance(record, TDFRecord):
        raise InputError(f"write_tdf needs a TDFRecord, got {type(record).__name__}")
    record = dataclasses.replace(record)  # re-normalises and re-validates (fields may have been reassigned)
    with atomic_write(path, force=force) as fh:
        for chunk in _render(record):
            fh.write(chunk.encode("utf-8"))
    return Path(path)


# --------------------------------------------------------------------- reader


class _Reader:
    """Line source with file:line errors; skips blank lines and '##' comments."""

    def __init__(self, fh, name: str):
        self.fh = fh
        self.name = name
        self.lineno = 0
        self._peeked = None  # (lineno, text) or None
        self._eof = False

    def error(self, lineno: int, msg: str) -> InputError:
        return InputError(f"{self.name}:{lineno}: {msg}")

    def _raw(self):
        """Next physical line (stripped), or None at end of file."""
        if self._eof:
            return None
        try:
            raw = self.fh.readline(MAX_LINE_CHARS + 1)
        except OSError as exc:
            raise self.error(self.lineno + 1, f"cannot read: {one_line(exc.strerror or exc)}") from None
        if not raw:
            self._eof = True
            return None
        self.lineno += 1
        if len(raw) > MAX_LINE_CHARS:
            raise self.error(self.lineno, "line longer than 1 MiB (not a TDF text file?)")
        if self.lineno == 1 and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]  # UTF-8 byte-order mark
        if b"\x00" in raw:
            raise self.error(self.lineno, "not a TDF text file (NUL byte, binary data?)")
        try:  # line by line, so that the error names the right line
            line = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise self.error(self.lineno, "not a TDF text file (invalid UTF-8, binary data?)") from None
        return line.strip()

    def first_line(self):
        return self._raw()

    def peek(self):
        """Next meaningful line as (lineno, text), or None at end of file."""
        while self._peeked is None:
            text = self._raw()
            if text is None:
                return None
            if text and not text.startswith("##"):
                self._peeked = (self.lineno, text)
        return self._peeked

    def take(self):
        item = self.peek()
        self._peeked = None
        return item

    def data_lines(self):
        """Yield (lineno, text) of the data lines up to the next header or end of file."""
        while True:
            item = self.peek()
            if item is None or item[1].startswith("#"):
                return
            yield self.take()

    def end_line(self) -> int:
        """Line where the current section's data stopped: the next header, or the last line."""
        item = self.peek()
        return item[0] if item is not None else self.lineno


def _expect(r: _Reader, key: str, optional: bool = False) -> int | None:
    """Consume the header of section `key`; return its line number."""
    want = _HEADERS[key]
    item = r.peek()
    if item is None:
        if optional:
            return None
        raise r.error(r.lineno, f"unexpected end of file: missing section '{want}' (file truncated?)")
    lineno, text = item
    if not text.startswith("#"):
        if optional:
            return None
        # Only reachable right after the magic line (data before any header).
        raise r.error(lineno, f"expected section header '{want}', got {_quote(text)}")
    got = _HEADER_KEYS.get(_normalise_header(text))
    if got is None:
        if optional:
            return None
        raise r.error(lineno, f"unknown section header ({_quote(text)})")
    if got != key:
        if optional:
            return None
        if _ORDER.index(got) < _ORDER.index(key):
            raise r.error(lineno, f"section '{_HEADERS[got]}' out of order (repeated or misplaced): expected '{want}'")
        raise r.error(lineno, f"section '{_HEADERS[got]}' out of order: expected '{want}' first")
    r.take()
    return lineno


def _read_tokens(r: _Reader, key: str, header_line: int, count: int, parse, what: str):
    """Read exactly `count` tokens of section `key`, parsing each with `parse`.

    Yields (lineno, values) per data line. Errors name the offending line: the
    line with a surplus or bad token, or the last line read when data ran out.
    """
    got, last = 0, header_line
    for lineno, text in r.data_lines():
        tokens = text.split()
        if got + len(tokens) > count:
            raise r.error(lineno, f"too many values: expected {count} {what} in '{_HEADERS[key]}'")
        yield lineno, [parse(r, lineno, t) for t in tokens]
        got += len(tokens)
        last = lineno
    if got < count:
        if r.peek() is None:
            raise r.error(max(last, r.lineno), f"unexpected end of file: expected {count} {what} in "
                          f"'{_HEADERS[key]}', got {got} (file truncated?)")
        raise r.error(last, f"expected {count} {what}, got {got} (section '{_HEADERS[key]}' "
                      f"ends before the next section at line {r.end_line()})")


def _parse_float(r: _Reader, lineno: int, tok: str) -> float:
    if _FLOAT.fullmatch(tok):
        return float(tok)
    if _NONFINITE.fullmatch(tok):
        raise r.error(lineno, f"{_quote(tok)} is not a finite number (NaN and infinity are not allowed)")
    raise r.error(lineno, f"{_quote(tok)} is not a number")


def _parse_int(r: _Reader, lineno: int, tok: str) -> int:
    if _INT.fullmatch(tok):
        return int(tok)
    raise r.error(lineno, f"{_quote(tok)} is not an integer")


def _read_small(r: _Reader, key: str, count: int, parse, what: str):
    """A short section: its header line and its `count` values."""
    header = _expect(r, key)
    values, first = [], None
    for lineno, vals in _read_tokens(r, key, header, count, parse, what):
        first = first or lineno
        values.extend(vals)
    return header, first, values


def _read_word(r: _Reader, key: str, what: str) -> tuple[int, str]:
    _expect(r, key)
    lines = list(r.data_lines())
    if not lines:
        raise r.error(r.end_line(), f"expected the {what} after '{_HEADERS[key]}'")
    lineno, text = lines[0]
    if len(lines) > 1 or len(text.split()) != 1:
        bad = lines[1][0] if len(lines) > 1 else lineno
        raise r.error(bad, f"expected one word for the {what}, got more")
    return lineno, text


def _read_array(r: _Reader, key: str, count: int, what: str) -> np.ndarray:
    header = _expect(r, key)
    out = np.empty(count, dtype=np.float64)
    pos = 0
    for _, vals in _read_tokens(r, key, header, count, _parse_float, what):
        out[pos:pos + len(vals)] = vals
        pos += len(vals)
    return out


def _read_spline(r: _Reader, name: str, ncomp: int, with_periodic: bool):
    lo = name.lower()
    _, line, degs = _read_small(r, f"{lo}_degrees", 3, _parse_int, "degrees (p_u p_v p_w)")
    msg = check_degrees(degs, f"{name} degree")
    if msg:
        raise r.error(line, msg)
    periodic = (False, False, False)
    if with_periodic:
        _, line, flags = _read_small(r, f"{lo}_periodic", 3, _parse_int, "periodic flags (0 or 1)")
        if any(f not in (0, 1) for f in flags):
            raise r.error(line, f"periodic flags must be 0 or 1, got {' '.join(map(str, flags))}")
        periodic = tuple(bool(f) for f in flags)
    _, line, shape = _read_small(r, f"{lo}_res", 3, _parse_int, "control grid sizes (n_u n_v n_w)")
    msg = check_resolution(shape, degs, ncomp, name)  # before anything is allocated
    if msg:
        raise r.error(line, msg)
    total = math.prod(shape) * ncomp
    what = "control values" if ncomp == 1 else f"control point coordinates ({math.prod(shape)} points x 3)"
    ctrl = _read_array(r, f"{lo}_ctrl", total, what).reshape(tuple(shape) + ((ncomp,) if ncomp > 1 else ()))
    knots = []
    for ax, p, n in zip(AXES, degs, shape):
        key = f"{lo}_knots_{ax}"
        _, line, kv = _read_small(r, key, n + p + 1, _parse_float, f"knots ({n} control points, degree {p})")
        try:
            knots.append(validate_knots(kv, p, n, f"{name} knot vector {ax}"))
        except InputError as exc:
            raise r.error(line, str(exc)) from None
    return tuple(degs), tuple(knots), ctrl, periodic


def _read_metadata(r: _Reader) -> dict[str, str]:
    if _expect(r, "metadata", optional=True) is None:
        return {}
    meta = {}
    for lineno, text in r.data_lines():
        m = _META_LINE.fullmatch(text)
        if not m:
            raise r.error(lineno, f"expected 'key = value' in '#metadata', got {_quote(text)}")
        k, v = m.group(1), m.group(2).strip()
        if k in meta:
            raise r.error(lineno, f"metadata key {_quote(k)} given twice")
        meta[k] = v
    return meta


def _parse(r: _Reader) -> TDFRecord:
    first = r.first_line()
    if first is None:
        raise r.error(1, f"empty file (a TDF file starts with '{MAGIC} {TDF_VERSION}')")
    parts = first.split()
    if len(parts) != 2 or parts[0] != MAGIC:
        raise r.error(1, f"not a porecad TDF file: the first line must be '{MAGIC} {TDF_VERSION}'")
    if not _INT.fullmatch(parts[1]) or int(parts[1]) != TDF_VERSION:
        raise r.error(1, f"unsupported TDF version {_quote(parts[1])} (this porecad reads version {TDF_VERSION})")

    metadata = _read_metadata(r)
    _, tpms = _read_word(r, "tpms", "TPMS type name")
    line, structure = _read_word(r, "structure", "structure (pore, rod or sheet)")
    if structure not in STRUCTURES:
        raise r.error(line, f"structure must be 'pore', 'rod' or 'sheet', got {_quote(structure)}")
    _, line, periods = _read_small(r, "periods", 3, _parse_float, "period coefficients")
    if not all(p > 0 for p in periods):
        raise r.error(line, f"period coefficients must be > 0, got {' '.join(map(repr, periods))}")

    tdf_deg, tdf_knots, tdf_ctrl, _ = _read_spline(r, "TDF", 1, with_periodic=False)
    tbss_deg, tbss_knots, tbss_ctrl, periodic = _read_spline(r, "TBSS", 3, with_periodic=True)

    _expect(r, "end")
    extra = r.peek()
    if extra is not None:
        raise r.error(extra[0], f"unexpected content after '{_HEADERS['end']}'")
    try:
        return TDFRecord(
            tpms_type=tpms, structure=structure, periods=tuple(periods),
            tdf_degrees=tdf_deg, tdf_knots=tdf_knots, tdf_control=tdf_ctrl,
            tbss_degrees=tbss_deg, tbss_knots=tbss_knots, tbss_control=tbss_ctrl,
            tbss_periodic=periodic, metadata=metadata, version=TDF_VERSION,
        )
    except InputError as exc:  # not expected: everything was checked above
        raise r.error(r.lineno, str(exc)) from None


def read_tdf(path) -> TDFRecord:
    """Read a TDF file strictly.

    Raises
    ------
    InputError
        For a missing file or any defect, with a one-line message
        ``"<path>:<line>: <what is wrong>"`` (wrong magic or version, unknown
        or misplaced section, truncated data, too many or non-numeric values,
        NaN/inf, absurd grid sizes, invalid knots or degrees, binary data).
    """
    from .confine import regular_file
    p = Path(os.fspath(path))
    regular_file(p, "a TDF file")
    try:
        fh = open(p, "rb")
    except OSError as exc:
        raise InputError(f"{p}: cannot read: {one_line(exc.strerror or exc)}") from None
    with fh:
        return _parse(_Reader(fh, str(p)))
