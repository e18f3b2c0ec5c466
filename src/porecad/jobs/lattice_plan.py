"""Planning a lattice job (``tpms`` / ``infill``): the fields, grid, body and threshold of a checked spec.

A plan is everything the polygoniser needs (the solid field and its
sampling grid) plus the facts the report needs (domain volume and area,
the threshold or grading, the body). No heavy work happens here beyond
loading a body.
"""

from __future__ import annotations

import numpy as np

from ..calibration import check_porosity, check_threshold, threshold_for_porosity, valid_range
from ..errors import InputError, RangeError
from ..fields.base import Field
from ..fields.sdf import LumbarDisc
from ..fields.tpms import TPMSField
from ..grading import PorosityToThreshold, field_from_spec
from ..mesh.polygonise import Grid
from ..solids import StructureField


def graded_cell(spec: dict, box_min, box_max):
    """A cell-size ramp spec -> (GradedCellTPMS kwargs, smallest cell)."""
    axis = spec.get("axis", "z")
    a = "xyz".index(axis)
    L0, L1 = float(spec["from"]), float(spec["to"])
    start = float(spec.get("start", box_min[a]))
    end = float(spec.get("end", box_max[a]))
    centre = spec.get("centre", ((np.asarray(box_min) + np.asarray(box_max)) / 2).tolist())
    return {"L0": L0, "L1": L1, "axis": axis, "start": start, "end": end, "centre": centre}, min(L0, L1)


def body_field(domain: dict, h: float | None):
    """The body field of a non-box domain, its bounds and facts about it.

    ``h`` is the sample spacing; None for a mesh body means its smallest
    extent / 200 (returned as ``voxel`` in the facts).
    """
    kind = domain.get("kind", "box")
    if kind == "disc":
        params = {k: domain[k] for k in ("a", "b", "height", "notch", "notch_depth", "rim") if k in domain}
        body = LumbarDisc(**params)
        lo, hi = body.bounds
        return body, lo, hi, {"kind": "disc"}
    if kind == "mesh":
        from ..bodies import MeshBody, load_body
        boundary = domain.get("boundary", "cut")
        skin = float(domain.get("skin", 1.0)) if boundary == "skin" else 0.0
        image_opts = {key: domain[key] for key in ("label", "threshold") if domain.get(key) is not None}
        v, f, report = load_body(domain["path"], keep_all=bool(domain.get("keep_all", False)), **image_opts)
        ext = np.asarray(report["bounds"][1]) - np.asarray(report["bounds"][0])
        if h is None:
            h = float(ext.min()) / 200.0
            samples = float(np.prod(ext / max(h, 1e-300) + 1))
            if not samples <= MAX_DEFAULT_SAMPLES:  # a thin, long body: the default voxel would take hours
                from ..errors import RecipeError
                raise RecipeError("sampling.voxel", f"the default voxel (smallest body extent / 200 = {h:.3g} mm) "
                                                    f"gives {samples:.3g} samples (at most {MAX_DEFAULT_SAMPLES:.3g} "
                                                    "by default); give a voxel")
        if skin >= 0.5 * float(ext.min()):
            raise InputError(f"skin thickness {skin:g} mm fills the body (smallest extent {ext.min():.3g} mm)")
        body = MeshBody(v, f, band=skin + 2.0 * h)
        lo, hi = body.bounds
        return body, lo, hi, {"kind": "mesh", "volume": report["volume"], "skin": skin,
                              "load_report": report, "voxel": h}
    raise InputError(f"unknown domain kind {kind!r}; use 'box', 'disc' or 'mesh'")


#: most samples the default voxel of a body may give (larger jobs need an explicit voxel)
MAX_DEFAULT_SAMPLES = 2e8


class SkinSolid(Field):
    """``(material ∪ shell) ∩ body`` with the shell ``{-T ≤ d ≤ 0}``: ``max(min(m, -d - T), d)``."""

    def __init__(self, material, body, skin):
        self.material, self.body, self.skin = material, body, float(skin)

    def evaluate(self, points):
        d = self.body(points)
        return np.maximum(np.minimum(self.material(points), -d - self.skin), d)

    def sample_grid(self, xs, ys, zs):
        d = self.body.sample_grid(xs, ys, zs)
        m = self.material.sample_grid(xs, ys, zs)
        np.minimum(m, -d - np.float32(self.skin), out=m)
        np.maximum(m, d, out=m)
        return m


