"""The ``tbss`` job: a heterogeneous scaffold in a trivariate B-spline solid (document 001).

Recipe (TOML, ``job = "tbss"``)::

    [body]   kind = "disc" | "box" | "cylinder" | "tube" | "mesh"
             path = "femur.stl"          # kind = "mesh": fitted, fit = "auto" | "radial" | "sliced" | "hex"
             control = [8, 8, 8]         # TBSS control grid of a fitted body
             clip = true                 # mesh: fit a margin larger, cut the scaffold to the body
             margin = 2.0                # mm (default: radial fit a tenth of the body's mean thickness 3V/A, hex 0)
             skin = 1.0                  # mm: a clipped scaffold wrapped in a solid shell that thick (default 0)
    [tpms]   type = "G", structure = "sheet", periods = [4, 4, 4]
             cell_size = 10.0             # instead of periods: mm per cell along the solid's u, v, w lines
    [tdf]    method = "layer" | "fill" | "function"
             by = "w"   layers = 4        # layer method: u, v, w, sides, boundary
             quantity = "mean"            # fill method: mean or gaussian curvature
             expr = "0.5 + 0.5 * w"       # function method
             threshold_range = [lo, hi]   # or porosity_range; default: the valid range, inset 10 %
             grid = 100  control = 20  degree = 3
    [tdf]    file = "scaffold.tdf"        # instead: regenerate from a TDF file
             edits = [{where = "w > 0.8", threshold = 0.3}]   # local modifications (001 §3.2)
    [mesh]   resolution = 16              # samples per period edge
    [analysis] layers = true              # achieved porosity per layer
    [output] mesh = "out.stl", tdf = "out.tdf", report = "report.json", recipe = "out.toml"

Stages: TBSS (primitive or fit; Jacobian checked) → discrete TDF on the
parametric grid → linear map into the threshold range → LSPIA fit → volume
TPMS in the parameter cube → map through the TBSS → validate → write.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError, MeshError
from ..findings import Finding
from ..resources import mapped_estimate, require_fits, require_param_samples
from .contract import Job, Result, RunOptions, Validation, stage_progress
from ..maps.tbss_design import (TbssBody, TdfSpec, apply_edits, build_tbss, build_tdf, calibrate_in_body,
                          check_tdf_range, layer_porosity, uniform_porosity)

#: how often a mapped scaffold whose curved boundary band intersects itself is rebuilt finer (x 1.5 each)
MAX_REFINEMENTS = 2



@dataclasses.dataclass(frozen=True)
class TbssSpec:
    """A checked ``tbss`` recipe (see the module docstring for the keys)."""

    body: TbssBody | None
    type: str | None
    structure: str | None
    periods: tuple | None
    allow: bool
    tdf: TdfSpec
    resolution: int
    layers_report: bool
    cell_size: float | None = None

    @classmethod
    def from_recipe(cls, r):
        from ..fields.tpms import get_type
        from ..maps.tbss import check_periods
        from ..solids import check_structure
        t = r.table("tpms")
        allow = t.get("allow_closed_pores")
        d = r.table("tdf")
        m = r.table("mesh")
        resolution = m.get("resolution")
        m.done()
        a = r.table("analysis")
        layers_report = a.get("layers")
        a.done()
        pairs = []
        for e in d.get("edits"):
            # TPMS values are of order 1: a threshold beyond ±10 selects all or nothing (and 1e308 overflows the fit)
            pairs.append((e.get("where", check=_check_condition), e.get("threshold")))
            e.done()
        edits = {"edits": tuple(pairs), "edit_grid": d.get("edit_grid")} if pairs else {}
        if d.has("file"):
            tdf = TdfSpec(file=d.get("file"), **edits)
            d.done()
            t.done()
            if r.has("body"):
                raise r.error("body", "a TDF file holds its own body; give no [body] with tdf.file")
            return cls(None, None, None, None, allow, tdf, resolution, layers_report)
        ttype = t.get("type", check=lambda v: get_type(str(v)).name)
        structure = t.get("structure", check=check_structure)
        if structure == "surface":
            raise t.error("structure", "a TBSS scaffold needs a solid structure: pore, rod or sheet")
        cell_size = None
        if t.has("cell_size"):
            if t.has("periods"):
                raise t.error("cell_size", "give periods or a cell size, not both")
            cell_size = t.get("cell_size")
            periods = None
        else:
            periods = t.get("periods", check=check_periods)
            if float(np.max(periods)) > 1000:
                raise t.error("periods", f"at most 1000 periods per direction, got {tuple(periods)}")
            require_param_samples(periods, resolution, per="period")
        t.done()
        body = _body_table(r.table("body"))
        tdf = _tdf_table(d, periods, edits)
        return cls(body, ttype, structure, None if periods is None else tuple(int(p) for p in periods), allow, tdf,
                   resolution, layers_report, cell_size)

    def asked_porosity(self):
        """The uniform porosity the recipe asks for (``tdf.porosity_range = [p, p]``), else None."""
        return uniform_porosity(self.tdf)

    def inputs(self) -> list:
        return [p for p in (self.body and self.body.path, self.tdf.file) if p]


def _body_table(b) -> TbssBody:
    """The checked ``[body]`` table: a primitive (``kind`` and its ``params``) or a mesh to fit and cut to."""
    kind = b.get("kind")
    if kind == "mesh":
        path, fit, control, clip = b.get("path"), b.get("fit"), _three(b, "control"), b.get("clip")
        if b.has("margin") and fit == "sliced":
            raise b.error("margin", "a margin inflates a radial or hex fit; the sliced fit takes none")
        margin, skin = b.get("margin"), b.get("skin")
        if skin and not clip:
            raise b.error("skin", "a skin wraps a scaffold cut to the body; it needs clip = true")
        body = TbssBody(kind, path=path, fit=fit, control=control, clip=clip, margin=margin, skin=skin)
    else:
        body = TbssBody(kind, params=_primitive_params(b.get("params"), kind))
    b.done()
    return body


def _tdf_table(d, periods, edits: dict) -> TdfSpec:
    """The checked ``[tdf]`` keys of a built (not loaded) TDF: its method and fit, the threshold or porosity range."""
    method = d.get("method")
    fit = {"grid": _three(d, "grid"), "control": _three(d, "control"),
           **{k: d.get(k) for k in ("degree", "tol", "max_iter")}}
    if method == "layer":
        by = d.get("by")
        # one layer per period along ``by`` (with a cell size: once the periods are known)
        default_layers = int(periods["uvw".index(by)]) if by in "uvw" and periods is not None else None
        made = {"by": by, "layers": d.get("layers", default_layers), "layer_values": d.get("layer_values")}
    elif method == "fill":
        made = {"quantity": d.get("quantity")}
    else:
        made = {"expr": d.get("expr", check=_check_expression)}
    if d.has("threshold_range") and d.has("porosity_range"):
        raise d.error("porosity_range", "give a threshold range or a porosity range, not both")
    tdf = TdfSpec(method=method, **made, threshold_range=d.get("threshold_range"),
                  porosity_range=d.get("porosity_range"), **fit, **edits)
    d.done()
    return tdf


def _three(table, key):
    """One integer or three, as a 3-tuple (bounds and default: the key's declaration)."""
    k = table.declared(key)
    v = table.data.get(key, k.default)
    if isinstance(v, (list, tuple)):
        return tuple(table.get(key))
    return (table.integer(key, k.default, lo=k.lo, hi=k.hi),) * 3


#: the numeric parameters of the primitive bodies (mm; degrees for the disc's wedge)
PRIMITIVE_PARAMS = {"disc": {"width": 1, "depth": 1, "height": 1, "wedge_deg": 1, "dome": 1, "center": 3},
                    "box": {"size": 3, "origin": 3}, "cylinder": {"radius": 1, "height": 1, "center": 3},
                    "tube": {"r_inner": 1, "r_outer": 1, "height": 1, "center": 3}}


def _primitive_params(p, kind) -> dict:
    """The checked ``[body.params]`` of a primitive body (sizes positive, positions finite)."""
    out = {}
    for k in PRIMITIVE_PARAMS[kind]:
        if not p.has(k):
            continue
        out[k] = p.get(k)
    p.done()
    return out


def _check_expression(text):
    """A TDF expression or edit condition, parsed and checked now (:mod:`porecad.expressions`)."""
    from ..expressions import check_expression
    from ..grading.tdf_field import TDF_VARIABLES
    return check_expression(text, TDF_VARIABLES)


def _check_condition(text):
    return _check_expression(text)


@dataclasses.dataclass
class Design:
    """What :func:`run` builds before meshing: the solid, the TDF and how the scaffold is cut."""

    tpms_type: str
    structure: str
    periods: np.ndarray
    tbss: object                 # porecad.splines.TBSS
    tdf: object                  # porecad.splines.BSplineVolume of thresholds
    thresholds: np.ndarray | None  # the discrete TDF it was fitted to (None: read from a TDF file)
    body: tuple | None = None    # the body's (vertices, faces) (a mesh body cut to its surface)
    clip: object = None          # the body prepared for the cut (porecad.maps.tbss.body_clip)
    skin: float = 0.0


def run(spec: TbssSpec, progress=None, options=None) -> Result:
    """Build the TBSS scaffold of ``spec`` (nothing written).

    Stages: :func:`_design` (the TBSS and TDF, from the recipe or a TDF
    file) → :func:`_prepare_cut` (a mesh body: its clip and skin; a uniform
    porosity calibrated in the body) → :func:`_mesh` (the mapped scaffold,
    finer until no triangles cross) → :func:`_domain_report` (how much of the
    body the scaffold covers) → validation and the report.
    """
    from ..mesh.validate import signed_volume

    options = options or RunOptions()
    timer = (options or RunOptions()).stages  # the runner's stage clock: it reports the timings
    report, warnings = {}, []
    if spec.periods is not None:  # sized before the solid is built (a body's fit takes a while)
        require_size(spec.periods, spec.resolution, spec.structure, options.memory_limit)
    d, tdf_spec = _design(spec, timer, report)
    require_size(d.periods, spec.resolution, d.structure, options.memory_limit)
    _prepare_cut(spec, d, tdf_spec, timer, report, warnings, options, progress)
    res, resolution, crossings = _mesh(d, spec.resolution, options, report, warnings, progress)
    timer.timings.update(res["timings"])
    vertices, faces = res["vertices"], res["faces"]
    total_volume = _domain_report(d, res, report, warnings)
    mesh_param = 1.0 - float(signed_volume(res["params"], faces))
    sample_param = 1.0 - res["inside_fraction"]
    if abs(mesh_param - sample_param) > 0.02 and not any(getattr(d.tbss, "periodic", ())):  # a seam opens it
        warnings.append(Finding(
            "resolution-coarse", f"the resolution is coarse for this structure's walls: parametric porosity "
            f"{mesh_param:.3f} by mesh volume but {sample_param:.3f} by samples; raise the resolution",
            {"porosity_mesh": mesh_param, "porosity_samples": sample_param}))
    report.update({"type": d.tpms_type, "structure": d.structure, "periods": d.periods.tolist(),
                   "resolution": resolution, "tbss_volume": d.tbss.volume(), "domain_volume": total_volume})
    if d.clip is None:
        report["porosity_parametric"] = 1.0 - res["inside_fraction"]
    if spec.layers_report:
        with timer("layers"):
            _layers_report(d, tdf_spec, resolution, options, report)
    report["warnings"] = warnings
    fr = report["tdf"]["fitted_range"]
    design = {"type": d.tpms_type, "structure": d.structure, "threshold_min": fr["min"], "threshold_max": fr["max"]}
    from ..maps.domain_surface import tbss_surface
    from .contract import DeferredDomain
    if options.check_intersections:  # the mesh loop already searched the whole mesh for crossings
        report["self_intersections"] = crossings
    check = Validation("the mapped scaffold", total_volume)
    return Result(report, vertices, faces, domain_volume=total_volume, domain=DeferredDomain(tbss_surface, d.tbss),
                  design=design, extra_outputs={"tdf": _tdf_writer(d)}, body=d.body, validation=check)


def _design(spec, timer, report) -> tuple[Design, TdfSpec]:
    """The TBSS and TDF: read from ``tdf.file``, or the TBSS built (``[body]``) and the TDF fitted in it; and the
    ``[tdf]`` table with the number of layers found (a layered TDF of a cell size)."""
    from ..fields.tpms import get_type
    from ..io.tdf_file import read_tdf
    from ..maps.tbss import check_periods
    from ..solids import check_structure
    from ..splines import TBSS, BSplineVolume
    tdf_spec = spec.tdf
    if tdf_spec.file:
        with timer("read"):
            rec = read_tdf(tdf_spec.file)
            tpms_type, structure = get_type(rec.tpms_type).name, check_structure(rec.structure)
            periods = check_periods(rec.periods)
            tbss = TBSS(rec.tbss_control, rec.tbss_degrees, rec.tbss_knots, periodic=rec.tbss_periodic)
            jac = tbss.check_jacobian()
            tdf_volume = BSplineVolume(rec.tdf_control[..., None], rec.tdf_degrees, rec.tdf_knots)
        report["tdf"] = {"file": str(tdf_spec.file), "control": list(rec.tdf_control.shape)}
        report["tbss"] = {"kind": "tdf-file", "control_grid": list(rec.tbss_control.shape[:3]),
                          "min_jacobian": jac["min_det"]}
        d = Design(tpms_type, structure, periods, tbss, tdf_volume, None)
    else:
        with timer("tbss"):
            tbss, tinfo, body = build_tbss(spec.body)
        tinfo.pop("time_s", None)
        report["tbss"] = tinfo
        if spec.periods is None:  # from the cell size: the solid's mean line lengths along u, v, w
            from ..maps.tbss import periods_for_cell
            periods, lengths = periods_for_cell(tbss, spec.cell_size)
            require_param_samples(periods, spec.resolution, per="period")
            report["cell_size"] = {"requested": float(spec.cell_size), "line_lengths": lengths.tolist(),
                                   "achieved": (lengths / periods).tolist()}
            if tdf_spec.method == "layer" and tdf_spec.by in ("u", "v", "w") and tdf_spec.layers is None:
                tdf_spec = dataclasses.replace(tdf_spec, layers=int(periods["uvw".index(tdf_spec.by)]))
        else:
            periods = np.asarray(spec.periods, dtype=np.int64)
        with timer("tdf"):
            tdf_volume, report["tdf"], thresholds = build_tdf(tdf_spec, tbss, spec.type, spec.structure)
        d = Design(spec.type, spec.structure, periods, tbss, tdf_volume, thresholds, body=body)
    if tdf_spec.edits:
        with timer("edit"):
            d.tdf, report["tdf"]["edits"] = apply_edits(d.tdf, tdf_spec.edits, d.tbss, int(tdf_spec.edit_grid))
    report["tdf"]["fitted_range"] = check_tdf_range(d.tdf, d.tpms_type, d.structure, spec.allow)
    return d, tdf_spec


def _prepare_cut(spec, d: Design, tdf_spec, timer, report, warnings, options, progress) -> None:
    """A mesh body: its skin checked, the body prepared for the cut, a uniform porosity calibrated in it."""
    if d.body is None:
        return
    from ..maps.tbss import body_clip, sample_spacing
    d.skin = skin = float(spec.body.skin or 0.0)
    report["tbss"]["skin"] = skin
    if skin > 0:
        ext = np.ptp(d.body[0], axis=0)
        if skin >= 0.5 * float(ext.min()):
            raise InputError(f"skin thickness {skin:g} mm fills the body (smallest extent {ext.min():.3g} mm)")
        delta = sample_spacing(d.tbss, d.periods, spec.resolution)
        if skin < 1.5 * delta:
            warnings.append(Finding(
                "skin-thin", f"the skin ({skin:g} mm) is thinner than 1.5 samples ({1.5 * delta:.3g} mm): "
                "where a pore meets it, it is lost between samples; raise the resolution or the skin",
                {"skin": skin, "min_skin": 1.5 * delta}))
    # exact a few samples (and the skin) deep; finer samples stay within
    d.clip = body_clip(*d.body, d.tbss, d.periods, spec.resolution, skin=skin)
    target = uniform_porosity(tdf_spec) if d.thresholds is not None else None
    if target is not None:
        with timer("calibrate"):
            d.tdf, report["porosity_calibration"] = calibrate_in_body(
                d.tbss, d.tpms_type, d.structure, d.tdf, d.periods, spec.resolution, d.clip, skin, target,
                options.threads, stage_progress(progress, "calibrate"))
        report["tdf"]["fitted_range"] = check_tdf_range(d.tdf, d.tpms_type, d.structure, spec.allow)


def require_size(periods, resolution: int, structure: str, memory_limit=None) -> None:
    """Refuse (ResourceError, one line with the estimate) a TBSS scaffold that will not fit in the memory."""
    require_fits(mapped_estimate(periods, resolution, structure), memory_limit,
                 "lower the `resolution` or use fewer `periods`", "the TBSS scaffold")


def _mesh(d: Design, resolution, options, report, warnings, progress):
    """The mapped scaffold, rebuilt 1.5 x finer (at most :data:`MAX_REFINEMENTS` times) while triangles cross.

    Returns ``(res, resolution, crossings)``: :func:`porecad.maps.tbss.tbss_scaffold`'s
    result, the resolution used and the crossing face pairs left (0).
    """
    from ..maps.tbss import boundary_band_intersections, tbss_scaffold
    requested = resolution
    whole = bool(options.check_intersections) or d.clip is not None
    for attempt in range(MAX_REFINEMENTS + 1):
        res = tbss_scaffold(d.tbss, d.tpms_type, d.structure, d.tdf, d.periods, resolution, threads=options.threads,
                            progress=stage_progress(progress, "mesh"), clip=d.clip, skin=d.skin)
        # a cut surface runs through the cube's inside, where the band check does not look
        if whole:  # the whole mesh (slivers can cross where the map is very anisotropic)
            from ..maps.mapped_refine import refine_mapped_crossings
            # flat triangles of the mapped mesh crossing where the map bends strongly: split them in the
            # parameter domain (new vertices mapped exactly) before raising the resolution everywhere
            res["vertices"], res["params"], res["faces"], fix = refine_mapped_crossings(
                res["vertices"], res["params"], res["faces"], d.tbss.map_points, d.tbss.jacobian,
                periodic=tuple(getattr(d.tbss, "periodic", (False,) * 3)))
            crossings = fix["pairs_after"]
            if fix["pairs_before"]:
                report["crossing_refinement"] = fix
        else:
            crossings = boundary_band_intersections(res["vertices"], res["faces"], res["params"])
        if crossings == 0:
            break
        if attempt == MAX_REFINEMENTS:
            raise MeshError(f"the mapped scaffold intersects itself ({crossings} face pairs at resolution "
                            f"{resolution}); raise the resolution; nothing written")
        resolution = int(np.ceil(resolution * 1.5))
    if resolution != requested:
        warnings.append(Finding(
            "resolution-raised", f"resolution raised from {requested} to {resolution}: at {requested} mapped "
            "triangles crossed (flat boundary triangles where the TBSS bends the cube's faces, or slivers where it "
            "stretches strongly)", {"asked": requested, "used": resolution}))
    return res, resolution, crossings


def _domain_report(d: Design, res, report, warnings) -> float:
    """The design domain's volume (the TBSS, or the body inside it) and, cut to a body, how much of it is covered."""
    if d.clip is None:
        return d.tbss.volume()
    dom = res["domain"]
    t = report["tbss"]
    body_ext = np.asarray(t["body_hi"]) - np.asarray(t["body_lo"])
    domain_fraction = dom["volume"] / abs(t["body_volume"])
    t.update({
        "tbss_volume_ratio": t.get("covered_fraction"),
        # the fit's own coverage (exact Boolean); the cut domain's where that could not be formed
        "covered_fraction": t.get("tbss_coverage", domain_fraction),
        "domain_fraction": domain_fraction,
        "fit_extent_error": t.get("extent_error"),
        "extent_error": float(np.max(np.abs(np.asarray(dom["hi"]) - np.asarray(dom["lo"]) - body_ext) / body_ext)),
        "domain_lo": dom["lo"], "domain_hi": dom["hi"]})
    if t["covered_fraction"] < 0.98:
        warnings.append(Finding("fit-short", f"the TBSS covers {100 * t['covered_fraction']:.1f} % of the "
                                "body; raise body.margin or body.control",
                                {"covered_fraction": t["covered_fraction"], "limit": 0.98}))
    elif domain_fraction < t["covered_fraction"] - 0.02:
        warnings.append(Finding(
            "thin-parts-cut", f"the scaffold's samples resolve {100 * domain_fraction:.1f} % of the body (the "
            f"TBSS covers {100 * t['covered_fraction']:.1f} %): parts thinner than a sample are cut away; raise "
            "the resolution or the periods",
            {"domain_fraction": domain_fraction, "covered_fraction": t["covered_fraction"]}))
    return dom["volume"]


def _layers_report(d: Design, tdf_spec, resolution, options, report) -> None:
    """``report["layers"]``: the achieved porosity of each layer of a layered TDF (one layer per period)."""
    dinfo = report["tdf"]
    if d.thresholds is None or dinfo.get("method") != "layer" or dinfo.get("by") not in ("u", "v", "w"):
        return
    from ..grading.tdf_field import layer_index
    layer, n = layer_index(d.thresholds.shape, dinfo["by"], tdf_spec.layers)
    per = [float(np.mean(d.thresholds[layer == k])) for k in range(n)]
    if n == int(d.periods["uvw".index(dinfo["by"])]):
        report["layers"] = layer_porosity(d.tbss, d.tpms_type, d.structure, d.tdf, d.periods, resolution,
                                          dinfo["by"], per, options.threads, d.clip, d.skin)


def _tdf_writer(d: Design):
    """The ``tdf`` output: ``write(path, force)`` writes the design as a TDF file."""
    from ..io.tdf_file import TDFRecord, write_tdf

    def write(path, force):
        vol, tbss = d.tdf, d.tbss
        rec = TDFRecord(version=1, tpms_type=d.tpms_type, structure=d.structure,
                        periods=tuple(float(p) for p in d.periods), tdf_degrees=tuple(vol.degrees),
                        tdf_knots=tuple(vol.knots), tdf_control=vol.control[..., 0],
                        tbss_degrees=tuple(tbss.degrees), tbss_knots=tuple(tbss.knots), tbss_control=tbss.control,
                        tbss_periodic=tuple(bool(p) for p in tbss.periodic))
        write_tdf(path, rec, force=force)
    return write


JOB = Job("tbss", TbssSpec, run, outputs=("mesh", "report", "recipe", "tdf"),
          summary=("type", "structure", "periods", "resolution", "tbss_volume"),
          title="heterogeneous TPMS scaffolds in trivariate B-spline solids (001)")
