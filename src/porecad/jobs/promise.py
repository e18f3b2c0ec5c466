"""The promise check: every solid is the part that was asked for — one piece, on target — or a clear no.

After a job computed its solid, :func:`keep_promise` measures what was
built from the solid and the body alone (never from the job's intermediate
numbers) and compares it with what the recipe asked:

* **pieces** — the solid's connected pieces (:func:`porecad.mesh.shells.keep_largest_piece`).
  By default (``islands = "drop"``) pieces that do not touch the largest one
  are dropped: a printer cannot hold them and a culture medium washes them
  out. Pieces of at least :data:`NETWORK_FRACTION` of the largest one's
  volume lying within its bounding box are interwoven networks (a lattice
  past its valid range), not debris: they are kept, with the ``islands``
  warning. Such pieces beside it are separate parts (the complete cells of
  two arms of a body): dropping them would leave another part, so the job is
  refused (:class:`~porecad.errors.PromiseError`) — for a job with a body in
  one piece (a box of cells or a given cell mesh is a lattice: its pieces join
  the next cells'). With no body, a piece with a vertex on the design domain's
  faces was cut off by them and is kept without a warning. ``islands = "keep"``
  keeps every piece, with the warning.
* **porosity** — the void fraction of the design domain by volume,
  ``1 − V(solid) / V(domain)`` (the result's ``domain_volume``: the body, the
  kept cells of a ``whole`` infill), after dropping; where the recipe asked
  for a porosity (the spec's ``asked_porosity()``), ``porosity_error`` is the
  achieved minus the asked, and a miss by more than
  :data:`POROSITY_TOLERANCE` is the ``porosity-off`` warning.
* **coverage** — the fraction of the body's volume the solid fills: the
  cells of a regular grid inside the body within a pore's reach of the
  solid's surface (:func:`porecad.analysis.coverage.filled`); below :data:`COVERAGE_MIN`, ``coverage-low``.
* **extents** — the part of each of the body's extents the solid's bounding
  box spans; below :data:`EXTENT_MIN` on an axis, ``extent-short``.

``strict = true`` turns any warning of the job into a refusal that writes
nothing (:class:`~porecad.errors.PromiseError`, one line naming the codes).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..findings import Finding, as_finding
from ..mesh.shells import WOVEN_OVERLAP

#: the written solid's porosity may miss the asked one by this much (void fraction of the domain)
POROSITY_TOLERANCE = 0.01
#: the least fraction of the body's volume the solid must fill
COVERAGE_MIN = 0.95
#: the least fraction of each of the body's extents the solid must span
EXTENT_MIN = 0.95
#: a piece of at least this fraction of the largest one's volume is an interwoven network, never dropped
NETWORK_FRACTION = 0.1
#: dropping islands that hold more than this fraction of the material is an ``islands-dropped`` warning
ISLANDS_LOSS = 0.05


@dataclasses.dataclass(frozen=True)
class Promise:
    """The recipe's top-level ``strict`` and ``islands`` keys (``islands`` None: the job's own default)."""

    strict: bool = False
    islands: str | None = None

    @classmethod
    def from_recipe(cls, root) -> Promise:
        islands = root.get("islands")
        return cls(root.get("strict"), islands)


def keep_promise(result, spec, promise: Promise) -> None:
    """Measure ``result``'s solid against ``spec``; drop islands, add the figures and findings to its report.

    Raises :class:`~porecad.errors.PromiseError` for a ``strict`` promise
    with any warning. A mesh streamed to its file is held to its porosity (by
    the volume summed slab by slab) and ``strict``; a folder of meshes only to
    ``strict``.
    """
    report = result.report
    warnings = list(report.get("warnings") or [])
    solid = report.get("volume") is not None  # a closed solid (not a bare surface)
    asked = spec.asked_porosity() if hasattr(spec, "asked_porosity") else None
    if solid and result.vertices is not None and result.faces is not None and len(result.faces):
        mode = promise.islands or getattr(spec, "islands", None) or "drop"
        warnings += _pieces(result, mode)
        warnings += _porosity(result, asked)
        if getattr(result, "body", None) is not None:
            warnings += _coverage(result)
    elif solid:  # a mesh streamed to its file: its volume and pieces were counted slab by slab, nothing dropped
        warnings += _streamed_pieces(report) + _porosity(result, asked)
    report["warnings"] = warnings
    if promise.strict and warnings:
        from ..errors import PromiseError
        found = [as_finding(w) for w in warnings]
        codes = sorted({f.code for f in found})
        raise PromiseError(f"strict: the solid is not the part asked for ({', '.join(codes)}: "
                           f"{found[0].message}); nothing written")


def _pieces(result, mode: str) -> list:
    """Drop (or count) the pieces besides the largest; the report's ``pieces`` keys."""
    from ..analysis.basic import mesh_report
    from ..mesh.shells import keep_largest_piece, shell_labels
    from ..mesh.validate import check_solid
    report = result.report
    if mode == "drop":
        # a body in one piece is the part asked for: large pieces beside the largest one are separate parts. In
        # a box of cells or a given cell mesh (one TPMS cell, one tet of 002's tables) they are the lattice's own
        # pieces, joined by the next cells; a body in pieces may be filled in as many
        body = getattr(result, "body", None)
        several = body is None or _body_pieces(body) > 1
        v, f, info = keep_largest_piece(result.vertices, result.faces, keep_fraction=NETWORK_FRACTION,
                                        overlap=0.0 if several else WOVEN_OVERLAP,
                                        anchored=_on_domain_faces(result) if body is None and
                                        result.domain is not None else None)
        dropped, fraction = info["islands_dropped"], info["islands_fraction"]
        if info["separate"]:
            from ..errors import PromiseError
            raise PromiseError(f"the solid falls into {info['separate'] + 1} separate parts of comparable size "
                               f"({100 * info['separate_fraction']:.0f} % of the material besides the largest): "
                               "it is not one part (smaller cells, a finer sampling or a lower porosity may join "
                               "them; `islands` keep writes them all, with the islands warning); nothing written")
        if dropped:
            old = result.check or {}
            chk = check_solid(v, f, check_self_intersections=False)
            chk["self_intersections"] = old.get("self_intersections")
            # the report's porosity keeps its job's meaning (a whole infill's is of the body, not of its cells)
            report.update(mesh_report(v, f, domain_volume=report.get("domain_volume") or result.domain_volume,
                                      check=chk))
            result.vertices, result.faces, result.check = v.astype(result.vertices.dtype), f, chk
        report.update(pieces=info["kept"], islands_dropped=int(dropped), islands_volume_fraction=float(fraction))
        found = _dropped_findings(dropped, fraction)
        if info["kept"] - info["anchored"] > 1:
            why = "a lattice in a box or a body in pieces" if several else "interwoven networks"
            found.append(Finding("islands", f"the solid is {info['kept']} pieces, each at least "
                                            f"{100 * NETWORK_FRACTION:.0f} % of the largest (kept: {why}): "
                                            "not attached to each other",
                                 {"asked": 1, "achieved": info["kept"], "volume_fraction": 0.0}))
        return found
    _, vol = shell_labels(result.vertices, result.faces)
    pos = vol[vol > 0]
    n = int(len(pos))
    fraction = float((pos.sum() - pos.max()) / vol.sum()) if n > 1 and vol.sum() > 0 else 0.0
    report.update(pieces=n, islands_dropped=0, islands_volume_fraction=fraction)
    if n <= 1:
        return []
    return [Finding("islands", f"the solid falls into {n} separate pieces ({100 * fraction:.2g} % of its volume "
                               "besides the largest): loose pieces fall out of a print and wash out in culture",
                    {"asked": 1, "achieved": n, "volume_fraction": fraction})]


