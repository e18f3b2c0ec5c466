"""The lattice jobs: ``tpms`` (a TPMS solid in a box of cells) and ``infill`` (a body filled with one).

The one pipeline: recipe → field → solid → chunked polygonise → post → validate.

Recipe::

    job = "tpms" | "infill"
    [tpms]     type = "G", structure = "sheet", porosity = 0.6 | threshold = 0.4, cell_size = 1.0
               (or [x, y, z], or {kind = "linear", axis = "z", from = 2, to = 4}: a ramp, bodies only),
               origin = [0, 0, 0], allow_closed_pores = false
    [domain]   kind = "box", cells = [2, 2, 2], origin = [0, 0, 0]
               | kind = "disc" (analytic lumbar disc: a, b, height, notch, notch_depth, rim)
               | kind = "mesh", path = "body.stl", boundary = "cut" | "skin" | "whole", skin = 1.0,
                 label = 2 | threshold = 300 (image bodies), keep_all = false
    [grading]  optional threshold or porosity field (porecad.grading): kind = "linear" | "radial" |
               "expression" | "distance" | "points" | "image" | "constant", of = "threshold" | "porosity"
    [sampling] resolution = 40 (samples per cell edge, both ends included) | voxel = 0.1 (mm)
    [post]     smooth = "none" | "laplacian" | "taubin", smooth_iterations = 10, decimate = 0.0
    [analysis] regions = 5, region_axis = "z"   (per-region porosity of graded body jobs)
    [scale]    scheduler = "threads" | "local:N" | "tcp://HOST:PORT", stream = true, zarr = "f.zarr",
               retries = 2, chunk_mb = 64   (porecad.scale, docs/scale-out.md)
    [output]   mesh = "out.stl", report = "out.json", report_dir = "out_report/", recipe = "out.toml"
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..calibration import porosity_of_threshold
from ..errors import InputError, MeshError, RecipeError, ResourceError
from ..findings import Finding
from .contract import Job, Result, RunOptions, Timer, stage_progress
from .lattice_plan import hold_porosity, plan_lattice, post_process, refine_porosity
from .outputs import validated_report

CHUNK_BYTES = 16 << 20
#: the most meshes of a calibrated body job (the first, then corrections of its porosity: lattice_plan.refine_porosity)
MESH_PASSES = 3
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


# ---------------------------------------------------------------------------------------------------------------


def stream_blockers(spec: TpmsSpec, out: dict, check_intersections: bool) -> list[str]:
    """Why this job cannot stream its mesh (empty list: it can)."""
    from ..analysis.report import is_report_dir
    why = []
    if spec.post["smooth"] != "none" and spec.post["smooth_iterations"] > 0:
        why.append("smoothing")
    if spec.post["decimate"] > 0:
        why.append("decimation")
    if check_intersections:
        why.append("the self-intersection check")
    if out.get("mesh") and Path(str(out["mesh"])).suffix.lower() not in (".stl", ".ply"):
        why.append(f"{Path(str(out['mesh'])).suffix or 'this'} output (stream .stl or .ply)")
    if out.get("report") and is_report_dir(out["report"]):
        why.append("a report directory (use a .json report)")
    return why


def polygonise_scaled(plan, scale, scheduler, stream, mesh_path, force, chunk_bytes, est, progress):
    """The main polygonisation on a scheduler (:mod:`porecad.scale`), in memory or streamed.

    Returns ``(vertices, faces, inside_fraction, check, scale_info)``;
    vertices and faces are None when streamed (the mesh is then already
    written and ``check`` is the streamed check). The zarr store, if asked
    for, is published only when the run succeeded.
    """
    from ..mesh.polygonise import slab_job
    from ..scale.build import collect_mesh, stream_mesh
    from ..scale.memwatch import PeakMemory
    grid = plan["grid"]
    job = slab_job(plan["field"].sample_grid, grid, caps=plan["closed"], chunk_bytes=chunk_bytes)
    store = None
    if scale["zarr"]:
        from ..io.zarr_field import create_store
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
            from ..io.zarr_field import commit_store
            commit_store(store, scale["zarr"], force=force)
            store = None
    finally:
        if store is not None:
            from ..io.zarr_field import discard_store
            discard_store(store)
    info = {k: v for k, v in stats.items() if k != "inside_fraction"}
    info.update({"stream": bool(stream), "peak_memory_bytes": mem.peak_bytes, "chunk_bytes": int(chunk_bytes)})
    if scale["zarr"]:
        info["zarr"] = scale["zarr"]
    return vertices, faces, stats["inside_fraction"], chk, info


def regions_wanted(spec: TpmsSpec, plan: dict, calibrating: bool = False):
    """(count, axis) of the per-region report, or None (default: 5 for graded body jobs, none otherwise).

    ``calibrating``: the regions a graded target is calibrated on (:func:`hold_porosity`): the report's,
    or 5 when the report has none.
    """
    graded = "grading" in plan["threshold_info"] or "cell_size_grading" in plan["threshold_info"]
    n = spec.analysis["regions"]
    n = (5 if graded else 0) if n is None else n
    axis = spec.analysis["region_axis"]
    axis = None if axis is None else "xyz".index(axis.lower())
    if calibrating:
        return (n or 5), axis
    if n == 0 or plan["body"] is None or not plan["closed"]:
        return None
    return n, axis


def run(spec: TpmsSpec, progress=None, options: RunOptions | None = None) -> Result:
    """Build the lattice solid of ``spec`` (a streamed mesh is written to ``options.outputs["mesh"]``)."""
    from ..mesh.polygonise import default_threads, polygonise
    from ..resources import announce_size, estimate, estimate_streamed, memory_budget, require_disk, require_fits

    options = options or RunOptions()
    out = options.outputs or {}
    force = options.force
    timer = Timer()
    scale = spec.scale
    if scale["zarr"]:
        from ..io.zarr_field import check_store_path
        check_store_path(scale["zarr"], force)
    plan = plan_lattice(spec, progress=stage_progress(progress, "body surface"))
    grid = plan["grid"]
    threads = default_threads() if options.threads is None else options.threads
    chunk_bytes = CHUNK_BYTES if scale["chunk_mb"] is None else int(scale["chunk_mb"] * 2**20)
    est = estimate(grid, plan["cell_size"], plan["structure"], plan["domain_volume"], plan["domain_area"],
                   chunk_bytes, threads)
    check_intersections = bool(options.check_intersections)
    stream = scale["stream"]
    blockers = stream_blockers(spec, out, check_intersections)
    if stream and blockers:
        raise InputError(f"streamed output is not possible with {', '.join(blockers)}")
    if stream and not out.get("mesh"):
        raise InputError("streamed output needs an output mesh file")
    if stream is None:  # automatic: stream when the whole mesh would not fit comfortably
        limit = memory_budget(options.memory_limit)
        stream = bool(out.get("mesh")) and not blockers and est["peak_bytes"] > 0.5 * limit
    sched_spec = scale["scheduler"]
    on_scale = stream or sched_spec.kind != "threads" or scale["zarr"] is not None
    if on_scale:
        from ..scale import open_scheduler
        scheduler = open_scheduler(sched_spec, threads)  # fails here (one line) without dask
        if stream:
            workers = sched_spec.workers or (threads if sched_spec.kind == "threads" else 1)
            est = estimate_streamed(est, grid, chunk_bytes, workers, 2 * workers + 1,
                                    processes=sched_spec.kind != "threads")
    units = [f.message for f in (plan.get("body_info") or {}).get("findings", []) if getattr(f, "code", "") == "units"]
    try:
        require_fits(est, options.memory_limit)
        require_disk(est, out.get("mesh"))
        announce_size(est, scale.get("max_output"))
    except ResourceError as exc:  # a body in the wrong units is the likely cause: say so
        raise ResourceError(str(exc) + "".join(f"; {u}" for u in units)) from None
    if plan["body"] is not None:
        n_regions, axis = regions_wanted(spec, plan, calibrating=True)
        with timer("calibrate"):
            hold_porosity(plan, n_regions, axis, allow=spec.tpms["allow_closed_pores"],
                          progress=stage_progress(progress, "calibrate"))
    whole_info = None
    if plan["cells_pending"]:
        from ..bodies.cells import CellUnion, complete_cells
        with timer("cells"):
            margin = float(np.linalg.norm(grid.spacing))  # one sample diagonal
            kept, c_lo = complete_cells(plan["body"].sample_grid, grid, plan["origin"], plan["cell_size"],
                                        margin, progress=stage_progress(progress, "cells"))
            if not kept.any():
                raise InputError("no complete cell fits inside the body; use smaller cells or boundary 'cut'")
            cells = CellUnion(kept, c_lo, plan["origin"], plan["cell_size"])
            plan["field"] = plan["material"] & cells
            plan["cells"] = cells  # the analysis domain of a whole infill
        whole_info = {"complete_cells": cells.n_cells,
                      "cells_volume": float(cells.n_cells * np.prod(plan["cell_size"]))}
    chk = None
    domain_volume = plan["domain_volume"]
    voxel_porosity = None
    body_info = plan.get("body_info") or {}
    body_res = None
    if plan["body"] is not None and body_info.get("kind") != "mesh":
        from ..mesh.validate import signed_volume
        with timer("body"):  # an analytic body's volume: its own mesh on the job's grid
            body_res = polygonise(plan["body"].sample_grid, grid, caps=True, chunk_bytes=CHUNK_BYTES,
                                  threads=threads, progress=stage_progress(progress, "body"))
            domain_volume = float(signed_volume(body_res.vertices, body_res.faces))
    passes = 0
    mesh_stage = f"mesh ~{est['seconds']:.0f} s"  # the up-front estimate (resources.estimate)
    while True:
        with timer("polygonise"):
            if on_scale:
                vertices, faces, inside_fraction, chk, scale_info = polygonise_scaled(
                    plan, scale, scheduler, stream, out.get("mesh"), force, chunk_bytes, est,
                    stage_progress(progress, mesh_stage))
            else:
                res = polygonise(plan["field"].sample_grid, grid, caps=plan["closed"], chunk_bytes=chunk_bytes,
                                 threads=threads, progress=stage_progress(progress, mesh_stage))
                vertices, faces, inside_fraction = res.vertices, res.faces, res.inside_fraction
        passes += 1
        if stream or "porosity_hold" not in plan or not len(faces) or passes >= MESH_PASSES:
            break
        from ..mesh.validate import signed_volume
        if not refine_porosity(plan, 1.0 - float(signed_volume(vertices, faces)) / domain_volume):
            break
    plan.pop("porosity_hold", None)
    if plan["body"] is not None and body_info.get("kind") == "mesh":
        # the body volume is exact from its mesh; the voxel estimate uses the grid box
        box_volume = float(np.prod(grid.box_max - grid.box_min))
        if plan["closed"]:
            voxel_porosity = 1.0 - inside_fraction * box_volume / domain_volume
    elif body_res is not None:
        if plan["closed"] and body_res.inside_fraction > 0:
            voxel_porosity = 1.0 - inside_fraction / body_res.inside_fraction
    elif plan["closed"]:
        voxel_porosity = 1.0 - inside_fraction
    warnings = []
    if stream:
        from ..scale.build import streamed_mesh_report
        with timer("validate"):
            report = streamed_mesh_report(chk, domain_volume, solid=plan["closed"])
    else:
        if len(faces) == 0:
            raise MeshError("the structure is empty on this grid: nothing to write" + "".join(f"; {u}" for u in units))
        with timer("post"):
            vertices, faces = post_process(vertices, faces, spec.post, grid, boxed=plan["body"] is None)
        with timer("validate"):
            report, chk, vertices = validated_report(vertices, faces, domain_volume, check_intersections,
                                           solid=plan["closed"])
    if plan["closed"]:
        report["porosity_voxel"] = voxel_porosity
        if (voxel_porosity is not None and report.get("porosity") is not None
                and abs(voxel_porosity - report["porosity"]) > 0.02):
            warnings.append(Finding(
                "voxel-coarse", f"the voxel is coarse for this structure's walls: porosity {report['porosity']:.3f} "
                f"by mesh volume but {voxel_porosity:.3f} by samples; use a smaller voxel (or larger cells)",
                {"porosity_mesh": report["porosity"], "porosity_samples": voxel_porosity}))
    else:
        report.pop("porosity", None)
        report["printable"] = False
    tinfo = plan["threshold_info"]
    if plan["closed"] and "threshold" in tinfo and plan["body"] is None:
        report["porosity_calibrated"] = porosity_of_threshold(plan["type"], plan["structure"], tinfo["threshold"])
    report.update({
        "type": plan["type"], "structure": plan["structure"], "cell_size": plan["cell_size"].tolist(), **tinfo,
        "grid": {"shape": list(grid.shape), "spacing": list(grid.spacing), "origin": list(grid.origin)},
        "estimate": est,
    })
    if plan["body"] is not None:
        report["body_volume"] = domain_volume
    if body_info.get("kind") == "mesh":
        report["boundary"] = plan["boundary"]
        load_report = body_info["load_report"]
        report["body"] = {k: load_report[k] for k in ("triangles", "repairs", "self_intersections")}
        warnings.extend(body_info.get("findings", []))
        if "image" in load_report:
            report["body"]["image"] = load_report["image"]
        if plan["boundary"] == "skin":
            report["skin"] = body_info["skin"]
    if whole_info is not None:
        report.update(whole_info)
        if plan["closed"] and report.get("volume"):
            report["porosity_cells"] = 1.0 - report["volume"] / whole_info["cells_volume"]
    limited = (tinfo.get("calibration") or {}).get("limited")
    asked = tinfo.get("target_porosity")
    if limited:
        warnings.append(Finding("porosity-limited", limited, {"asked": asked}))
    # a whole-cell infill's porosity is of its cells; any other is measured on the written solid by the
    # promise check (porecad.jobs.promise), which gives its own porosity-off
    achieved = report.get("porosity_cells") if whole_info is not None else None
    if (plan["body"] is not None and asked is not None and achieved is not None and not limited
            and abs(achieved - asked) > 0.01):
        warnings.append(Finding(
            "porosity-off", f"porosity {achieved:.3f} misses the {asked:g} asked for by more than 0.01 (the voxel "
            "is coarse for the walls, or the body too thin for its cells); use a smaller voxel",
            {"asked": asked, "achieved": achieved, "error": achieved - asked}))
    regions = regions_wanted(spec, plan)
    if regions:
        from ..analysis.regions import region_porosity
        with timer("regions"):
            report["regions"] = region_porosity(plan, n_shells=regions[0], n_slabs=regions[0], axis=regions[1])
    if on_scale:
        report["scale"] = scale_info
    report["domain_volume"] = domain_volume
    report["warnings"] = warnings
    report["timings"] = timer.total()
    # analytic curvature where the mesh is the field's level set: box jobs, unsmoothed
    exact = plan["body"] is None and spec.post["smooth"] == "none" and not spec.post["decimate"]
    from .lattice_domain import lattice_analysis_domain
    analysis_domain, analysis_volume = lattice_analysis_domain(plan, grid, whole_info, domain_volume)
    return Result(report, vertices, faces, domain_volume=analysis_volume, domain=analysis_domain,
                  skin=body_info.get("skin") if plan["boundary"] == "skin" else None,
                  field=plan["field"] if exact else None, mesh_written=bool(stream),
                  check=None if stream else chk, body=plan["body"])


def plan_tpms(recipe: dict) -> dict:
    """The plan of a lattice recipe (checked; no heavy work beyond loading a body)."""
    from .runner import parse
    _, spec, _, _ = parse(recipe)
    return plan_lattice(spec)


def demo_recipe(out_dir) -> dict:
    """The main job: a graded gyroid sheet in the bundled analytic lumbar disc.

    Porosity grows from 0.60 at the rim (annulus: stiffer) to 0.80 in the
    centre (nucleus: more open), set through the gyroid-sheet calibration.
    Writes the STL, the JSON report, the recipe and the report folder
    ``demo_report/`` (``report.html``: analysis, plots, 3D view).
    """
    d = Path(out_dir)
    return {
        "job": "infill",
        "tpms": {"type": "G", "structure": "sheet", "cell_size": 5.0},
        "domain": {"kind": "disc", "a": 22.5, "b": 16.0, "height": 10.0},
        "grading": {"kind": "radial", "of": "porosity", "axes": "xy", "centre": [0.0, 0.0, 0.0],
                    "r0": 4.0, "r1": 20.0, "from": 0.80, "to": 0.60},
        "sampling": {"voxel": 0.25},
        "post": {"smooth": "none"},
        "output": {"mesh": str(d / "disc_scaffold.stl"), "report": str(d / "disc_scaffold.report.json"),
                   "report_dir": str(d / "demo_report"), "recipe": str(d / "disc_scaffold.recipe.toml")},
    }


#: output keys: ``report`` a JSON file (or a folder), ``report_dir`` the HTML report folder beside it
_OUTPUTS = ("mesh", "report", "report_dir", "recipe")
_SUMMARY = ("type", "structure", "threshold", "porosity_min", "porosity_max", "specific_surface")
JOBS = {
    "tpms": Job("tpms", TpmsSpec, run, outputs=_OUTPUTS, summary=_SUMMARY,
                title="a TPMS pore, rod or sheet solid in a box of cells"),
    "infill": Job("infill", InfillSpec, run, outputs=_OUTPUTS, summary=_SUMMARY + ("boundary", "body_volume"),
                  title="a body (mesh, image or analytic disc) filled with a graded TPMS scaffold"),
}
