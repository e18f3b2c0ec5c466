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
from ..errors import InputError, MeshError, ResourceError
from ..findings import Finding
from ..io.mesh_formats import mesh_suffixes
from .contract import Job, Result, RunOptions, Timer, Validation, stage_progress
from ..lattice.plan import LatticePlan, hold_porosity, plan_lattice, post_process, refine_porosity
from ..lattice.spec import Scale
from .tpms_spec import GRADING_KINDS, InfillSpec, TpmsSpec  # noqa: F401 - the jobs' specs, and their names here

CHUNK_BYTES = 16 << 20
#: the thinnest chunk a streamed job shrinks its slabs to while they do not fit the memory
MIN_CHUNK_BYTES = 1 << 20
#: the most meshes of a calibrated body job (the first, then corrections of its porosity: lattice.plan.refine_porosity)
MESH_PASSES = 3


def stream_blockers(spec: TpmsSpec, out: dict, check_intersections: bool) -> list[str]:
    """Why this job cannot stream its mesh (empty list: it can)."""
    from ..analysis.report import is_report_dir
    why = []
    if spec.post.smooth != "none" and spec.post.smooth_iterations > 0:
        why.append("smoothing")
    if spec.post.decimate > 0:
        why.append("decimation")
    if check_intersections:
        why.append("the self-intersection check")
    if out.get("mesh") and Path(str(out["mesh"])).suffix.lower() not in mesh_suffixes("stream"):
        why.append(f"{Path(str(out['mesh'])).suffix or 'this'} output (stream {mesh_suffixes('stream', ' or ')})")
    if out.get("report") and is_report_dir(out["report"]):
        why.append("a report directory (use a .json report)")
    return why


def polygonise_scaled(plan, scale, scheduler, stream, mesh_path, force, chunk_bytes, est, progress,
                      islands: str = "drop"):
    """The main polygonisation on a scheduler (:mod:`porecad.scale`), in memory or streamed.

    Returns ``(vertices, faces, inside_fraction, check, scale_info)``;
    vertices and faces are None when streamed (the mesh is then already
    written and ``check`` is the streamed check). The zarr store, if asked
    for, is published only when the run succeeded. A streamed infill drops its ``islands`` as the
    promise check does in memory (:mod:`porecad.jobs.promise`), a lattice with no body keeps them (its pieces
    are cut off by the domain's faces and go on in the next cells).
    """
    from ..mesh.polygonise import slab_job
    from ..scale.build import collect_mesh, stream_mesh
    from ..scale.memwatch import PeakMemory
    grid = plan.grid
    job = slab_job(plan.field.sample_grid, grid, caps=plan.closed, chunk_bytes=chunk_bytes)
    store = None
    if scale.zarr:
        from ..io.zarr_field import create_store
        store = create_store(scale.zarr, grid, job.planes, force=force)
        job = dataclasses.replace(job, zarr_path=store)
    vertices = faces = chk = None
    try:
        with PeakMemory() as mem, scheduler as sched:
            if stream:
                centre = (grid.box_min + grid.box_max) / 2
                from .promise import NETWORK_FRACTION
                drop = islands == "drop" and plan.body is not None
                chk, stats = stream_mesh(job, sched, mesh_path, force=force, solid=plan.closed,
                                         retries=scale.retries, progress=progress,
                                         expected_bytes=est["stl_bytes"], centre=centre,
                                         keep_fraction=NETWORK_FRACTION if drop else None)
            else:
                vertices, faces, stats = collect_mesh(job, sched, retries=scale.retries, progress=progress)
        if store is not None:
            from ..io.zarr_field import commit_store
            commit_store(store, scale.zarr, force=force)
            store = None
    finally:
        if store is not None:
            from ..io.zarr_field import discard_store
            discard_store(store)
    info = {k: v for k, v in stats.items() if k != "inside_fraction"}
    info.update({"stream": bool(stream), "peak_memory_bytes": mem.peak_bytes, "chunk_bytes": int(chunk_bytes)})
    if scale.zarr:
        info["zarr"] = scale.zarr
    return vertices, faces, stats["inside_fraction"], chk, info


