"""Structured warnings: a stable code, the numbers, one sentence for people.

A job (or any library function) that delivers something other than what was
asked says so with a :class:`Finding` — ``Finding("porosity-off", "the
solid's porosity is 0.62, asked 0.60", {"asked": 0.6, "achieved": 0.62})``.
Programs (the studio, ``--strict``, tests) read the ``code`` and ``values``;
people read the ``message``. A report carries them twice: ``warnings`` (the
sentences, as earlier reports did) and ``warning_details`` (code, message,
values), both built by :func:`report_fields`.

Codes are lower-case words joined by ``-``, listed with their meaning in
:data:`CODES` (a Finding with another code is a programming error, and
``docs/recipes.md`` lists them all: a test keeps the two in step); a code
once published keeps its meaning. Plain strings (in reports of earlier
versions) read back with the code ``note``.
"""

from __future__ import annotations

import dataclasses
import math
import re

_CODE = re.compile(r"^[a-z][a-z0-9]*(-[a-z0-9]+)*$")

#: every warning code, with what it means (``docs/recipes.md`` lists the same)
CODES = {
    # what was asked against what was built (porecad.jobs.promise, every job)
    "islands": "the solid is more than one piece",
    "islands-dropped": "loose pieces holding over 5 % of the material were dropped",
    "porosity-off": "the porosity is more than 0.01 from the one asked for",
    "porosity-limited": "the asked porosity needs the lattice outside its valid range; built at its edge",
    "coverage-low": "the solid fills under 95 % of the body",
    "extent-short": "the solid spans under 95 % of one of the body's extents",
    # the inputs
    "body-repaired": "the body mesh was repaired (holes closed, faces reoriented)",
    "units": "the body's size is implausible for its cells (probably other units)",
    "not-tube-like": "the vessel taken from a grey image is mostly not tube-like (bone joined to it?)",
    "path-not-tube": "the path between vessel seeds leaves the tube (a chamber, bone, a radius jump)",
    # sampling
    "voxel-coarse": "the voxel is coarse for the walls (mesh and sample porosity differ)",
    "resolution-coarse": "the mapped resolution is coarse for the walls (mesh and sample porosity differ)",
    "resolution-raised": "the resolution was raised so that mapped triangles do not cross",
    "skin-thin": "the skin is thinner than 1.5 samples",
    "layer-thin": "a vessel wall layer spans fewer than 3 voxels",
    "thin-parts-cut": "parts of the body thinner than a sample were cut away",
    "smoothing-stopped": "smoothing stopped before the asked iterations: the next would have folded the surface",
    "fit-short": "the fitted TBSS covers under 98 % of the body",
    # the method's own conditions
    "threshold-disconnected": "a TIS relative threshold outside its type's connected range",
    "no-rainbow-colouring": "TIS-G on a tet mesh without a rainbow colouring: C0 across faces",
    "iso-outside": "an ARBF iso-value outside (-1, 1)",
    "cells-disagree": "ARBF local systems disagree across cell faces",
    "pores-shut": "the ARBF pore network does not open on every outer face",
    "pores-split": "the ARBF pores form separate networks",
    # the printer (porecad.printing)
    "thin-wall": "walls narrower than the printer's smallest feature",
    "narrow-channel": "channels narrower than the printer's smallest channel",
    "closed-pore": "closed pores trap resin or powder",
    "check-coarse": "the wall and channel checks ran on voxels coarser than the printer's limits need",
    "mid-air-start": "a piece starts in mid-air on a layer",
    "unsupported-overhang": "down-facing surface steeper than the printer's overhang limit",
    # text without a code (reports of earlier versions)
    "note": "a warning given as plain text",
}


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
        if not _CODE.match(self.code) or self.code not in CODES:
            raise ValueError(f"warning code {self.code!r} is not one of porecad.findings.CODES")

    def __str__(self) -> str:
        return self.message

    def as_dict(self) -> dict:
        """``{"code", "message", "values"}`` with JSON-ready values (non-finite floats become None)."""
        return {"code": self.code, "message": self.message, "values": {k: _plain(v) for k, v in self.values.items()}}


def as_finding(item) -> Finding:
    """``item`` as a :class:`Finding`: a Finding as is, a dict from a report, anything else a ``note``."""
    if isinstance(item, Finding):
        return item
    if isinstance(item, dict) and item.get("code") in CODES and "message" in item:
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
