"""The lattice jobs' recipes: :class:`TpmsSpec` (``tpms``) and :class:`InfillSpec` (``infill``), checked.

The keys of each table are listed in :mod:`porecad.jobs.tpms_job`; every
value is typed and bounded here (:class:`~porecad.recipes.table.Table`) into
the records of :mod:`porecad.lattice.spec`, so the job starts from a spec it can trust.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError, RecipeError, ResourceError
from ..grading import Grading
from ..lattice.spec import Analysis, CellRamp, Domain, Lattice, Post, Sampling, Scale
from ..recipes.keys import GRADING

#: the kinds of grading field (declared in porecad.recipes.keys)
GRADING_KINDS = GRADING["kind"].choices


@dataclasses.dataclass(frozen=True)
class TpmsSpec:
    """A checked lattice recipe (see the module docstring for the keys)."""

    tpms: Lattice
    domain: Domain
    grading: Grading | None
    sampling: Sampling
    post: Post
    analysis: Analysis
    scale: Scale

    body_required = False

    @classmethod
    def from_recipe(cls, r):
        tpms = _tpms_table(r.table("tpms", required=True))
        domain = _domain_table(r.table("domain"))
        if cls.body_required and domain.kind == "box":
            raise RecipeError("domain.kind", "an infill needs a body (kind = mesh or disc); a box is job tpms")
        if isinstance(tpms.cell_size, CellRamp):
            if domain.kind == "box":
                raise RecipeError("tpms.cell_size", "cell-size grading needs a body domain (disc or mesh); a box "
                                                     "is counted in cells")
            if domain.boundary == "whole":
                raise RecipeError("tpms.cell_size", "boundary 'whole' keeps complete cells of a regular lattice: "
                                                     "give one cell size, not a ramp")
        grading = _grading_table(r.table("grading")) if r.has("grading") else None
        if grading is not None and (tpms.threshold is not None or tpms.porosity is not None):
            raise RecipeError("grading", "give either a threshold/porosity or a grading field, not both")
        r.table("tpms").one_of("threshold", waived=grading is not None, alternative=" (or a [grading])")
        if tpms.structure == "surface" and tpms.porosity is not None:
            raise RecipeError("tpms.porosity", "a bare surface has no porosity; give a threshold")
        s = r.table("sampling")
        if s.has("resolution") and s.has("voxel"):
            raise s.error("voxel", "give either sampling.resolution or sampling.voxel")
        if s.has("voxel"):
            sampling = Sampling(voxel=s.get("voxel"))
        elif s.has("resolution") or domain.kind != "mesh":
            sampling = Sampling(resolution=s.get("resolution"))
        else:
            sampling = Sampling()
        s.done()
        p = r.table("post")
        post = Post(p.get("smooth"), p.get("smooth_iterations"), p.get("decimate"))
        p.done()
        a = r.table("analysis")
        analysis = Analysis(a.get("regions"), a.get("region_axis"))
        a.done()
        scale = _scale_table(r.table("scale"))
        _check_size(tpms, domain, sampling)
        return cls(tpms, domain, grading, sampling, post, analysis, scale)

    def asked_porosity(self):
        """The uniform porosity the recipe asks for (None: a threshold or a grading)."""
        return None if self.grading else self.tpms.porosity

    def inputs(self) -> list:
        paths = [self.domain.path]
        if self.grading:
            paths += [self.grading.file, self.grading.path]
        return [p for p in paths if p]


class InfillSpec(TpmsSpec):
    """A checked ``infill`` recipe: a lattice job whose domain is a body."""

    body_required = True


def _tpms_table(t) -> Lattice:
    from ..fields.tpms import get_type
    from ..solids import check_structure
    ttype = t.get("type", check=lambda v: get_type(str(v)))
    structure = t.get("structure", check=check_structure)
    threshold, porosity, allow = t.get("threshold"), t.get("porosity"), t.get("allow_closed_pores")
    if isinstance(t.data.get("cell_size"), dict):
        c = t.table("cell_size")
        if c.get("kind") != "linear":  # pragma: no cover - choice refuses
            raise c.error("kind", "must be linear")
        axis, L0, L1 = c.get("axis").lower(), c.get("from"), c.get("to")
        cell = CellRamp(axis, L0, L1, *(_given(c, k) for k in ("start", "end", "centre")))
        c.done()
    else:
        cs = t.get("cell_size")
        cell = np.full(3, cs[0]) if len(cs) == 1 else np.asarray(cs)
    out = Lattice(ttype, structure, threshold, porosity, allow, cell, tuple(t.get("origin")))
    t.done()
    return out


def _domain_table(d) -> Domain:
    kind = d.get("kind")
    if kind == "box":
        dom = Domain(kind, cells=d.get("cells"), origin=d.get("origin"))
    elif kind == "disc":
        dom = Domain(kind, **{k: _given(d, k) for k in ("a", "b", "height", "notch", "notch_depth", "rim")})
    else:
        path, boundary = d.get("path"), d.get("boundary")
        skin = d.get("skin") if boundary == "skin" else None
        if boundary != "skin" and d.has("skin"):
            raise d.error("skin", "a skin thickness needs boundary = 'skin'")
        if d.has("label") and d.has("threshold"):
            raise d.error("label", "give an image body's label or its threshold, not both")
        dom = Domain(kind, path=path, boundary=boundary, skin=skin, label=_given(d, "label"),
                     threshold=_given(d, "threshold"), keep_all=d.get("keep_all"), units=_given(d, "units"))
    d.done()
    return dom


def _grading_table(g) -> Grading:
    """The checked ``[grading]`` table (what each kind takes: :mod:`porecad.grading`)."""
    kind = g.get("kind")
    keys = {"kind": kind, "of": g.get("of")}
    ramp = lambda: {"value_from": g.get("from"), "value_to": g.get("to")}  # noqa: E731
    if kind == "constant":
        keys["value"] = g.get("value")
    elif kind == "linear":
        keys.update(axis=g.get("axis").lower(), start=g.get("start"), end=g.get("end"), **ramp())
        if keys["start"] == keys["end"]:
            raise g.error("end", "must differ from start")
    elif kind == "radial":
        axes = g.get("axes").lower()
        if not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
            raise g.error("axes", f"must be some of x, y, z (e.g. xy), got {axes!r}")
        keys.update(axes=axes, centre=g.get("centre"), r0=g.get("r0"), r1=g.get("r1"), **ramp())
        if keys["r1"] <= keys["r0"]:
            raise g.error("r1", "must be larger than r0")
    elif kind == "expression":
        keys["expr"] = g.get("expr", check=_check_expression)
    elif kind == "distance":
        keys.update(d0=g.get("d0"), exponent=g.get("exponent"), **ramp(), d1=_given(g, "d1"))
    elif kind == "points":
        if g.has("points") == g.has("file"):
            raise g.error("file", "give the points (a list of [x, y, z, value]) or a CSV file, not both")
        if g.has("file"):
            keys["file"] = g.get("file")
        else:
            pts = g.get("points")
            if not isinstance(pts, list) or not 4 <= len(pts) <= 100_000:
                raise g.error("points", "takes 4 to 100,000 rows of [x, y, z, value]")
            keys["points"] = [_row(g, i, row) for i, row in enumerate(pts)]
        keys["smoothing"] = g.get("smoothing")
    elif kind == "image":
        keys.update(path=g.get("path"), scale=g.get("scale"), offset=g.get("offset"))
    g.done()
    return Grading(**keys)


def _given(t, k):
    """``t.get(k)`` where ``k`` is given, else None (unread: a misspelt key's error lists the keys read)."""
    return t.get(k) if t.has(k) else None


def _row(g, i, row):
    from ..recipes.table import Table
    return Table({"row": row}, g.key(f"points[{i}]")).numbers("row", length=4, lo=-1e7, hi=1e7)


def _check_expression(text):
    """A grading expression, parsed and checked now (:mod:`porecad.expressions`)."""
    from ..expressions import ExpressionError, check_expression
    from ..grading import GRADING_VARIABLES
    try:
        return check_expression(text, GRADING_VARIABLES)
    except ExpressionError as exc:
        raise InputError(f"grading expression is not valid: {exc}") from None


def _scale_table(s) -> Scale:
    from ..resources import parse_size
    from ..scale.schedulers import parse_scheduler, recipe_scheduler
    given = s.data.get("scheduler")  # a recipe file's own scheduler (not typed on the command line): untrusted
    shared = s.confine is not None and not (isinstance(given, str) and given in s.confine[1])
    scheduler = s.get("scheduler", check=recipe_scheduler if shared else parse_scheduler)
    out = Scale(scheduler if scheduler is not None else parse_scheduler(None),
                stream=s.get("stream") if s.has("stream") else None, zarr=s.get("zarr"), retries=s.get("retries"),
                chunk_mb=s.get("chunk_mb"), max_output=s.get("max_output", check=parse_size))
    s.done()
    return out


def _check_size(tpms: Lattice, domain: Domain, sampling: Sampling) -> None:
    """Refuse box grids whose sample count alone is absurd (the memory estimate refines this later)."""
    if domain.kind != "box":
        return
    cells = np.asarray(domain.cells, dtype=float)
    if sampling.resolution is not None:
        n = cells * (sampling.resolution - 1) + 1
    else:
        cs = tpms.cell_size if not isinstance(tpms.cell_size, CellRamp) else np.ones(3)
        n = cells * np.asarray(cs, float) / sampling.voxel + 1
    total = float(np.prod(n))
    if total > 1e13 or not np.isfinite(total):
        raise ResourceError(f"the job is too large: the sampling grid would have {total:.3g} samples; lower the "
                            "resolution or the cell count")
