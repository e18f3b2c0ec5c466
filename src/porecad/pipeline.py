"""The one pipeline: recipe -> field -> solid -> chunked polygonise -> post -> validate -> export.

A recipe is a plain dict (TOML on disk, :mod:`porecad.io.recipe`)::

    job = "tpms"
    [tpms]     type = "G", structure = "sheet", porosity = 0.6 | threshold = 0.4, cell_size = 1.0
    [domain]   kind = "box", cells = [2, 2, 2]      |  kind = "disc" (analytic lumbar disc) + params
    [grading]  optional threshold/porosity field spec (porecad.grading)
    [sampling] resolution = 40 (samples per cell edge, both ends included) | voxel = 0.1 (mm)
    [post]     smooth = "none" | "laplacian" | "taubin", smooth_iterations = 10, decimate = 0.0
    [output]   mesh = "out.stl", report = "out.json", recipe = "out.toml"
    [scale]    scheduler = "threads" | "local:N" | "tcp://HOST:PORT", stream = true, zarr = "f.zarr",
               retries = 2, chunk_mb = 64   (optional: porecad.scale, docs/scale-out.md)

:func:`run_recipe` returns the report (a JSON-ready dict). Nothing is written
unless the whole job succeeded and the solid passed validation.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from . import __version__
from .calibration import (check_porosity, check_threshold, porosity_of_threshold,
                          threshold_for_porosity, valid_range)
from .errors import InputError, MeshError, RangeError
from .fields.base import Field
from .fields.sdf import LumbarDisc
from .fields.tpms import TPMSField, get_type
from .grading import PorosityToThreshold, field_from_spec
from .mesh.polygonise import Grid, default_threads, polygonise
from .resources import available_memory, estimate, estimate_streamed, require_fits
from .solids import StructureField, check_structure

CHUNK_BYTES = 16 << 20


def _positive_float(value, name):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be positive, got {value!r}")
    return v


def _graded_cell(spec: dict, box_min, box_max):
    """A cell-size ramp spec -> (GradedCellTPMS kwargs, smallest cell)."""
    if spec.get("kind", "linear") != "linear":
        raise InputError("cell-size grading supports kind = 'linear' (an axial ramp)")
    axis = str(spec.get("axis", "z")).lower()
    if axis not in ("x", "y", "z"):
        raise InputError(f"cell-size grading axis must be x, y or z, got {axis!r}")
    a = "xyz".index(axis)
    try:
        L0 = _positive_float(spec["from"], "cell size")
        L1 = _positive_float(spec["to"], "cell size")
    except KeyError as exc:
        raise InputError(f"cell-size grading is missing {exc.args[0]!r}") from None
    start = float(spec.get("start", box_min[a]))
    end = float(spec.get("end", box_max[a]))
    centre = spec.get("centre", ((np.asarray(box_min) + np.asarray(box_max)) / 2).tolist())
    return {"L0": L0, "L1": L1, "axis": axis, "start": start, "end": end, "centre": centre}, min(L0, L1)


def _cell_size(value):
    if isinstance(value, dict):
        return value  # graded: resolved once the domain box is known
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise InputError("cell_size takes one number or three (x, y, z)")
        return np.array([_positive_float(v, "cell size") for v in value])
    return np.full(3, _positive_float(value, "cell size"))


def _cells(value):
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise InputError("cells takes three integers NX NY NZ")
    out = []
    for v in value:
        if isinstance(v, bool) or not float(v).is_integer() or int(v) < 1:
            raise InputError(f"cell counts must be positive integers, got {v!r}")
        out.append(int(v))
    return np.array(out)


def _body_field(domain: dict, h: float | None):
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
        from .bodies import MeshBody, load_body
        if not domain.get("path"):
            raise InputError("domain kind 'mesh' needs a path")
        boundary = domain.get("boundary", "cut")
        if boundary not in ("cut", "skin", "whole"):
            raise InputError(f"unknown boundary mode {boundary!r}; use cut, skin or whole")
        skin = 0.0
        if boundary == "skin":
            skin = _positive_float(domain.get("skin", 1.0), "skin thickness")
        elif domain.get("skin") is not None:
            raise InputError("a skin thickness needs boundary = 'skin'")
        image_opts = {}
        for key in ("label", "threshold"):
            if domain.get(key) is not None:
                try:
                    image_opts[key] = float(domain[key])
                except (TypeError, ValueError):
                    raise InputError(f"body {key} must be a number, got {domain[key]!r}") from None
        v, f, report = load_body(domain["path"], keep_all=_flag(domain.get("keep_all", False), "keep_all"),
                                 **image_opts)
        ext = np.asarray(report["bounds"][1]) - np.asarray(report["bounds"][0])
        if h is None:
            h = float(ext.min()) / 200.0
        if skin >= 0.5 * float(ext.min()):
            raise InputError(f"skin thickness {skin:g} mm fills the body (smallest extent {ext.min():.3g} mm)")
        body = MeshBody(v, f, band=skin + 2.0 * h)
        lo, hi = body.bounds
        return body, lo, hi, {"kind": "mesh", "volume": report["volume"], "skin": skin,
                              "load_report": report, "voxel": h}
    raise InputError(f"unknown domain kind {kind!r}; use 'box', 'disc' or 'mesh'")


class _SkinSolid(Field):
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


class _Stage:
    """Progress reporting helper: forwards (stage, done, total) to a callback."""

    def __init__(self, callback):
        self.callback = callback

    def __call__(self, stage):
        if self.callback is None:
            return None
        return lambda done, total: self.callback(stage, done, total)


def _flag(value, name: str) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{name} must be true or false, got {value!r}")
    return value


def _in_valid_range(check, tpms_type: str, structure: str, value: float, allow: bool) -> bool:
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
    allow = _flag(spec.get("allow_closed_pores", False), "allow_closed_pores")
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
        try:
            p = float(spec["porosity"])
        except (TypeError, ValueError):
            raise InputError(f"porosity must be a number, got {spec['porosity']!r}") from None
        if not np.isfinite(p) or not 0 < p < 1:
            raise RangeError(f"porosity must lie strictly between 0 and 1, got {p:g}")
        ok = _in_valid_range(check_porosity, tpms_type, structure, p, allow)
        c = threshold_for_porosity(tpms_type, structure, p)
        return c, {"threshold": c, "target_porosity": p, "in_valid_range": ok}
    try:
        c = float(spec["threshold"])
    except (TypeError, ValueError):
        raise InputError(f"threshold must be a number, got {spec['threshold']!r}") from None
    if structure == "surface":
        r = valid_range(tpms_type, "surface")["threshold"]
        if not r[0] < c < r[1]:
            raise RangeError(f"threshold {c:g} is outside the value range ({r[0]:.4g}, {r[1]:.4g}) of "
                             f"{tpms_type}: the surface would be empty")
        return c, {"threshold": c}
    ok = _in_valid_range(check_threshold, tpms_type, structure, c, allow)
    return c, {"threshold": c, "in_valid_range": ok}


def _check_graded(field, of, tpms_type, structure, grid, allow=False, body=None):
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
        ok = all([_in_valid_range(check_porosity, tpms_type, structure, p, allow) for p in (lo, hi)])
        return PorosityToThreshold(field, tpms_type, structure), {"porosity_min": lo, "porosity_max": hi,
                                                                  "in_valid_range": ok}
    ok = all([_in_valid_range(check_threshold, tpms_type, structure, c, allow) for c in (lo, hi)])
    return field, {"threshold_min": lo, "threshold_max": hi, "in_valid_range": ok}


def plan_tpms(recipe: dict) -> dict:
    """Validate a tpms recipe and build everything needed to run it (no heavy work)."""
    spec = dict(recipe.get("tpms", {}))
    if "type" not in spec:
        raise InputError("recipe [tpms] needs a type")
    ttype = get_type(spec["type"]).name
    structure = check_structure(spec.get("structure", "sheet"))
    cell = _cell_size(spec.get("cell_size", 1.0))
    domain = dict(recipe.get("domain", {"kind": "box", "cells": [1, 1, 1]}))
    sampling = dict(recipe.get("sampling", {}))
    if "resolution" in sampling and "voxel" in sampling:
        raise InputError("give either sampling.resolution or sampling.voxel")
    if "voxel" in sampling:
        h = _positive_float(sampling["voxel"], "voxel size")
    else:
        res = sampling.get("resolution", 40)
        if isinstance(res, bool) or not float(res).is_integer() or int(res) < 2:
            raise InputError(f"resolution must be an integer >= 2 (samples per cell edge), got {res!r}")
        h = None
        res = int(res)
    body = None
    graded_cell = isinstance(cell, dict)
    if graded_cell:
        if domain.get("kind", "box") == "box":
            raise InputError("cell-size grading needs a body domain (disc or mesh); a box is counted in cells")
        if domain.get("boundary") == "whole":
            raise InputError("boundary 'whole' keeps complete cells of a regular lattice: "
                             "give one cell size, not a ramp")
        smallest = min(_positive_float(cell.get("from", 1.0), "cell size"),
                       _positive_float(cell.get("to", 1.0), "cell size"))
    if domain.get("kind", "box") == "box":
        cells = _cells(domain.get("cells", [1, 1, 1]))
        lo = np.asarray(domain.get("origin", [0.0, 0.0, 0.0]), dtype=float)
        hi = lo + cells * cell
        if h is None:
            n = cells * (res - 1) + 1
        else:
            n = np.maximum(np.round((hi - lo) / h).astype(np.int64), 1) + 1
        grid = Grid.from_box(lo, hi, samples_per_axis=n)
        domain_volume = float(np.prod(hi - lo))
        ext = hi - lo
        domain_area = float(2 * (ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2]))
    else:
        if h is None and not (domain.get("kind") == "mesh" and "resolution" not in sampling):
            h = (smallest if graded_cell else float(np.min(cell))) / (res - 1)
        body, blo, bhi, body_info = _body_field(domain, h)
        h = body_info.get("voxel", h)
        pad = 2.0 * h
        grid = Grid.from_box(blo - pad, bhi + pad, spacing=h)
        domain_volume = body_info.get("volume") or float(np.prod(bhi - blo))  # refined by the body mesh
        ext = bhi - blo
        domain_area = float(2 * (ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2]))
    cell_grading = None
    if graded_cell:
        from .fields.graded_cell import GradedCellTPMS
        cell_grading, smallest = _graded_cell(cell, blo, bhi)
        phi = GradedCellTPMS(ttype, **cell_grading)
        cell = np.full(3, smallest)
    else:
        phi = TPMSField(ttype, cell, origin=spec.get("origin", (0.0, 0.0, 0.0)))
    context = _grading_context(grid, cell, float(np.min(grid.spacing)), body, body_info if body is not None else None)
    threshold, tinfo = resolve_threshold(ttype, structure, spec, recipe.get("grading"), context)
    if not isinstance(threshold, float):
        threshold, extra = _check_graded(threshold, tinfo["of"], ttype, structure, grid,
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
        field = _SkinSolid(material, body, body_info["skin"])
    elif boundary == "whole":
        field = material  # restricted to the complete cells in run_recipe (needs a pass over the body)
    else:
        raise InputError(f"unknown boundary mode {boundary!r}; use cut, skin or whole")
    return {"type": ttype, "structure": structure, "cell_size": cell, "grid": grid,
            "field": field, "body": body, "threshold_info": tinfo, "domain_volume": domain_volume,
            "domain_area": domain_area, "closed": structure != "surface", "boundary": boundary,
            "body_info": body_info if body is not None else None, "material": material,
            "origin": np.asarray(spec.get("origin", (0.0, 0.0, 0.0)), dtype=float),
            "cells_pending": boundary == "whole", "context": context}


def _grading_context(grid, cell, h, body, body_info):
    """Grading context: the grid box, coarse caches at an eighth of a cell, the body's depth."""
    from .grading import GradingContext

    coarse = max(float(np.min(cell)) / 8.0, float(h) if h else 0.0)
    factory = None
    if body is not None:
        if body_info.get("kind") == "mesh":
            def factory():
                from .bodies.distance import BodyDepth
                return BodyDepth(body, coarse)
        else:
            def factory():
                from .fields.gridded import cache_on_grid
                depth = cache_on_grid(-body, grid.box_min, grid.box_max, coarse)
                depth.max_depth = float(depth.values.max())
                return depth
    return GradingContext(grid.box_min, grid.box_max, coarse, depth=factory)