def _on_domain_faces(result):
    """``anchored`` for :func:`~porecad.mesh.shells.keep_largest_piece` of a lattice with no body (a box of
    cells, one cell, a tet mesh): the shells with a vertex on the design domain's boundary — pieces its faces cut
    off, which go on in the next cell — are the lattice's own, not debris."""
    def anchored(v, f, lab, n):
        from ..analysis.domain import make_domain
        from .contract import DeferredDomain
        dom = result.domain.resolve() if isinstance(result.domain, DeferredDomain) else result.domain
        if isinstance(dom, tuple):
            from ..analysis.domain import MeshDomain
            dom = MeshDomain(*dom)
        dom = make_domain(dom, v)  # a box, a mesh (a tet mesh's boundary) or a field
        tol = 1e-5 * float(np.ptp(v, axis=0).max())
        near = dom.wall(v, tol)[0] < tol
        held = np.zeros(n, bool)
        held[lab[near[f].any(axis=1)]] = True
        return held
    return anchored


def _streamed_pieces(report) -> list:
    """The findings of a streamed mesh's pieces: dropped while it was written (an infill's STL), or kept."""
    n = report.get("pieces")
    fraction = float(report.get("islands_volume_fraction") or 0.0)
    dropped = int(report.get("islands_dropped") or 0)
    if dropped:
        return _dropped_findings(dropped, fraction) + ([] if n <= 1 else [Finding(
            "islands", f"the streamed solid is {n} pieces, each at least {100 * NETWORK_FRACTION:.0f} % of the "
                       "largest (kept: interwoven networks or a body in pieces): not attached to each other",
            {"asked": 1, "achieved": int(n), "volume_fraction": 0.0})])
    if not n or n <= 1:
        return []
    return [Finding("islands", f"the streamed solid is {n} separate pieces ({100 * fraction:.2g} % of its volume "
                               "besides the largest), all written: a streamed mesh keeps its loose pieces",
                    {"asked": 1, "achieved": int(n), "volume_fraction": fraction})]


