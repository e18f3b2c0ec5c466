"""Planning a lattice job (``tpms`` / ``infill``): the fields, grid, body and threshold of a checked spec.

A plan (:class:`LatticePlan`) is everything the polygoniser needs (the solid field and its
sampling grid) plus the facts the report needs (domain volume and area,
the threshold or grading, the body). No heavy work happens here beyond
loading a body.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..calibration import (check_porosity, check_threshold, checked_range, constant_threshold, threshold_for_porosity,
                           valid_range, within_range)
from ..errors import InputError, RangeError
from ..fields.base import Field
from ..fields.sdf import LumbarDisc
from ..fields.tpms import TPMSField, TPMSType
from ..grading import Grading, PorosityToThreshold, field_from_spec
from ..mesh.polygonise import Grid
from ..solids import StructureField
from .spec import CellRamp, Domain, Lattice, Post

if TYPE_CHECKING:
    from ..bodies.cells import CellUnion
    from ..grading import GradingContext


def graded_cell(ramp: CellRamp, box_min, box_max):
    """A cell-size ramp -> (GradedCellTPMS kwargs, smallest cell); its start, end and centre default to the box's."""
    a = "xyz".index(ramp.axis)
    L0, L1 = float(ramp.L0), float(ramp.L1)
    start = float(box_min[a] if ramp.start is None else ramp.start)
    end = float(box_max[a] if ramp.end is None else ramp.end)
    centre = ramp.centre if ramp.centre is not None else ((np.asarray(box_min) + np.asarray(box_max)) / 2).tolist()
    return {"L0": L0, "L1": L1, "axis": ramp.axis, "start": start, "end": end, "centre": centre}, min(L0, L1)


#: default voxel of a mesh body: this many samples per cell edge ...
SAMPLES_PER_CELL = 20
#: ... and across the body's smallest extent, but never finer than that extent / 200 ...
SAMPLES_ACROSS, FINEST_ACROSS = 50, 200
#: ... unless the design needs more samples per cell (a graded design: this many)
GRADED_SAMPLES_PER_CELL = 10


def default_voxel(extent, cell: float, need: int | None = None) -> float:
    """The default sample spacing of a mesh body: ``min(L / 20, e / 50)``, at least ``e / 200``, and at most
    ``L / need``.

    ``e`` is the body's smallest extent and ``L`` the (smallest) cell: 20
    samples per cell edge resolve the lattice's walls (the porosity is
    calibrated on the body and its mesh bias taken out,
    :func:`hold_porosity`), 50 across the body its shape; a thin body with
    small cells (a disc 9 mm high in cells of 2 mm) no longer gets the
    200 samples across that made its grid and mesh 10 times larger. A large
    body stops at ``e / 200`` only while that keeps the ``need`` samples per
    cell its design needs (:func:`porecad.sampling_need.samples_per_cell`):
    the sampling follows the design, never the body's size alone.
    """
    e, L = float(np.min(extent)), float(cell)
    h = max(min(L / SAMPLES_PER_CELL, e / SAMPLES_ACROSS), e / FINEST_ACROSS)
    return min(h, L / need) if need else h


def sampling_need(tp: Lattice, grading) -> tuple[int, dict]:
    """The samples per cell edge a lattice's design needs (:mod:`porecad.sampling_need`).

    A constant threshold or porosity is measured; a graded one, whose
    thresholds are known only on the grid, takes :data:`GRADED_SAMPLES_PER_CELL`.
    """
    from ..errors import PorecadError
    from ..sampling_need import samples_per_cell
    if tp.structure == "surface":
        return 0, {"rule": "surface"}
    if grading:
        return GRADED_SAMPLES_PER_CELL, {"rule": "graded", "samples_per_cell": GRADED_SAMPLES_PER_CELL}
    try:
        c, _ = constant_threshold(tp.type, tp.structure, tp.threshold, tp.porosity, True)
    except PorecadError:
        return 0, {"rule": "none"}  # the design itself is refused further on, in its own words
    n, info = samples_per_cell(tp.type, tp.structure, c)
    return n, {"rule": "measured", **info}