def _post_process(vertices, faces, post: dict, grid, boxed: bool):
    smooth = str(post.get("smooth", "none")).lower()
    iters = int(post.get("smooth_iterations", 10))
    if smooth not in ("none", "laplacian", "taubin"):
        raise InputError(f"unknown smoothing {smooth!r}; use none, laplacian or taubin")
    if smooth != "none" and iters > 0:
        from .mesh import smooth as sm
        fixed = None
        if boxed:
            tol = 1e-9 * float(np.max(grid.box_max - grid.box_min))
            fixed = (np.any(np.abs(vertices - grid.box_min) <= tol, axis=1)
                     | np.any(np.abs(vertices - grid.box_max) <= tol, axis=1))
        fn = sm.taubin_smooth if smooth == "taubin" else sm.laplacian_smooth
        vertices = fn(vertices, faces, iterations=iters, fixed=fixed)
    tol = float(post.get("decimate", 0.0) or 0.0)
    if tol > 0:
        from .mesh.decimate import decimate
        vertices, faces = decimate(vertices, faces, tol)
    return vertices, faces


def scale_options(recipe: dict) -> dict:
    """The recipe's ``[scale]`` table, checked: scheduler, stream (None: automatic), zarr, retries, chunk_mb."""
    from .scale.schedulers import parse_scheduler
    table = dict(recipe.get("scale") or {})
    unknown = set(table) - {"scheduler", "stream", "zarr", "retries", "chunk_mb"}
    if unknown:
        raise InputError(f"unknown [scale] setting {sorted(unknown)[0]!r}; "
                         "use scheduler, stream, zarr, retries, chunk_mb")
    stream = table.get("stream")
    if stream is not None:
        stream = _flag(stream, "stream")
    retries = table.get("retries", 2)
    if isinstance(retries, bool) or not float(retries).is_integer() or not 0 <= int(retries) <= 100:
        raise InputError(f"retries must be an integer 0-100, got {retries!r}")
    chunk_mb = table.get("chunk_mb")
    if chunk_mb is not None:
        chunk_mb = _positive_float(chunk_mb, "chunk_mb")
        if chunk_mb > 1 << 16:
            raise InputError(f"chunk_mb must be at most 65536, got {chunk_mb:g}")
    zarr = table.get("zarr")
    return {"scheduler": parse_scheduler(table.get("scheduler")), "stream": stream,
            "zarr": str(zarr) if zarr else None, "retries": int(retries), "chunk_mb": chunk_mb}