def in_valid_range(check, tpms_type: str, structure: str, value: float, allow: bool) -> bool:
    """Run a valid-range ``check``; with ``allow`` report instead of refusing."""
    try:
        check(tpms_type, structure, value)
    except RangeError:
        if not allow:
            raise
        return False
    return True


def resolve_threshold(tpms_type: str, structure: str, spec: dict, grading: dict | None, context=None):
    """Threshold (number or field) and its description from the recipe's tpms/grading tables.

    ``spec["allow_closed_pores"]`` (default false) builds outside the valid
    range instead of refusing; the description then says
    ``"in_valid_range": False``.
    """
    allow = bool(spec.get("allow_closed_pores", False))
    has_c = spec.get("threshold") is not None
    has_p = spec.get("porosity") is not None
    if grading:
        if has_c or has_p:
            raise InputError("give either a threshold/porosity or a grading field, not both")
        field, of = field_from_spec(grading, context)
        return field, {"grading": dict(grading), "of": of, "allow_closed_pores": allow}
    if has_c == has_p:
        raise InputError("give exactly one of threshold or porosity")
    if has_p:
        if structure == "surface":
            raise InputError("a bare surface has no porosity; give a threshold")
        p = float(spec["porosity"])
        if not 0 < p < 1:
            raise RangeError(f"porosity must lie strictly between 0 and 1, got {p:g}")
        ok = in_valid_range(check_porosity, tpms_type, structure, p, allow)
        c = threshold_for_porosity(tpms_type, structure, p)
        return c, {"threshold": c, "target_porosity": p, "in_valid_range": ok}
    c = float(spec["threshold"])
    if structure == "surface":
        r = valid_range(tpms_type, "surface")["threshold"]
        if not r[0] < c < r[1]:
            raise RangeError(f"threshold {c:g} is outside the value range ({r[0]:.4g}, {r[1]:.4g}) of "
                             f"{tpms_type}: the surface would be empty")
        return c, {"threshold": c}
    ok = in_valid_range(check_threshold, tpms_type, structure, c, allow)
    return c, {"threshold": c, "in_valid_range": ok}


def check_graded(field, of, tpms_type, structure, grid, allow=False, body=None):
    """Check a graded threshold/porosity field against the valid range on a coarse grid (inside the body)."""
    xs = np.linspace(grid.box_min[0], grid.box_max[0], 33)
    ys = np.linspace(grid.box_min[1], grid.box_max[1], 33)
    zs = np.linspace(grid.box_min[2], grid.box_max[2], 33)
    vals = field.sample_grid(xs, ys, zs)
    if body is not None:
        inside = body.sample_grid(xs, ys, zs) < 0
        if inside.any():
            vals = vals[inside]
    lo, hi = float(vals.min()), float(vals.max())
    if of == "porosity":
        for p in (lo, hi):
            if not np.isfinite(p) or not 0 < p < 1:
                raise RangeError(f"porosity must lie strictly between 0 and 1, got {p:g}")
        ok = all([in_valid_range(check_porosity, tpms_type, structure, p, allow) for p in (lo, hi)])
        return PorosityToThreshold(field, tpms_type, structure), {"porosity_min": lo, "porosity_max": hi,
                                                                  "in_valid_range": ok}
    ok = all([in_valid_range(check_threshold, tpms_type, structure, c, allow) for c in (lo, hi)])
    return field, {"threshold_min": lo, "threshold_max": hi, "in_valid_range": ok}