def regions_wanted(spec: TpmsSpec, plan: LatticePlan, calibrating: bool = False):
    """(count, axis) of the per-region report, or None (default: 5 for graded body jobs, none otherwise).

    ``calibrating``: the regions a graded target is calibrated on (:func:`hold_porosity`): the report's,
    or 5 when the report has none.
    """
    graded = "grading" in plan.threshold_info or "cell_size_grading" in plan.threshold_info
    n = spec.analysis.regions
    n = (5 if graded else 0) if n is None else n
    axis = spec.analysis.region_axis
    axis = None if axis is None else "xyz".index(axis.lower())
    if calibrating:
        return (n or 5), axis
    if n == 0 or plan.body is None or not plan.closed:
        return None
    return n, axis


@dataclasses.dataclass
class _Setup:
    """What :func:`_setup` decided before any heavy work: the plan, its size, where and how it is meshed."""

    plan: LatticePlan
    est: dict
    stream: bool
    on_scale: bool
    scheduler: object
    chunk_bytes: int
    threads: int
    units: list  # the body's units warnings, added to a refusal that the wrong units likely caused
    scale: Scale  # the recipe's [scale] table


@dataclasses.dataclass
class _Mesh:
    """The polygonised solid: its arrays (None when streamed), the streamed check, porosity by samples."""

    vertices: np.ndarray | None
    faces: np.ndarray | None
    check: dict | None
    scale_info: dict | None
    domain_volume: float
    voxel_porosity: float | None
    contour: dict | None = None  # the last polygonise pass's CPU split (contour_figures)


def run(spec: TpmsSpec, progress=None, options: RunOptions | None = None) -> Result:
    """Build the lattice solid of ``spec`` (a streamed mesh is written to ``options.outputs["mesh"]``).

    The stages, each taking the plan (:func:`~porecad.lattice.plan.plan_lattice`) and returning
    what the next needs:

    1. :func:`_setup` — plan the lattice, estimate its size and refuse what will not fit, choose
       streaming and the scheduler → :class:`_Setup`;
    2. calibrate (:func:`~porecad.lattice.plan.hold_porosity`) — a body job's threshold field
       holds the asked porosity;
    3. :func:`_whole_cells` — a ``whole`` infill keeps only the cells inside the body → the cells' figures;
    4. :func:`_mesh` — polygonise (again, up to ``MESH_PASSES`` times, while a held porosity misses)
       → :class:`_Mesh`;
    5. :func:`_report` — post-process, validate, and the report's figures and findings → ``Result``.
    """
    options = options or RunOptions()
    timer = (options or RunOptions()).stages  # the runner's stage clock: it reports the timings
    s = _setup(spec, options, progress)
    plan = s.plan
    if plan.body is not None:
        n_regions, axis = regions_wanted(spec, plan, calibrating=True)
        with timer("calibrate"):
            hold_porosity(plan, n_regions, axis, allow=spec.tpms.allow_closed_pores,
                          progress=stage_progress(progress, "calibrate"))
    whole_info = _whole_cells(plan, timer, progress) if plan.cells_pending else None
    mesh = _mesh(s, options, timer, progress)
    return _report(spec, s, mesh, whole_info, options, timer)