def _stream_blockers(recipe: dict, out: dict, check_intersections: bool) -> list[str]:
    """Why this job cannot stream its mesh (empty list: it can)."""
    from .analysis.report import is_report_dir
    post = dict(recipe.get("post", {}))
    why = []
    if str(post.get("smooth", "none")).lower() != "none" and int(post.get("smooth_iterations", 10)) > 0:
        why.append("smoothing")
    if float(post.get("decimate", 0.0) or 0.0) > 0:
        why.append("decimation")
    if check_intersections:
        why.append("the self-intersection check")
    if out.get("mesh") and Path(str(out["mesh"])).suffix.lower() not in (".stl", ".ply"):
        why.append(f"{Path(str(out['mesh'])).suffix or 'this'} output (stream .stl or .ply)")
    if out.get("report") and is_report_dir(out["report"]):
        why.append("a report directory (use a .json report)")
    return why


def _polygonise_scaled(plan, scale, scheduler, stream, mesh_path, force, chunk_bytes, est, progress):
    """The main polygonisation on a scheduler (:mod:`porecad.scale`), in memory or streamed.

    Returns ``(vertices, faces, inside_fraction, check, scale_info)``;
    vertices and faces are None when streamed (the mesh is then already
    written and ``check`` is the streamed check). The zarr store, if asked
    for, is published only when the run succeeded.
    """
    from .mesh.polygonise import slab_job
    from .scale.build import collect_mesh, stream_mesh
    from .scale.memwatch import PeakMemory
    grid = plan["grid"]
    job = slab_job(plan["field"].sample_grid, grid, caps=plan["closed"], chunk_bytes=chunk_bytes)
    store = None
    if scale["zarr"]:
        from .io.zarr_field import create_store
        store = create_store(scale["zarr"], grid, job.planes, force=force)
        job = dataclasses.replace(job, zarr_path=store)
    vertices = faces = chk = None
    try:
        with PeakMemory() as mem, scheduler as sched:
            if stream:
                centre = (grid.box_min + grid.box_max) / 2
                chk, stats = stream_mesh(job, sched, mesh_path, force=force, solid=plan["closed"],
                                         retries=scale["retries"], progress=progress,
                                         expected_bytes=est["stl_bytes"], centre=centre)
            else:
                vertices, faces, stats = collect_mesh(job, sched, retries=scale["retries"], progress=progress)
        if store is not None:
            from .io.zarr_field import commit_store
            commit_store(store, scale["zarr"], force=force)
            store = None
    finally:
        if store is not None:
            from .io.zarr_field import discard_store
            discard_store(store)
    info = {k: v for k, v in stats.items() if k != "inside_fraction"}
    info.update({"stream": bool(stream), "peak_memory_bytes": mem.peak_bytes,
                 "chunk_bytes": int(chunk_bytes)})
    if scale["zarr"]:
        info["zarr"] = scale["zarr"]
    return vertices, faces, stats["inside_fraction"], chk, info