def body_field(domain: Domain, h: float | None, cell: float | None = None, progress=None, need=None):
    """The body field of a non-box domain, its bounds and facts about it.

    ``h`` is the sample spacing; None for a mesh body means
    :func:`default_voxel` of its extent, ``cell`` (the smallest cell;
    without one, its smallest extent / 200) and ``need`` (``(samples per cell,
    info)`` of :func:`sampling_need`), returned as ``voxel`` (and ``sampling``) in the facts.
    """
    kind = domain.kind
    if kind == "disc":
        body = LumbarDisc(**{k: v for k in ("a", "b", "height", "notch", "notch_depth", "rim")
                             if (v := getattr(domain, k)) is not None})
        lo, hi = body.bounds
        return body, lo, hi, {"kind": "disc"}
    if kind == "mesh":
        from ..bodies import MeshBody, load_body
        skin = float(domain.skin) if domain.boundary == "skin" else 0.0
        image_opts = {key: getattr(domain, key) for key in ("label", "threshold") if getattr(domain, key) is not None}
        from ..bodies.units import unit_scale
        v, f, report = load_body(domain.path, keep_all=bool(domain.keep_all), progress=progress,
                                 scale=unit_scale(domain.units or "mm"), **image_opts)
        ext = np.asarray(report["bounds"][1]) - np.asarray(report["bounds"][0])
        findings = body_findings(report, ext, cell, domain.units or "mm")
        sampling = None
        if h is None:
            n_need, sampling = need or (0, None)
            h = default_voxel(ext, cell, n_need) if cell is not None else float(ext.min()) / FINEST_ACROSS
            samples = float(np.prod(ext / max(h, 1e-300) + 1))
            if not samples <= MAX_DEFAULT_SAMPLES:  # a thin, long body: the default voxel would take hours
                from ..errors import RecipeError
                why = f", {n_need} samples per cell as its design needs," if n_need and h < cell / SAMPLES_PER_CELL else ""
                raise RecipeError("sampling.voxel", f"the default voxel ({h:.3g} mm{why}) "
                                                    f"gives {samples:.3g} samples (at most {MAX_DEFAULT_SAMPLES:.3g} "
                                                    "by default); give a voxel")
        units = "".join(f"; {x.message}" for x in findings if x.code == "units")
        if skin >= 0.5 * float(ext.min()):  # a body in the wrong units fails here or below first: say so
            raise InputError(f"skin thickness {skin:g} mm fills the body (smallest extent {ext.min():.3g} mm){units}")
        try:
            body = MeshBody(v, f, band=skin + 2.0 * h)
        except InputError as exc:
            raise InputError(str(exc) + units) from None
        lo, hi = body.bounds
        return body, lo, hi, {"kind": "mesh", "volume": report["volume"], "skin": skin,
                              "load_report": report, "voxel": h, "findings": findings,
                              **({"sampling": sampling} if sampling else {})}
    raise InputError(f"unknown domain kind {kind!r}; use 'box', 'disc' or 'mesh'")


#: most samples the default voxel of a body may give (larger jobs need an explicit voxel)
MAX_DEFAULT_SAMPLES = 1e9


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


def resolve_threshold(tp: Lattice, grading: Grading | None, context=None):
    """Threshold (number or field) and its description from the recipe's tpms/grading tables.

    ``tp.allow_closed_pores`` builds outside the valid range instead of
    refusing; the description then says ``"in_valid_range": False``.
    """
    allow = bool(tp.allow_closed_pores)
    if grading:  # never with a threshold or porosity: the spec refuses both (jobs.tpms_spec)
        field, of = field_from_spec(grading, context)
        return field, {"grading": grading.table(), "of": of, "allow_closed_pores": allow}
    return constant_threshold(tp.type, tp.structure, tp.threshold, tp.porosity, allow)


def check_graded(field, of, tpms_type, structure, grid, allow=False, body=None, skin=0.0):
    """Check a graded threshold/porosity field against the valid range on a coarse grid.

    With a ``body``, only inside it, deeper than ``skin`` (a solid skin holds no lattice).
    """
    xs = np.linspace(grid.box_min[0], grid.box_max[0], 33)
    ys = np.linspace(grid.box_min[1], grid.box_max[1], 33)
    zs = np.linspace(grid.box_min[2], grid.box_max[2], 33)
    vals = field.sample_grid(xs, ys, zs)
    if body is not None:
        inside = body.sample_grid(xs, ys, zs) < -float(skin)
        if inside.any():
            vals = vals[inside]
    lo, hi = float(vals.min()), float(vals.max())
    if of == "porosity":
        for p in (lo, hi):
            if not np.isfinite(p) or not 0 < p < 1:
                raise RangeError(f"porosity must lie strictly between 0 and 1, got {p:g}")
        ok = all([within_range(check_porosity, tpms_type, structure, p, allow) for p in (lo, hi)])
        return PorosityToThreshold(field, tpms_type, structure), {"porosity_min": lo, "porosity_max": hi,
                                                                  "in_valid_range": ok}
    ok = all([within_range(check_threshold, tpms_type, structure, c, allow) for c in (lo, hi)])
    return field, {"threshold_min": lo, "threshold_max": hi, "in_valid_range": ok}