def _setup(spec: TpmsSpec, options: RunOptions, progress) -> _Setup:
    """Plan the lattice; estimate memory, disk and output size and refuse what will not fit; stream or not."""
    from ..mesh.polygonise import default_threads
    from ..resources import (announce_size, estimate, estimate_streamed, memory_budget, require_disk, require_fits,
                             usable_bytes)

    out = options.outputs or {}
    scale = spec.scale
    if scale.zarr:
        from ..io.zarr_field import check_store_path
        check_store_path(scale.zarr, options.force)
    plan = plan_lattice(spec, progress=stage_progress(progress, "body surface"))
    grid = plan.grid
    threads = default_threads() if options.threads is None else options.threads
    chunk_bytes = CHUNK_BYTES if scale.chunk_mb is None else int(scale.chunk_mb * 2**20)
    apv, solid = lattice_area(plan)  # the domain's faces are cut through the solid only
    est = estimate(grid, plan.cell_size, plan.structure, plan.domain_volume, plan.domain_area * solid,
                   chunk_bytes, threads, apv)
    stream = scale.stream
    blockers = stream_blockers(spec, out, bool(options.check_intersections))
    if stream and blockers:
        raise InputError(f"streamed output is not possible with {', '.join(blockers)}")
    if stream and not out.get("mesh"):
        raise InputError("streamed output needs an output mesh file")
    if stream is None:  # automatic: stream when the whole mesh would not fit comfortably
        limit = memory_budget(options.memory_limit)
        stream = bool(out.get("mesh")) and not blockers and est["peak_bytes"] > 0.5 * limit
    sched_spec = scale.scheduler
    on_scale = stream or sched_spec.kind != "threads" or scale.zarr is not None
    scheduler = None
    if on_scale:
        from ..scale import open_scheduler
        scheduler = open_scheduler(sched_spec, threads)  # fails here (one line) without dask
        if stream:
            workers = sched_spec.workers or (threads if sched_spec.kind == "threads" else 1)
            streamed = lambda b: estimate_streamed(est, grid, b, workers, 2 * workers + 1,  # noqa: E731
                                                   processes=sched_spec.kind != "threads")
            while (scale.chunk_mb is None and chunk_bytes > MIN_CHUNK_BYTES
                   and streamed(chunk_bytes)["peak_bytes"] > usable_bytes(options.memory_limit)):
                chunk_bytes //= 2  # thinner slabs until the chunks in flight fit the memory
            est = streamed(chunk_bytes)
    units = [f.message for f in (plan.body_info or {}).get("findings", []) if getattr(f, "code", "") == "units"]
    try:
        require_fits(est, options.memory_limit)
        require_disk(est, out.get("mesh"))
        announce_size(est, scale.max_output)
    except ResourceError as exc:  # a body in the wrong units is the likely cause: say so
        raise ResourceError(str(exc) + "".join(f"; {u}" for u in units)) from None
    return _Setup(plan, est, bool(stream), bool(on_scale), scheduler, chunk_bytes, threads, units, scale)


def contour_figures(res) -> dict:
    """The CPU split of a polygonise pass (sampling the field; marching cubes and welding the slabs) and the
    triangles it made per CPU second of contouring."""
    st = res.stats
    contour_cpu = float(st.get("mesh_cpu_s", 0.0) + st.get("weld_cpu_s", 0.0))
    return {"sample_cpu_s": round(float(st.get("sample_cpu_s", 0.0)), 4), "contour_cpu_s": round(contour_cpu, 4),
            "triangles_per_contour_cpu_s": round(len(res.faces) / contour_cpu) if contour_cpu > 0 else None,
            "threads": st.get("threads")}


def lattice_area(plan) -> tuple[float | None, float]:
    """The lattice's area per volume (mm⁻¹) and solid fraction, for the size estimate: measured for a constant
    design in cells of one size; otherwise None (the upper bound) and 1."""
    c = plan.threshold_info.get("threshold")
    L = np.broadcast_to(np.asarray(plan.cell_size, float), (3,))
    if not isinstance(c, float) or plan.structure == "surface" or "cell_size_grading" in plan.threshold_info \
            or np.ptp(L) > 0:
        return None, 1.0
    from ..sampling_need import area_per_volume
    return (area_per_volume(plan.type, plan.structure, c) / float(L[0]),
            1.0 - float(porosity_of_threshold(plan.type, plan.structure, c)))


def _whole_cells(plan: LatticePlan, timer: Timer, progress) -> dict:
    """A ``whole`` infill: the field cut to the complete cells inside the body; their count and volume."""
    from ..bodies.cells import CellUnion, complete_cells
    grid = plan.grid
    with timer("cells"):
        margin = float(np.linalg.norm(grid.spacing))  # one sample diagonal
        kept, c_lo = complete_cells(plan.body.sample_grid, grid, plan.origin, plan.cell_size,
                                    margin, progress=stage_progress(progress, "cells"))
        if not kept.any():
            raise InputError("no complete cell fits inside the body; use smaller cells or boundary 'cut'")
        cells = CellUnion(kept, c_lo, plan.origin, plan.cell_size)
        plan.field = plan.material & cells
        plan.cells = cells  # the analysis domain of a whole infill
    return {"complete_cells": cells.n_cells, "cells_volume": float(cells.n_cells * np.prod(plan.cell_size))}