def run_recipe(recipe: dict, force: bool = False, progress=None, threads: int | None = None,
               check_intersections: bool = False, memory_limit: int | None = None) -> dict:
    """Run a recipe; write its outputs atomically; return the report dict."""
    from .io import write_mesh
    from .io.recipe import save_recipe
    from .outputs import check_outputs, validated_report, write_report_output

    t0 = time.perf_counter()
    job = recipe.get("job")
    if job != "tpms":
        raise InputError(f"unknown job {job!r}; this version runs job = \"tpms\"")
    out = dict(recipe.get("output", {}))
    scale = scale_options(recipe)
    check_outputs(out, ("mesh", "report", "recipe"), force)
    if scale["zarr"]:
        from .io.zarr_field import check_store_path
        check_store_path(scale["zarr"], force)
    plan = plan_tpms(recipe)
    grid = plan["grid"]
    threads = default_threads() if threads is None else threads
    chunk_bytes = CHUNK_BYTES if scale["chunk_mb"] is None else int(scale["chunk_mb"] * 2**20)
    est = estimate(grid, plan["cell_size"], plan["structure"], plan["domain_volume"],
                   plan["domain_area"], chunk_bytes, threads)
    stream = scale["stream"]
    blockers = _stream_blockers(recipe, out, check_intersections)
    if stream and blockers:
        raise InputError(f"streamed output is not possible with {', '.join(blockers)}")
    if stream is None:  # automatic: stream when the whole mesh would not fit comfortably
        limit = available_memory() if memory_limit is None else int(memory_limit)
        stream = not blockers and est["peak_bytes"] > 0.5 * limit
    spec = scale["scheduler"]
    on_scale = stream or spec.kind != "threads" or scale["zarr"] is not None
    if on_scale:
        from .scale import open_scheduler
        scheduler = open_scheduler(spec, threads)  # fails here (one line) without dask
        if stream:
            workers = spec.workers or (threads if spec.kind == "threads" else 1)
            est = estimate_streamed(est, grid, chunk_bytes, workers, 2 * workers + 1,
                                    processes=spec.kind != "threads")
    require_fits(est, memory_limit)
    stage = _Stage(progress)
    timings = {}
    whole_info = None
    if plan["cells_pending"]:
        from .bodies.cells import CellUnion, complete_cells
        t = time.perf_counter()
        margin = float(np.linalg.norm(grid.spacing))  # one sample diagonal
        kept, c_lo = complete_cells(plan["body"].sample_grid, grid, plan["origin"], plan["cell_size"],
                                    margin, progress=stage("cells"))
        if not kept.any():
            raise InputError("no complete cell fits inside the body; use smaller cells or boundary 'cut'")
        cells = CellUnion(kept, c_lo, plan["origin"], plan["cell_size"])
        plan["field"] = plan["material"] & cells
        whole_info = {"complete_cells": cells.n_cells,
                      "cells_volume": float(cells.n_cells * np.prod(plan["cell_size"]))}
        timings["cells_s"] = time.perf_counter() - t
    t = time.perf_counter()
    chk = None
    if on_scale:
        vertices, faces, inside_fraction, chk, scale_info = _polygonise_scaled(
            plan, scale, scheduler, stream, out.get("mesh"), force, chunk_bytes, est, stage("mesh"))
    else:
        res = polygonise(plan["field"].sample_grid, grid, caps=plan["closed"], chunk_bytes=chunk_bytes,
                         threads=threads, progress=stage("mesh"))
        vertices, faces, inside_fraction = res.vertices, res.faces, res.inside_fraction
    timings["polygonise_s"] = time.perf_counter() - t
    domain_volume = plan["domain_volume"]
    voxel_porosity = None
    body_info = plan.get("body_info") or {}
    if plan["body"] is not None and body_info.get("kind") == "mesh":
        # the body volume is exact from its mesh; the voxel estimate uses the grid box
        box_volume = float(np.prod(grid.box_max - grid.box_min))
        if plan["closed"]:
            voxel_porosity = 1.0 - inside_fraction * box_volume / domain_volume
    elif plan["body"] is not None:
        t = time.perf_counter()
        body_res = polygonise(plan["body"].sample_grid, grid, caps=True, chunk_bytes=CHUNK_BYTES,
                              threads=threads, progress=stage("body"))
        from .mesh.validate import signed_volume
        domain_volume = float(signed_volume(body_res.vertices, body_res.faces))
        if plan["closed"] and body_res.inside_fraction > 0:
            voxel_porosity = 1.0 - inside_fraction / body_res.inside_fraction
        timings["body_s"] = time.perf_counter() - t
    elif plan["closed"]:
        voxel_porosity = 1.0 - inside_fraction
    if stream:
        from .scale.build import streamed_mesh_report
        t = time.perf_counter()
        report = streamed_mesh_report(chk, domain_volume, solid=plan["closed"])
    else:
        if len(faces) == 0:
            raise MeshError("the structure is empty on this grid: nothing to write")
        t = time.perf_counter()
        vertices, faces = _post_process(vertices, faces, dict(recipe.get("post", {})), grid,
                                        boxed=plan["body"] is None)
        timings["post_s"] = time.perf_counter() - t
        t = time.perf_counter()
        report, chk = validated_report(vertices, faces, domain_volume, check_intersections,
                                       solid=plan["closed"])
    if plan["closed"]:
        report["porosity_voxel"] = voxel_porosity
        if (voxel_porosity is not None and report.get("porosity") is not None
                and abs(voxel_porosity - report["porosity"]) > 0.02):
            report.setdefault("warnings", []).append(
                f"the voxel is coarse for this structure's walls: porosity {report['porosity']:.3f} by mesh "
                f"volume but {voxel_porosity:.3f} by samples; use a smaller voxel (or larger cells)")
    else:
        report.pop("porosity", None)
        report["printable"] = False
    timings["validate_s"] = time.perf_counter() - t
    tinfo = plan["threshold_info"]
    if plan["closed"] and "threshold" in tinfo and plan["body"] is None:
        report["porosity_calibrated"] = porosity_of_threshold(plan["type"], plan["structure"],
                                                              tinfo["threshold"])
    report.update({
        "type": plan["type"], "structure": plan["structure"],
        "cell_size": plan["cell_size"].tolist(), **tinfo,
        "grid": {"shape": list(grid.shape), "spacing": list(grid.spacing), "origin": list(grid.origin)},
        "estimate": est, "porecad_version": __version__,
    })
    if plan["body"] is not None:
        report["body_volume"] = domain_volume
    if body_info.get("kind") == "mesh":
        report["boundary"] = plan["boundary"]
        load_report = body_info["load_report"]
        report["body"] = {k: load_report[k] for k in ("triangles", "repairs", "self_intersections")}
        if "image" in load_report:
            report["body"]["image"] = load_report["image"]
        if plan["boundary"] == "skin":
            report["skin"] = body_info["skin"]
    if whole_info is not None:
        report.update(whole_info)
        if plan["closed"] and report.get("volume"):
            report["porosity_cells"] = 1.0 - report["volume"] / whole_info["cells_volume"]
    regions = _regions_wanted(recipe, plan)
    if regions:
        from .analysis.regions import region_porosity
        t = time.perf_counter()
        report["regions"] = region_porosity(plan, n_shells=regions[0], n_slabs=regions[0], axis=regions[1])
        timings["regions_s"] = time.perf_counter() - t
    if on_scale:
        report["scale"] = scale_info
    if out.get("mesh"):
        if not stream:  # a streamed mesh is already written
            t = time.perf_counter()
            write_mesh(out["mesh"], vertices, faces, force=force)
            timings["write_s"] = time.perf_counter() - t
        report["mesh_file"] = str(out["mesh"])
    if out.get("recipe"):
        rec = {k: v for k, v in recipe.items()}
        save_recipe(rec, out["recipe"], force=force)
        report["recipe_file"] = str(out["recipe"])
    timings["total_s"] = time.perf_counter() - t0
    report["timings"] = timings
    if out.get("report"):
        # analytic curvature where the mesh is the field's level set: box jobs, unsmoothed
        post = dict(recipe.get("post", {}))
        exact = plan["body"] is None and str(post.get("smooth", "none")) == "none" and not post.get("decimate")
        write_report_output(out["report"], report, vertices, faces, domain_volume=domain_volume, force=force,
                            field=plan["field"] if exact else None)
    return report


