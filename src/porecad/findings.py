"""Structured warnings: a stable code, the numbers, one sentence for people.

A job (or any library function) that delivers something other than what was
asked says so with a :class:`Finding` — ``Finding("porosity-off", "the
solid's porosity is 0.62, asked 0.60", {"asked": 0.6, "achieved": 0.62})``.
Programs (the studio, ``--strict``, tests) read the ``code`` and ``values``;
people read the ``message``. A report carries them twice: ``warnings`` (the
sentences, as earlier reports did) and ``warning_details`` (code, message,
values), both built by :func:`report_fields`.

Codes are lower-case words joined by ``-``; a code once published keeps its
meaning. Plain strings are still accepted where a warning is expected and get
the code ``note``.
"""

from __future__ import annotations

import dataclasses
import math
import re

_CODE = re.compile(r"^[a-z][a-z0-9]*(-[a-z0-9]+)*$")


@dataclasses.dataclass(frozen=True)
class Finding:
    """One structured warning.

    Attributes
    ----------
    code : str
        Stable identifier, e.g. ``porosity-off``, ``islands``, ``coverage-low``.
    message : str
        One sentence for people (no CLI flags: the command line adds them).
    values : dict
        JSON-ready numbers behind the message (``asked``, ``achieved``, counts...).
    """

    code: str
    message: str
    values: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if not _CODE.match(self.code):
            raise ValueError(f"warning code {self.code!r} is not lower-case words joined by '-'")

    def __str__(self) -> str:
        return self.message

    def as_dict(self) -> dict:
        """``{"code", "message", "values"}`` with JSON-ready values (non-finite floats become None)."""
        return {"code": self.code, "message": self.message, "values": {k: _plain(v) for k, v in self.values.items()}}


def as_finding(item) -> Finding:
    """``item`` as a :class:`Finding`: a Finding as is, a dict from a report, anything else a ``note``."""
    if isinstance(item, Finding):
        return item
    if isinstance(item, dict) and "code" in item and "message" in item:
        return Finding(str(item["code"]), str(item["message"]), dict(item.get("values") or {}))
    return Finding("note", " ".join(str(item).split()))


def report_fields(items) -> dict:
    """The report's ``warnings`` (sentences) and ``warning_details`` (dicts) of ``items``, duplicates dropped."""
    seen, found = set(), []
    for item in items or []:
        f = as_finding(item)
        key = (f.code, f.message)
        if key not in seen:
            seen.add(key)
            found.append(f)
    return {"warnings": [f.message for f in found], "warning_details": [f.as_dict() for f in found]}


def codes(report: dict) -> list[str]:
    """The warning codes of a report (``note`` for a warning written as plain text)."""
    details = report.get("warning_details")
    if details is None:
        return [as_finding(w).code for w in report.get("warnings") or []]
    return [d["code"] for d in details]


def _plain(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if hasattr(v, "item") and getattr(v, "ndim", 1) == 0:  # a numpy scalar
        return _plain(v.item())
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v