@dataclass
class LatticePlan:
    """The plan of a lattice job (``tpms`` / ``infill``): what the polygoniser and the report need.

    Built by :func:`plan_lattice` from a checked spec. Later stages change it in place:

    * :func:`hold_porosity` (and :func:`refine_porosity`, :func:`replay_hold`, through the
      calibration they share) set ``porosity_hold`` and replace ``material`` and ``field``;
      they add ``threshold_cells`` and ``calibration`` to ``threshold_info`` and update its
      ``threshold`` / ``in_valid_range``;
    * a ``whole`` infill (:func:`porecad.jobs.tpms_job.run`) sets ``cells`` and cuts ``field`` to them;
    * the mesh passes of :func:`porecad.jobs.tpms_job.run` clear ``porosity_hold`` when done.

    The other fields are read only after planning.
    """

    type: TPMSType  # the TPMS type (its name, "G", "D", "P", ..., in the report)
    structure: str  # "pore", "rod", "sheet" or "surface"
    cell_size: np.ndarray  # cell edge per axis (mm); a cell-size ramp's smallest cell on all three
    grid: Grid  # the sampling grid the solid is polygonised on
    field: Field  # the solid: material cut to the body, wrapped in its skin, or cut to whole cells
    body: Field | None  # the body's signed distance (negative inside); None for a box of cells
    threshold_info: dict  # the threshold or grading and its calibration, copied into the report
    domain_volume: float  # the box's or the body's volume (mm³), before the body's own mesh refines it
    domain_area: float  # the surface area of the domain's bounding box (mm²)
    closed: bool  # a closed solid (every structure but "surface")
    boundary: str | None  # "cut", "skin" or "whole" for a body; None for a box
    body_info: dict | None  # facts about the body (kind, volume, skin, load report, voxel, findings); None for a box
    material: StructureField  # the lattice alone (TPMS and threshold), before the body
    origin: np.ndarray  # the lattice origin (mm)
    cells_pending: bool  # a "whole" infill: ``field`` is cut to the complete cells when the job runs
    context: GradingContext  # grading context: grid box, coarse caches, the body's depth
    porosity_hold: dict | None = None  # the calibration state of a held porosity (hold_porosity), while meshing
    cells: CellUnion | None = None  # the complete cells of a "whole" infill, once the job has found them


def plan_lattice(spec, progress=None) -> LatticePlan:
    """Build everything needed to run a checked lattice spec (:class:`porecad.jobs.tpms_job.TpmsSpec`).

    ``progress(done, total)``: while an image body's surface is extracted.
    """
    tp, domain, sampling = spec.tpms, spec.domain, spec.sampling
    ttype, structure, cell = tp.type, tp.structure, tp.cell_size
    h, res = sampling.voxel, sampling.resolution or 40
    body = None
    body_info = None
    graded_cell_spec = isinstance(cell, CellRamp)
    if graded_cell_spec:
        smallest = min(float(cell.L0), float(cell.L1))
    if domain.kind == "box":
        cells = np.asarray(domain.cells)
        lo = np.asarray(domain.origin, dtype=float)
        hi = lo + cells * cell
        if h is None:
            n = cells * (res - 1) + 1
        else:
            n = np.maximum(np.round((hi - lo) / h).astype(np.int64), 1) + 1
        grid = Grid.from_box(lo, hi, samples_per_axis=n)
        domain_volume = float(np.prod(hi - lo))
        ext = hi - lo
    else:
        if h is None and not (domain.kind == "mesh" and sampling.resolution is None):
            h = (smallest if graded_cell_spec else float(np.min(cell))) / (res - 1)
        need = sampling_need(tp, spec.grading or graded_cell_spec) if h is None else None
        body, blo, bhi, body_info = body_field(domain, h, smallest if graded_cell_spec else float(np.min(cell)),
                                               progress=progress, need=need)
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
        phi = TPMSField(ttype, cell, origin=tp.origin)
    context = grading_context(grid, cell, float(np.min(grid.spacing)), body, body_info)
    threshold, tinfo = resolve_threshold(tp, spec.grading, context)
    if not isinstance(threshold, float):
        threshold, extra = check_graded(threshold, tinfo["of"], ttype, structure, grid,
                                        allow=tinfo.pop("allow_closed_pores"), body=body)
        tinfo.update(extra)
    if cell_grading is not None:
        tinfo["cell_size_grading"] = cell_grading
    material = StructureField(phi, structure, threshold)
    boundary = (domain.boundary or "cut") if body is not None else None
    field = solid_field(material, body, boundary, body_info)
    return LatticePlan(type=ttype, structure=structure, cell_size=cell, grid=grid, field=field, body=body,
                       threshold_info=tinfo, domain_volume=domain_volume, domain_area=domain_area,
                       closed=structure != "surface", boundary=boundary, body_info=body_info, material=material,
                       origin=np.asarray(tp.origin, dtype=float),
                       cells_pending=boundary == "whole", context=context)