def _dropped_findings(dropped: int, fraction: float) -> list:
    """``islands-dropped`` when the dropped pieces held more than :data:`ISLANDS_LOSS` of the material."""
    if fraction <= ISLANDS_LOSS:
        return []
    return [Finding("islands-dropped", f"{dropped} loose pieces holding {100 * fraction:.0f} % of the "
                                       "material were dropped: the part is thinner than designed "
                                       "(`islands` keep keeps them; a finer sampling or a lower "
                                       "porosity joins them)",
                    {"dropped": int(dropped), "volume_fraction": float(fraction)})]


def _body_pieces(body) -> int:
    """The solid pieces of a mesh body (``(vertices, faces)`` or a :class:`~porecad.bodies.mesh.MeshBody`); 1
    for any other body (a field, none)."""
    from ..mesh.shells import mesh_shells
    mesh = (body.vertices, body.faces) if hasattr(body, "faces") else body
    if not isinstance(mesh, (tuple, list)) or len(mesh) != 2:
        return 1
    return max(mesh_shells(*mesh)["solid_pieces"], 1)


def _porosity(result, asked) -> list:
    """The void fraction of the domain measured on the solid; ``porosity-off`` against ``asked``."""
    from ..mesh.validate import signed_volume
    report = result.report
    dv = result.domain_volume
    if not dv or dv <= 0:
        report["porosity_error"] = None
        return []
    volume = report["volume"] if result.vertices is None else signed_volume(result.vertices, result.faces)
    achieved = 1.0 - float(volume) / float(dv)
    if asked is None:
        report["porosity_error"] = None
        return []
    err = achieved - float(asked)
    report["porosity_error"] = err
    if abs(err) <= POROSITY_TOLERANCE:
        return []
    return [Finding("porosity-off", f"the solid's porosity is {achieved:.3f}, asked {float(asked):.3f} (off by "
                                    f"{err:+.3f}, more than {POROSITY_TOLERANCE:g})",
                    {"asked": float(asked), "achieved": achieved, "error": err})]


def _coverage(result) -> list:
    """Coverage of the body's volume and of its extents by the solid."""
    from ..analysis.coverage import body_coverage
    report = result.report
    measured = body_coverage(result.vertices, result.faces, result.domain_volume, result.body)
    if measured is None:
        return []
    coverage, span = measured
    report["extent_coverage"] = [float(x) for x in span]
    report["coverage"] = coverage
    out = []
    if coverage is None:
        return out
    if coverage < COVERAGE_MIN:
        out.append(Finding("coverage-low", f"the solid fills {100 * coverage:.1f} % of the body's volume "
                                           f"(at least {100 * COVERAGE_MIN:.0f} % expected)",
                           {"asked": COVERAGE_MIN, "achieved": coverage}))
    if span.min() < EXTENT_MIN:
        a = int(np.argmin(span))
        out.append(Finding("extent-short", f"the solid spans {', '.join(f'{100 * x:.0f} %' for x in span)} of the "
                                           f"body's x, y, z extents (short along {'xyz'[a]})",
                           {"asked": EXTENT_MIN, "achieved": [float(x) for x in span]}))
    return out
