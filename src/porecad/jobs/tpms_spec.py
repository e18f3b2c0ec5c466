"""The lattice jobs' recipes: :class:`TpmsSpec` (``tpms``) and :class:`InfillSpec` (``infill``), checked.

The keys of each table are listed in :mod:`porecad.jobs.tpms_job`; every
value is typed and bounded here (:class:`~porecad.jobs.recipe_table.Table`),
so the job itself starts from a spec it can trust.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError, RecipeError, ResourceError

GRADING_KINDS = ("constant", "linear", "radial", "expression", "distance", "points", "image")


@dataclasses.dataclass(frozen=True)
class TpmsSpec:
    """A checked lattice recipe (see the module docstring for the keys)."""

    tpms: dict
    domain: dict
    grading: dict | None
    sampling: dict
    post: dict
    analysis: dict
    scale: dict

    body_required = False

    @classmethod
    def from_recipe(cls, r):
        tpms = _tpms_table(r.table("tpms", required=True))
        domain = _domain_table(r.table("domain"), default="mesh" if cls.body_required else "box")
        if cls.body_required and domain["kind"] == "box":
            raise RecipeError("domain.kind", "an infill needs a body (kind = mesh or disc); a box is job tpms")
        if isinstance(tpms["cell_size"], dict):
            if domain["kind"] == "box":
                raise RecipeError("tpms.cell_size", "cell-size grading needs a body domain (disc or mesh); a box "
                                                     "is counted in cells")
            if domain.get("boundary") == "whole":
                raise RecipeError("tpms.cell_size", "boundary 'whole' keeps complete cells of a regular lattice: "
                                                     "give one cell size, not a ramp")
        grading = _grading_table(r.table("grading")) if r.has("grading") else None
        if grading is not None and (tpms.get("threshold") is not None or tpms.get("porosity") is not None):
            raise RecipeError("grading", "give either a threshold/porosity or a grading field, not both")
        if grading is None and (tpms.get("threshold") is None) == (tpms.get("porosity") is None):
            raise RecipeError("tpms.threshold", "give exactly one of threshold or porosity (or a [grading])")
        if tpms["structure"] == "surface" and tpms.get("porosity") is not None:
            raise RecipeError("tpms.porosity", "a bare surface has no porosity; give a threshold")
        s = r.table("sampling")
        sampling = {}
        if s.has("resolution") and s.has("voxel"):
            raise s.error("voxel", "give either sampling.resolution or sampling.voxel")
        if s.has("voxel"):
            sampling["voxel"] = s.number("voxel", positive=True, hi=1e4)
        elif s.has("resolution") or domain["kind"] != "mesh":
            sampling["resolution"] = s.integer("resolution", 40, lo=2, hi=100_000)
        s.done()
        p = r.table("post")
        post = {"smooth": p.choice("smooth", ("none", "laplacian", "taubin"), "none", fold_case=True),
                "smooth_iterations": p.integer("smooth_iterations", 10, lo=0, hi=10_000),
                "decimate": p.number("decimate", 0.0, nonneg=True, hi=1e6)}
        p.done()
        a = r.table("analysis")
        analysis = {"regions": a.integer("regions", None, lo=0, hi=100),
                    "region_axis": a.choice("region_axis", ("x", "y", "z"), None, fold_case=True)}
        a.done()
        scale = _scale_table(r.table("scale"))
        _check_size(tpms, domain, sampling)
        return cls(tpms, domain, grading, sampling, post, analysis, scale)

    def asked_porosity(self):
        """The uniform porosity the recipe asks for (None: a threshold or a grading)."""
        return None if self.grading else self.tpms.get("porosity")

    def inputs(self) -> list:
        paths = [self.domain.get("path")]
        if self.grading:
            paths += [self.grading.get("file"), self.grading.get("path")]
        return [p for p in paths if p]


class InfillSpec(TpmsSpec):
    """A checked ``infill`` recipe: a lattice job whose domain is a body."""

    body_required = True


def _tpms_table(t) -> dict:
    from ..fields.tpms import get_type
    from ..solids import check_structure
    out = {"type": t.checked("type", lambda v: get_type(str(v)).name),
           "structure": t.checked("structure", check_structure, "sheet"),
           "threshold": t.number("threshold", None),
           "porosity": t.number("porosity", None),
           "allow_closed_pores": t.flag("allow_closed_pores", False)}
    if isinstance(t.data.get("cell_size"), dict):
        c = t.table("cell_size")
        if c.choice("kind", ("linear",), "linear") != "linear":  # pragma: no cover - choice refuses
            raise c.error("kind", "must be linear")
        ramp = {"kind": "linear", "axis": c.choice("axis", ("x", "y", "z"), "z", fold_case=True).lower(),
                "from": c.number("from", positive=True, hi=1e5), "to": c.number("to", positive=True, hi=1e5)}
        for k in ("start", "end"):
            if c.has(k):
                ramp[k] = c.number(k, lo=-1e7, hi=1e7)
        if c.has("centre"):
            ramp["centre"] = c.numbers("centre", length=3, lo=-1e7, hi=1e7)
        c.done()
        out["cell_size"] = ramp
    else:
        cs = t.numbers("cell_size", [1.0], length=(1, 3), positive=True, hi=1e5)
        out["cell_size"] = np.full(3, cs[0]) if len(cs) == 1 else np.asarray(cs)
    out["origin"] = tuple(t.numbers("origin", [0.0, 0.0, 0.0], length=3, lo=-1e7, hi=1e7))
    t.done()
    return out


def _domain_table(d, default: str) -> dict:
    kind = d.choice("kind", ("box", "disc", "mesh"), default)
    dom = {"kind": kind}
    if kind == "box":
        dom["cells"] = d.integers("cells", [1, 1, 1], length=3, lo=1, hi=100_000, what="cell counts")
        dom["origin"] = d.numbers("origin", [0.0, 0.0, 0.0], length=3, lo=-1e7, hi=1e7)
    elif kind == "disc":
        for k in ("a", "b", "height", "notch", "notch_depth", "rim"):
            if d.has(k):
                dom[k] = d.number(k, nonneg=True, hi=1e5)
    else:
        dom["path"] = d.path("path")
        dom["boundary"] = d.choice("boundary", ("cut", "skin", "whole"), "cut")
        if dom["boundary"] == "skin":
            dom["skin"] = d.number("skin", 1.0, positive=True, hi=1e5)
        elif d.has("skin"):
            raise d.error("skin", "a skin thickness needs boundary = 'skin'")
        if d.has("label") and d.has("threshold"):
            raise d.error("label", "give an image body's label or its threshold, not both")
        for k in ("label", "threshold"):
            if d.has(k):
                dom[k] = d.number(k)
        dom["keep_all"] = d.flag("keep_all", False)
        if d.has("units"):
            dom["units"] = d.choice("units", ("mm", "m", "um", "in"), "mm")
    d.done()
    return dom


def _grading_table(g) -> dict:
    """The checked ``[grading]`` table (what each kind takes: :mod:`porecad.grading`)."""
    kind = g.choice("kind", GRADING_KINDS, "constant")
    out = {"kind": kind, "of": g.choice("of", ("threshold", "porosity"), "threshold")}
    num = lambda k, default=None: g.number(k, default, lo=-1e7, hi=1e7)  # noqa: E731
    if kind == "constant":
        out["value"] = num("value")
    elif kind == "linear":
        out.update(axis=g.choice("axis", ("x", "y", "z"), "z", fold_case=True).lower(), start=num("start"),
                   end=num("end"), **{"from": num("from"), "to": num("to")})
        if out["start"] == out["end"]:
            raise g.error("end", "must differ from start")
    elif kind == "radial":
        axes = g.string("axes", "xyz", max_len=3).lower()
        if not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
            raise g.error("axes", f"must be some of x, y, z (e.g. xy), got {axes!r}")
        out.update(axes=axes, centre=g.numbers("centre", [0.0, 0.0, 0.0], length=3, lo=-1e7, hi=1e7),
                   r0=g.number("r0", 0.0, nonneg=True, hi=1e7), r1=g.number("r1", positive=True, hi=1e7),
                   **{"from": num("from"), "to": num("to")})
        if out["r1"] <= out["r0"]:
            raise g.error("r1", "must be larger than r0")
    elif kind == "expression":
        out["expr"] = g.checked("expr", _check_expression)
    elif kind == "distance":
        out.update(d0=g.number("d0", 0.0, nonneg=True, hi=1e7), exponent=g.number("exponent", 1.0, positive=True,
                                                                                  hi=100.0),
                   **{"from": num("from"), "to": num("to")})
        if g.has("d1"):
            out["d1"] = g.number("d1", positive=True, hi=1e7)
    elif kind == "points":
        if g.has("points") == g.has("file"):
            raise g.error("file", "give the points (a list of [x, y, z, value]) or a CSV file, not both")
        if g.has("file"):
            out["file"] = g.path("file")
        else:
            pts = g.raw("points")
            if not isinstance(pts, list) or not 4 <= len(pts) <= 100_000:
                raise g.error("points", "takes 4 to 100,000 rows of [x, y, z, value]")
            out["points"] = [_row(g, i, row) for i, row in enumerate(pts)]
        out["smoothing"] = g.number("smoothing", 0.0, nonneg=True, hi=1e6)
    elif kind == "image":
        out.update(path=g.path("path"), scale=num("scale", 1.0), offset=num("offset", 0.0))
    g.done()
    return out


def _row(g, i, row):
    from .recipe_table import Table
    return Table({"row": row}, g.key(f"points[{i}]")).numbers("row", length=4, lo=-1e7, hi=1e7)


def _check_expression(text):
    """A grading expression, parsed and checked now (:mod:`porecad.expressions`)."""
    from ..expressions import ExpressionError, check_expression
    from ..grading import GRADING_VARIABLES
    try:
        return check_expression(text, GRADING_VARIABLES)
    except ExpressionError as exc:
        raise InputError(f"grading expression is not valid: {exc}") from None


def _scale_table(s) -> dict:
    from ..resources import parse_size
    from ..scale.schedulers import parse_scheduler
    out = {"scheduler": s.checked("scheduler", parse_scheduler, None),
           "stream": s.flag("stream", None) if s.has("stream") else None,
           "zarr": s.output("zarr"),
           "retries": s.integer("retries", 2, lo=0, hi=100),
           "chunk_mb": s.number("chunk_mb", None, positive=True, hi=1 << 16, what="chunk_mb"),
           "max_output": s.checked("max_output", parse_size, None)}
    if out["scheduler"] is None:
        out["scheduler"] = parse_scheduler(None)
    s.done()
    return out


def _check_size(tpms, domain, sampling) -> None:
    """Refuse box grids whose sample count alone is absurd (the memory estimate refines this later)."""
    if domain["kind"] != "box":
        return
    cells = np.asarray(domain["cells"], dtype=float)
    if "resolution" in sampling:
        n = cells * (sampling["resolution"] - 1) + 1
    else:
        cs = tpms["cell_size"] if not isinstance(tpms["cell_size"], dict) else np.ones(3)
        n = cells * np.asarray(cs, float) / sampling["voxel"] + 1
    total = float(np.prod(n))
    if total > 1e13 or not np.isfinite(total):
        raise ResourceError(f"the job is too large: the sampling grid would have {total:.3g} samples; lower the "
                            "resolution or the cell count")