def solid_field(material, body, boundary, body_info):
    """The solid of a lattice job: the material, cut to the body or wrapped in its skin."""
    if body is None:
        return material
    if boundary == "cut":
        return material & body
    if boundary == "skin":
        # (material ∪ shell) ∩ body with shell = {-T <= d <= 0}: max(min(m, -d - T), d)
        return SkinSolid(material, body, body_info["skin"])
    return material  # whole: restricted to the complete cells when the job runs (needs a pass over the body)


#: a calibrated body job is meshed again when its mesh porosity misses the target by more than this
MESH_TOLERANCE = 0.004


def hold_porosity(plan: LatticePlan, n_regions: int = 5, axis: int | None = None, allow: bool = False, progress=None):
    """Calibrate a porosity target against the body's own samples (:mod:`porecad.bodies.body_porosity`).

    For ``cut`` and ``skin`` bodies with a porosity target (uniform, or a
    graded porosity field), replace the whole-cell threshold by one solved on
    samples inside the body, so that the body's porosity (void / body volume)
    is the one asked for, and per region (``n_regions`` depth shells and
    slabs along ``axis``) for graded targets. ``whole`` keeps complete cells,
    where the whole-cell curve is already exact. Updates ``plan`` in place
    (``material``, ``field``, ``threshold_info["calibration"]``) and keeps
    the samples for :func:`refine_porosity`.
    """
    from ..bodies import body_porosity as bp
    body, tinfo, material = plan.body, plan.threshold_info, plan.material
    if body is None or not plan.closed or plan.boundary not in ("cut", "skin"):
        return
    state = {"shift": 0.0, "allow": bool(allow)}
    if tinfo.get("target_porosity") is not None:
        samples = bp.BodySamples(plan, progress=progress)
        if samples.n_inside < bp.MIN_SAMPLES:
            return  # a body of a few voxels: the whole-cell curve is all there is
        state.update(kind="uniform", requested=float(tinfo["target_porosity"]), samples=samples)
        tinfo["threshold_cells"] = tinfo["threshold"]
    elif tinfo.get("of") == "porosity" and isinstance(material.threshold, PorosityToThreshold):
        requested = material.threshold.porosity
        depth = plan.context.depth()
        lo, hi = body.bounds
        if axis is None:
            axis = int(np.argmax(np.asarray(hi) - np.asarray(lo)))
        samples = bp.BodySamples(plan, requested=requested, slab_axis=axis, depth=depth, progress=progress)
        if samples.n_inside < bp.MIN_SAMPLES:
            return
        shell_edges = np.linspace(0.0, depth.max_depth, n_regions + 1)
        slab_edges = np.linspace(lo[axis], hi[axis], n_regions + 1)
        limits = None if allow else checked_range(plan.type, plan.structure, "porosity")
        sn, sv, bn, bv, info = bp.fit_graded(samples, plan.type, plan.structure, shell_edges, slab_edges,
                                             limits=limits)
        state.update(kind="graded", requested=float(np.mean(samples.porosity)), field=requested, depth=depth,
                     axis=axis, nodes=(sn, sv, bn, bv), samples=samples,
                     info={"regions": n_regions, "axis": "xyz"[axis], **info})
    else:
        return
    plan.porosity_hold = state
    _apply_hold(plan, state)