def _mesh(s: _Setup, options: RunOptions, timer: Timer, progress) -> _Mesh:
    """Polygonise the plan's field (re-run while a held porosity misses) and its porosity by samples."""
    from ..mesh.polygonise import polygonise
    from ..mesh.validate import signed_volume
    plan, grid = s.plan, s.plan.grid
    out = options.outputs or {}
    domain_volume = plan.domain_volume
    body_info = plan.body_info or {}
    body_res = None
    if plan.body is not None and body_info.get("kind") != "mesh":
        with timer("body"):  # an analytic body's volume: its own mesh on the job's grid
            body_res = polygonise(plan.body.sample_grid, grid, caps=True, chunk_bytes=CHUNK_BYTES,
                                  threads=s.threads, progress=stage_progress(progress, "body"))
            domain_volume = float(signed_volume(body_res.vertices, body_res.faces))
    passes = 0
    chk = scale_info = contour = None
    force = options.force
    mesh_stage = f"mesh ~{s.est['seconds']:.0f} s"  # the up-front estimate (resources.estimate)
    while True:
        with timer("polygonise"):
            if s.on_scale:
                vertices, faces, inside_fraction, chk, scale_info = polygonise_scaled(
                    plan, s.scale, s.scheduler, s.stream, out.get("mesh"), force,
                    s.chunk_bytes, s.est, stage_progress(progress, mesh_stage), options.islands)
            else:
                res = polygonise(plan.field.sample_grid, grid, caps=plan.closed, chunk_bytes=s.chunk_bytes,
                                 threads=s.threads, progress=stage_progress(progress, mesh_stage))
                vertices, faces, inside_fraction = res.vertices, res.faces, res.inside_fraction
                contour = contour_figures(res)
        passes += 1
        if plan.porosity_hold is None or passes >= MESH_PASSES or (not s.stream and not len(faces)):
            break
        meshed = chk["meshed_volume"] if s.stream else float(signed_volume(vertices, faces))
        if not refine_porosity(plan, 1.0 - meshed / domain_volume):
            break
        if s.stream:  # the file of the pass that missed goes; outside an output set it is in place: written over
            from ..io.atomic import withdraw
            force = force if withdraw(out["mesh"]) else True
    plan.porosity_hold = None
    voxel_porosity = None
    if plan.body is not None and body_info.get("kind") == "mesh":
        # the body volume is exact from its mesh; the voxel estimate uses the grid box
        box_volume = float(np.prod(grid.box_max - grid.box_min))
        if plan.closed:
            voxel_porosity = 1.0 - inside_fraction * box_volume / domain_volume
    elif body_res is not None:
        if plan.closed and body_res.inside_fraction > 0:
            voxel_porosity = 1.0 - inside_fraction / body_res.inside_fraction
    elif plan.closed:
        voxel_porosity = 1.0 - inside_fraction
    return _Mesh(vertices, faces, chk, scale_info, domain_volume, voxel_porosity, contour)