def _regions_wanted(recipe: dict, plan: dict):
    """(count, axis) of the per-region report, or None.

    ``[analysis] regions = N`` (shells and slabs; 0 = none), ``region_axis``;
    default: 5 for graded body jobs, none otherwise.
    """
    analysis = dict(recipe.get("analysis", {}))
    graded = "grading" in plan["threshold_info"] or "cell_size_grading" in plan["threshold_info"]
    n = analysis.get("regions", 5 if graded else 0)
    if isinstance(n, bool) or not float(n).is_integer() or not 0 <= int(n) <= 100:
        raise InputError(f"analysis.regions must be an integer 0-100, got {n!r}")
    if int(n) == 0 or plan["body"] is None or not plan["closed"]:
        return None
    axis = analysis.get("region_axis")
    if axis is not None:
        if str(axis).lower() not in ("x", "y", "z"):
            raise InputError(f"analysis.region_axis must be x, y or z, got {axis!r}")
        axis = "xyz".index(str(axis).lower())
    return int(n), axis


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def demo_recipe(out_dir) -> dict:
    """The main job: a graded gyroid sheet in the bundled analytic lumbar disc.

    Porosity grows from 0.60 at the rim (annulus: stiffer) to 0.80 in the
    centre (nucleus: more open), set through the gyroid-sheet calibration.
    """
    d = Path(out_dir)
    return {
        "job": "tpms",
        "tpms": {"type": "G", "structure": "sheet", "cell_size": 4.0},
        "domain": {"kind": "disc", "a": 22.5, "b": 16.0, "height": 10.0},
        "grading": {"kind": "radial", "of": "porosity", "axes": "xy", "centre": [0.0, 0.0, 0.0],
                    "r0": 4.0, "r1": 20.0, "from": 0.80, "to": 0.60},
        "sampling": {"voxel": 0.2},
        "post": {"smooth": "none"},
        "output": {"mesh": str(d / "disc_scaffold.stl"), "report": str(d / "disc_scaffold.report.json"),
                   "recipe": str(d / "disc_scaffold.recipe.toml")},
    }