def refine_porosity(plan: LatticePlan, mesh_porosity: float, tolerance: float = MESH_TOLERANCE) -> bool:
    """After a mesh of a calibrated plan: shift the target by the mesh's miss and rebuild the solid.

    The mesh loses or gains volume against the samples where walls are
    thin for the voxel or the body has sharp edges; a step on the body's
    porosity (by mesh volume; 1:1 first, then the secant through the last
    two meshes) takes that out. Returns whether the plan changed (then mesh
    it again); the meshes' porosities are recorded in
    ``threshold_info["calibration"]["mesh_porosity_passes"]``.
    """
    state = plan.porosity_hold
    if state is None or not np.isfinite(mesh_porosity):
        return False
    miss = float(mesh_porosity) - state["requested"]
    cal = plan.threshold_info["calibration"]
    cal.setdefault("mesh_porosity_passes", []).append(float(mesh_porosity))
    if cal.get("limited"):
        return False  # the lattice is at the edge of its valid range: nothing left to move
    history = state.setdefault("history", [])
    history.append((state["shift"], miss))
    if abs(miss) <= tolerance:
        return False
    slope = 1.0
    if len(history) >= 2:  # secant through the last two meshes (thin walls respond faster than 1:1)
        (s0, m0), (s1, m1) = history[-2], history[-1]
        if s1 != s0 and 0.2 < (m1 - m0) / (s1 - s0) < 5.0:
            slope = (m1 - m0) / (s1 - s0)
    state["shift"] -= miss / slope
    _apply_hold(plan, state)
    return True


def replay_hold(plan: LatticePlan, shift: float, bias: float = 0.0) -> bool:
    """Rebuild a calibrated plan's solid with the given target ``shift`` and mesh ``bias`` (porosity).

    :mod:`porecad.printing` slices the exact field: no shift and no bias (both correct a mesh's discretisation).
    Returns whether the plan has a calibration to replay.
    """
    state = plan.porosity_hold
    if state is None:
        return False
    state["shift"], state["bias"] = float(shift), float(bias)
    _apply_hold(plan, state)
    return True