def _report(spec: TpmsSpec, s: _Setup, mesh: _Mesh, whole_info, options: RunOptions, timer: Timer) -> Result:
    """Post-process the mesh; the report's figures and findings; the ``Result`` (the runner checks the solid)."""
    plan, grid, est = s.plan, s.plan.grid, s.est
    domain_volume = mesh.domain_volume
    vertices, faces = mesh.vertices, mesh.faces
    body_info = plan.body_info or {}
    warnings = []
    validation = None
    if s.stream:  # checked as it was written
        from ..scale.build import streamed_mesh_report
        with timer("validate"):
            report = streamed_mesh_report(mesh.check, domain_volume, solid=plan.closed)
    else:
        if len(faces) == 0:
            raise MeshError("the structure is empty on this grid: nothing to write" + "".join(f"; {u}" for u in s.units))
        with timer("post"):
            vertices, faces, post_findings = post_process(vertices, faces, spec.post, grid, boxed=plan.body is None)
            warnings += post_findings
        report = {}
        validation = Validation(domain_volume=domain_volume, intersections=bool(options.check_intersections),
                                solid=plan.closed)
    tinfo = plan.threshold_info
    if plan.closed and "threshold" in tinfo and plan.body is None:
        report["porosity_calibrated"] = porosity_of_threshold(plan.type, plan.structure, tinfo["threshold"])
    report.update({
        "type": plan.type.name, "structure": plan.structure, "cell_size": plan.cell_size.tolist(), **tinfo,
        "grid": {"shape": list(grid.shape), "spacing": list(grid.spacing), "origin": list(grid.origin)},
        "estimate": est,
    })
    if plan.body is not None:
        report["body_volume"] = domain_volume
    if body_info.get("kind") == "mesh":
        report["boundary"] = plan.boundary
        load_report = body_info["load_report"]
        report["body"] = {k: load_report[k] for k in ("triangles", "repairs", "self_intersections")}
        warnings.extend(body_info.get("findings", []))
        if "image" in load_report:
            report["body"]["image"] = load_report["image"]
        if plan.boundary == "skin":
            report["skin"] = body_info["skin"]
    if whole_info is not None:
        report.update(whole_info)
    regions = regions_wanted(spec, plan)
    if regions:
        from ..analysis.regions import region_porosity
        with timer("regions"):
            report["regions"] = region_porosity(plan, n_shells=regions[0], n_slabs=regions[0], axis=regions[1])
    if s.on_scale:
        report["scale"] = mesh.scale_info
    if mesh.contour is not None:
        report["contour"] = mesh.contour
    report["warnings"] = warnings
    voxel_porosity = mesh.voxel_porosity  # derive keeps no reference to the mesh arrays (the runner holds them)

    def derive(report: dict) -> None:
        """The figures of the checked solid: porosity by samples against by volume, of the cells, on target."""
        report["domain_volume"] = domain_volume
        if not plan.closed:
            report.pop("porosity", None)
            report["printable"] = False
            return
        report["porosity_voxel"] = voxel_porosity
        if whole_info is not None and report.get("volume"):
            report["porosity_cells"] = 1.0 - report["volume"] / whole_info["cells_volume"]
        warnings.extend(_voxel_findings(plan, report) + _porosity_findings(plan, report, whole_info))

    # analytic curvature where the mesh is the field's level set: box jobs, unsmoothed
    exact = plan.body is None and spec.post.smooth == "none" and not spec.post.decimate
    from .lattice_domain import lattice_analysis_domain
    analysis_domain, analysis_volume = lattice_analysis_domain(plan, grid, whole_info, domain_volume)
    return Result(report, vertices, faces, domain_volume=analysis_volume, domain=analysis_domain,
                  skin=body_info.get("skin") if plan.boundary == "skin" else None,
                  field=plan.field if exact else None, mesh_written=bool(s.stream), body=plan.body,
                  validation=validation, derive=derive)


def _voxel_findings(plan: LatticePlan, report: dict) -> list:
    """``voxel-coarse`` where the solid's porosity by volume and by samples differ beyond the mesh's expected bias
    (taken out up front by :func:`~porecad.lattice.plan.hold_porosity`)."""
    voxel, mesh = report.get("porosity_voxel"), report.get("porosity")
    bias = float((plan.threshold_info.get("calibration") or {}).get("mesh_bias") or 0.0)
    if voxel is None or mesh is None or abs(mesh - voxel - bias) <= 0.02:
        return []
    return [Finding("voxel-coarse", f"the voxel is coarse for this structure's walls: porosity {mesh:.3f} by mesh "
                    f"volume but {voxel:.3f} by samples (a bias of {bias:.3f} expected); use a smaller voxel (or "
                    "larger cells)", {"porosity_mesh": mesh, "porosity_samples": voxel, "mesh_bias": bias})]


def _porosity_findings(plan: LatticePlan, report: dict, whole_info) -> list:
    """``porosity-limited`` where the calibration could not reach the target; ``porosity-off`` for a whole infill.

    A whole-cell infill's porosity is of its cells; any other is measured on the written solid by the
    promise check (:mod:`porecad.jobs.promise`), which gives its own ``porosity-off``.
    """
    tinfo = plan.threshold_info
    limited = (tinfo.get("calibration") or {}).get("limited")
    asked = tinfo.get("target_porosity")
    if limited:
        return [Finding("porosity-limited", limited, {"asked": asked})]
    achieved = report.get("porosity_cells") if whole_info is not None else None
    if plan.body is None or asked is None or achieved is None or abs(achieved - asked) <= 0.01:
        return []
    return [Finding("porosity-off", f"porosity {achieved:.3f} misses the {asked:g} asked for by more than 0.01 "
                    "(the voxel is coarse for the walls, or the body too thin for its cells); use a smaller voxel",
                    {"asked": asked, "achieved": achieved, "error": achieved - asked})]

def plan_tpms(recipe: dict) -> LatticePlan:
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