def plan_lattice(spec) -> dict:
    """Build everything needed to run a checked lattice spec (:class:`porecad.jobs.tpms_job.TpmsSpec`)."""
    tp = spec.tpms
    ttype, structure = tp["type"], tp["structure"]
    cell = tp["cell_size"]
    domain = spec.domain
    h = spec.sampling.get("voxel")
    res = spec.sampling.get("resolution", 40)
    body = None
    body_info = None
    graded_cell_spec = isinstance(cell, dict)
    if graded_cell_spec:
        smallest = min(float(cell["from"]), float(cell["to"]))
    if domain["kind"] == "box":
        cells = np.asarray(domain["cells"])
        lo = np.asarray(domain.get("origin", [0.0, 0.0, 0.0]), dtype=float)
        hi = lo + cells * cell
        if h is None:
            n = cells * (res - 1) + 1
        else:
            n = np.maximum(np.round((hi - lo) / h).astype(np.int64), 1) + 1
        grid = Grid.from_box(lo, hi, samples_per_axis=n)
        domain_volume = float(np.prod(hi - lo))
        ext = hi - lo
    else:
        if h is None and not (domain["kind"] == "mesh" and "resolution" not in spec.sampling):
            h = (smallest if graded_cell_spec else float(np.min(cell))) / (res - 1)
        body, blo, bhi, body_info = body_field(domain, h)
        h = body_info.get("voxel", h)
        pad = 2.0 * h
        grid = Grid.from_box(blo - pad, bhi + pad, spacing=h)
        domain_volume = body_info.get("volume") or float(np.prod(bhi - blo))  # refined by the body mesh
        ext = bhi - blo
    domain_area = float(2 * (ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2]))
    cell_grading = None
    if graded_cell_spec:
        from ..fields.graded_cell import GradedCellTPMS
        cell_grading, smallest = graded_cell(cell, blo, bhi)
        phi = GradedCellTPMS(ttype, **cell_grading)
        cell = np.full(3, smallest)
    else:
        phi = TPMSField(ttype, cell, origin=tp.get("origin", (0.0, 0.0, 0.0)))
    context = grading_context(grid, cell, float(np.min(grid.spacing)), body, body_info)
    threshold, tinfo = resolve_threshold(ttype, structure, tp, spec.grading, context)
    if not isinstance(threshold, float):
        threshold, extra = check_graded(threshold, tinfo["of"], ttype, structure, grid,
                                        allow=tinfo.pop("allow_closed_pores"), body=body)
        tinfo.update(extra)
    if cell_grading is not None:
        tinfo["cell_size_grading"] = cell_grading
    material = StructureField(phi, structure, threshold)
    boundary = domain.get("boundary", "cut") if body is not None else None
    if body is None:
        field = material
    elif boundary == "cut":
        field = material & body
    elif boundary == "skin":
        # (material ∪ shell) ∩ body with shell = {-T <= d <= 0}: max(min(m, -d - T), d)
        field = SkinSolid(material, body, body_info["skin"])
    else:  # whole: restricted to the complete cells when the job runs (needs a pass over the body)
        field = material
    return {"type": ttype, "structure": structure, "cell_size": cell, "grid": grid,
            "field": field, "body": body, "threshold_info": tinfo, "domain_volume": domain_volume,
            "domain_area": domain_area, "closed": structure != "surface", "boundary": boundary,
            "body_info": body_info, "material": material,
            "origin": np.asarray(tp.get("origin", (0.0, 0.0, 0.0)), dtype=float),
            "cells_pending": boundary == "whole", "context": context}

def grading_context(grid, cell, h, body, body_info):
    """Grading context: the grid box, coarse caches at an eighth of a cell, the body's depth."""
    from ..grading import GradingContext

    coarse = max(float(np.min(cell)) / 8.0, float(h) if h else 0.0)
    factory = None
    if body is not None:
        if body_info.get("kind") == "mesh":
            def factory():
                from ..bodies.distance import BodyDepth
                return BodyDepth(body, coarse)
        else:
            def factory():
                from ..fields.gridded import cache_on_grid
                depth = cache_on_grid(-body, grid.box_min, grid.box_max, coarse)
                depth.max_depth = float(depth.values.max())
                return depth
    return GradingContext(grid.box_min, grid.box_max, coarse, depth=factory)


def post_process(vertices, faces, post: dict, grid, boxed: bool):
    smooth = post.get("smooth", "none")
    iters = int(post.get("smooth_iterations", 10))
    if smooth != "none" and iters > 0:
        from ..mesh import smooth as sm
        fixed = None
        if boxed:
            tol = 1e-9 * float(np.max(grid.box_max - grid.box_min))
            fixed = (np.any(np.abs(vertices - grid.box_min) <= tol, axis=1)
                     | np.any(np.abs(vertices - grid.box_max) <= tol, axis=1))
        fn = sm.taubin_smooth if smooth == "taubin" else sm.laplacian_smooth
        vertices = fn(vertices, faces, iterations=iters, fixed=fixed)
    tol = float(post.get("decimate", 0.0) or 0.0)
    if tol > 0:
        from ..mesh.decimate import decimate
        vertices, faces = decimate(vertices, faces, tol)
    return vertices, faces