def _apply_hold(plan: LatticePlan, state: dict):
    """Solve the threshold (uniform) or build the corrected porosity field (graded) and rebuild the solid."""
    from ..bodies import body_porosity as bp
    from ..calibration import porosity_of_threshold
    tinfo, material = plan.threshold_info, plan.material
    ttype, structure, allow, samples = plan.type, plan.structure, state["allow"], state["samples"]
    p, shift = state["requested"], state["shift"]
    if "bias" not in state:  # the lattice's own mesh bias at the job's voxel (whole cells), taken out up front
        if isinstance(material.phi, TPMSField):
            c0 = (bp.fit_uniform(samples, p)[0] if state["kind"] == "uniform"
                  else threshold_for_porosity(ttype, structure, float(np.clip(p, 0.01, 0.99))))
            state["bias"] = bp.mesh_bias(ttype, structure, c0, plan.cell_size, float(np.min(plan.grid.spacing)))
        else:
            state["bias"] = 0.0
    shift = shift - state["bias"]
    if state["kind"] == "uniform":
        c, info = bp.fit_uniform(samples, float(np.clip(p + shift, 1e-4, 1 - 1e-4)))
        ok = within_range(check_threshold, ttype, structure, c, True)
        clamped = None
        if not ok and not allow:  # the most open (or dense) valid lattice: the nearest the body gets
            lo, hi = valid_range(ttype, structure)["threshold"]
            clamped = float(porosity_of_threshold(ttype, structure, c))
            c, ok = float(np.clip(c, lo, hi)), True
        lattice = float(porosity_of_threshold(ttype, structure, c))
        tinfo.update(threshold=c, in_valid_range=ok)
        cal = {"method": "body samples", "requested": p, "lattice_porosity": lattice,
               "sample_porosity": bp.achieved(samples, c), "samples": info["samples"],
               "core_fraction": info["core_fraction"], "sample_spacing": samples.spacing}
        if clamped is not None or not info["reachable"]:
            cal["limited"] = (f"the body's porosity {p:g} needs the lattice at porosity "
                              f"{clamped if info['reachable'] else 1.0:.3f}" + (
                                  f" (the skin holds {1 - info['core_fraction']:.0%} of the body)"
                                  if samples.skin > 0 else "")
                              + f", outside the valid range of {ttype.name} {structure}: built at {lattice:.3f}; use "
                              + ("a thinner skin, " if samples.skin > 0 else "")
                              + "another porosity or structure, or allow_closed_pores")
        threshold = c
    else:
        sn, sv, bn, bv = state["nodes"]
        if sv.size:
            sv = sv + shift
        else:
            bv = bv + shift
        limits = None if allow else checked_range(ttype, structure, "porosity")
        corrected = bp.CalibratedPorosity(state["field"], state["depth"], sn, sv, state["axis"], bn, bv,
                                          limits=limits)
        threshold, extra = check_graded(corrected, "porosity", ttype, structure, plan.grid, allow=True,
                                        body=plan.body, skin=samples.skin)
        tinfo["in_valid_range"] = bool(extra["in_valid_range"])
        cal = {"method": "body samples, per region", "requested": p, "samples": samples.n_inside,
               "sample_spacing": samples.spacing, "lattice_porosity_min": extra["porosity_min"],
               "lattice_porosity_max": extra["porosity_max"], "shell_correction": [float(x) for x in sv],
               "slab_correction": [float(x) for x in bv], **state["info"]}
        if limits is not None and bp.clipped_fraction(samples, corrected, state["axis"]) > 0.01:
            cal["limited"] = (f"the graded porosity needs the lattice outside the valid range "
                              f"[{limits[0]:.3f}, {limits[1]:.3f}] of {ttype.name} {structure} in places: built at its "
                              "edge there (see regions); use another porosity or structure, or allow_closed_pores")
    old = tinfo.get("calibration") or {}
    if "mesh_porosity_passes" in old:
        cal["mesh_porosity_passes"] = old["mesh_porosity_passes"]
    cal["mesh_bias"] = state["bias"]
    cal["mesh_shift"] = state["shift"]
    tinfo["calibration"] = cal
    plan.material = StructureField(material.phi, structure, threshold)
    plan.field = solid_field(plan.material, plan.body, plan.boundary, plan.body_info)


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


def post_process(vertices, faces, post: Post, grid, boxed: bool):
    """The ``[post]`` table: smoothing (stopped before it folds the solid) and decimation.

    Returns ``(vertices, faces, findings)``; a ``smoothing-stopped`` finding
    when fewer smoothing iterations were kept than asked for.
    """
    smooth, iters = post.smooth, int(post.smooth_iterations)
    findings = []
    if smooth != "none" and iters > 0:
        from ..findings import Finding
        from ..mesh.smooth import smooth_solid
        fixed = None
        if boxed:
            tol = 1e-9 * float(np.max(grid.box_max - grid.box_min))
            fixed = (np.any(np.abs(vertices - grid.box_min) <= tol, axis=1)
                     | np.any(np.abs(vertices - grid.box_max) <= tol, axis=1))
        vertices, done = smooth_solid(vertices, faces, smooth, iterations=iters, fixed=fixed)
        if done < iters:
            findings.append(Finding("smoothing-stopped", f"{smooth} smoothing stopped after {done} of the {iters} "
                                    "iterations asked for: the next would have folded the surface",
                                    {"asked": iters, "done": done}))
    tol = float(post.decimate or 0.0)
    if tol > 0:
        from ..mesh.decimate import decimate
        vertices, faces = decimate(vertices, faces, tol)
    return vertices, faces, findings




def body_findings(load_report: dict, extent, cell, units: str) -> list:
    """Warnings about a loaded body: every repair, and a size implausible for the cells (its units)."""
    from ..bodies.units import units_finding
    from ..findings import Finding
    out = []
    repairs = [r for r in load_report.get("repairs", []) if r != "no holes"]
    if repairs:
        holes = next((r for r in repairs if r.startswith("closed ")), None)
        n = int(holes.split()[1]) if holes else 0
        out.append(Finding("body-repaired", "the body mesh was repaired: " + "; ".join(repairs),
                           {"repairs": len(repairs), "holes_closed": n}))
    if cell is not None:
        f = units_finding(extent, float(np.min(cell)), units)
        if f is not None:
            out.append(f)
    return out
