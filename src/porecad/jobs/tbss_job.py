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
import time

import numpy as np

from ..errors import InputError, MeshError, RangeError, ResourceError
from ..findings import Finding
from .contract import Job, Result, RunOptions, Timer, stage_progress
from .outputs import validated_report

BODY_KINDS = ("disc", "box", "cylinder", "tube")
#: how often a mapped scaffold whose curved boundary band intersects itself is rebuilt finer (x 1.5 each)
MAX_REFINEMENTS = 2


def build_tbss(body: dict):
    """The TBSS of a ``[body]`` table, a dict describing it, and the body mesh the scaffold is cut to (or None).

    A mesh body with ``clip`` (the default) is fitted ``margin`` larger
    (default :func:`porecad.splines.meshfit.cover_margin`) and its scaffold
    cut to the body's signed distance in field space
    (:func:`porecad.maps.tbss.tbss_scaffold` with ``clip``), so that the
    scaffold fills the body and keeps to its extents.
    """
    from ..splines import construct
    kind = str(body.get("kind", "disc"))
    t = time.perf_counter()
    clip = None
    if kind == "mesh":
        from ..bodies import load_body
        path = body.get("path")
        if not path:
            raise InputError("a mesh body needs a path")
        # read and repaired (oriented outward, holes closed) as every job reads a body
        vertices, faces, load_report = load_body(path, check_intersections=False)
        control = body.get("control", (8, 8, 8))
        from ..splines.meshfit import FoldedFit, fit_tbss_to_mesh
        fit = str(body.get("fit", "auto"))
        margin = body.get("margin")
        if margin is None:
            margin = "auto" if body.get("clip", True) and fit != "sliced" else 0.0
        try:
            tbss, diag = fit_tbss_to_mesh(vertices, faces, method=fit, n_ctrl=control, inflate=margin,
                                          cover=bool(body.get("clip", True)))
        except FoldedFit as err:  # auto: both plain fits fold through the body (seconds, not minutes of untangling)
            from ..errors import RecipeError
            raise RecipeError("body.fit", f"{path}: the TBSS fit folds through the body: {err.detail}; give "
                                          "\"hex\" or \"radial\" to untangle it anyway (minutes), or fill the "
                                          "body by infill, TIS or ARBF") from None
        except (RuntimeError, np.linalg.LinAlgError) as err:  # a singular factorisation of the fit's systems
            if "singular" not in str(err).lower():
                raise
            raise InputError(f"{path}: the TBSS fit ({fit}) is singular on this body ({err}): parts of it are "
                             "thin against the control grid; try another body.fit or fewer body.control "
                             "points") from None
        info = {"kind": "mesh", "path": str(path), "margin": float(diag.pop("inflate")), **diag}
        if load_report["repairs"]:
            info["repairs"] = load_report["repairs"]
        if body.get("clip", True):
            from ..mesh.validate import signed_volume
            from ..maps.tbss import body_overlap
            clip = (vertices, faces)
            info.update(clip=True, body_volume=float(abs(signed_volume(vertices, faces))),
                        body_lo=vertices.min(axis=0).tolist(), body_hi=vertices.max(axis=0).tolist())
            overlap = body_overlap(tbss, vertices, faces)
            if overlap is not None:
                ext = np.ptp(vertices, axis=0)
                info["tbss_coverage"] = overlap["fraction"]
                if overlap["lo"] is not None:
                    info["tbss_coverage_extent_error"] = float(np.max(np.abs(
                        np.subtract(overlap["hi"], overlap["lo"]) - ext) / ext))
    elif kind in BODY_KINDS:
        tbss = {"disc": construct.disc_tbss, "box": construct.box_tbss, "cylinder": construct.cylinder_tbss,
                "tube": construct.tube_tbss}[kind](**dict(body.get("params", {})))
        info = {"kind": kind}
    else:
        raise InputError(f"unknown TBSS body {kind!r}; use disc, box, cylinder, tube or a mesh file")
    jac = tbss.check_jacobian()
    info.update({"control_grid": list(tbss.control.shape[:3]), "degrees": list(tbss.degrees),
                 "min_jacobian": jac["min_det"], "max_jacobian": jac["max_det"],
                 "time_s": time.perf_counter() - t})
    return tbss, info, clip


def threshold_targets(spec: dict, tpms_type: str, structure: str, raw: np.ndarray):
    """Map a discrete TDF onto thresholds (001: linearly into the valid range), or via a porosity range."""
    from ..calibration import checked_range, threshold_for_porosity
    from ..grading.tdf_field import default_threshold_range, to_threshold_range
    if spec.get("threshold_range") is not None and spec.get("porosity_range") is not None:
        raise InputError("give a threshold range or a porosity range, not both")
    if spec.get("porosity_range") is not None:
        lo, hi = (float(x) for x in spec["porosity_range"])
        plo, phi = checked_range(tpms_type, structure, "porosity")
        for p in (lo, hi):
            if not plo <= p <= phi:
                raise RangeError(f"porosity {p:g} is outside the valid range [{plo:.3f}, {phi:.3f}] "
                                 f"of {tpms_type} {structure}")
        porosity = to_threshold_range(raw, lo, hi)
        # through a 1001-point table of the calibration curve (it is smooth)
        table = np.linspace(lo, hi, 1001) if hi > lo else np.array([lo])
        c = np.asarray(threshold_for_porosity(tpms_type, structure, table), dtype=np.float64)
        if table.size == 1:
            return np.full_like(porosity, c[0])
        return np.interp(porosity, table, c)
    if spec.get("threshold_range") is not None:
        lo, hi = (float(x) for x in spec["threshold_range"])
    else:
        lo, hi = default_threshold_range(tpms_type, structure)
    tlo, thi = checked_range(tpms_type, structure, "threshold")
    for c in (lo, hi):
        if not tlo <= c <= thi:
            raise RangeError(f"threshold {c:g} is outside the valid range [{tlo:.3f}, {thi:.3f}] "
                             f"of {tpms_type} {structure}")
    return to_threshold_range(raw, lo, hi)


def build_tdf(spec: dict, tbss, tpms_type: str, structure: str):
    """Discrete TDF → thresholds → LSPIA-fitted scalar B-spline; returns ``(volume, info, discrete)``."""
    from ..grading import tdf_field as tdfm
    from ..splines.lspia import fit_grid
    t = time.perf_counter()
    method = str(spec.get("method", "layer"))
    shape = tuple(spec.get("grid", (100, 100, 100)))
    info = {"method": method, "grid": list(shape)}
    if method == "layer":
        by = str(spec.get("by", "w"))
        raw = tdfm.layer_values(shape, by, spec.get("layers"), spec.get("layer_values"))
        info.update(by=by, layers=int(tdfm.layer_index(shape, by, spec.get("layers"))[1]))
    elif method == "fill":
        raw = tdfm.fill_values(tbss, shape, str(spec.get("quantity", "mean")))
        info["quantity"] = str(spec.get("quantity", "mean"))
    elif method == "function":
        raw = tdfm.function_values(str(spec.get("expr", "")), shape, tbss)
        info["expr"] = str(spec.get("expr"))
    else:
        raise InputError(f"unknown TDF method {method!r}; use layer, fill or an expression")
    thresholds = threshold_targets(spec, tpms_type, structure, raw)
    t_discrete = time.perf_counter() - t
    control = tuple(spec.get("control", (20, 20, 20)))
    degree = int(spec.get("degree", 3))
    t = time.perf_counter()
    volume, fit = fit_grid(thresholds, control, degree=degree, tol=float(spec.get("tol", 1e-4)),
                           max_iter=int(spec.get("max_iter", 200)))
    info.update({"control": list(control), "degree": degree, "discrete_s": t_discrete,
                 "fit_s": time.perf_counter() - t,
                 "lspia": {"iterations": int(fit.iterations), "converged": bool(fit.converged),
                           "rms_initial": float(fit.rms_history[0]), "rms": float(fit.rms),
                           "max_error": float(fit.max_error)},
                 "threshold_min": float(thresholds.min()), "threshold_max": float(thresholds.max())})
    return volume, info, thresholds


def apply_edits(volume, edits, tbss=None, grid: int = 100):
    """Local modification (001 §3.2): set the TDF at the grid vertices of a region, refit by local LSPIA.

    ``edits``: ``[{"where": "w > 0.8", "threshold": 0.3}, ...]`` — a boolean
    expression in ``u, v, w`` (and ``x, y, z``) picking vertices of an
    ``grid``³ parametric grid, and their new threshold. Only the control
    points whose support contains an edited vertex move
    (:func:`porecad.splines.lspia.local_lspia`). Returns the new volume and a
    report per edit.
    """
    from ..grading.tdf_field import function_values, grid_params
    from ..splines.lspia import local_lspia
    shape = (grid, grid, grid)
    out = []
    for edit in edits:
        where = str(edit.get("where", ""))
        mask = function_values(where, shape, tbss) != 0
        if not mask.any():
            raise InputError(f"edit region {where!r} contains no vertex of the {grid}^3 parametric grid")
        check_edit_work(int(mask.sum()), volume.degrees, grid)
        value = float(edit["threshold"])
        values = volume.evaluate_grid(*grid_params(shape))[..., 0]
        values[mask] = value
        edited = np.argwhere(mask)
        lo, hi = float(values.min()), float(values.max())  # the edited field's own range
        volume, moved, fit = local_lspia(volume, values, edited)
        # fitting only the edited vertices lets the moved control points overshoot where the region meets
        # the rest (a step of the field): hold them within the range of the values asked, so that the
        # field, a convex combination of its control points, never leaves it (nor the valid range)
        ctrl = volume.control
        held = moved[..., None] & ((ctrl < lo) | (ctrl > hi))
        if held.any():
            volume = volume.with_control(np.where(moved[..., None], np.clip(ctrl, lo, hi), ctrl))
        out.append({"where": where, "threshold": value, "vertices": int(mask.sum()),
                    "moved_control_points": int(moved.sum()), "control_points": int(moved.size),
                    "held_control_points": int(held.sum()),
                    "iterations": int(fit.iterations), "rms": float(fit.rms), "max_error": float(fit.max_error)})
    return volume, out


#: most basis-value updates a local edit may cost (vertices x (p+1)(q+1)(r+1) x iterations; about a minute)
MAX_EDIT_WORK = 4e9
#: iterations of local LSPIA (:func:`porecad.splines.lspia.local_lspia`'s default)
EDIT_ITERATIONS = 200


def check_edit_work(vertices: int, degrees, grid: int) -> None:
    """Refuse, before any work, a local edit whose local LSPIA would run for minutes."""
    per = int(np.prod([int(p) + 1 for p in degrees]))
    work = float(vertices) * per * EDIT_ITERATIONS
    if work > MAX_EDIT_WORK:
        raise ResourceError(f"the edit region holds {vertices:,} vertices of the {grid}^3 edit grid: its local "
                            f"refit would take {work:.2g} basis updates (at most {MAX_EDIT_WORK:.2g}); edit a "
                            "smaller region or lower tdf.edit_grid")


def check_tdf_range(volume, tpms_type, structure, allow=False, samples=41) -> dict:
    """The fitted TDF's range on a dense sample; refuse values outside the valid threshold range."""
    from ..calibration import checked_range
    s = np.linspace(0.0, 1.0, samples)
    vals = volume.evaluate_grid(s, s, s)[..., 0]
    lo, hi = float(vals.min()), float(vals.max())
    tlo, thi = checked_range(tpms_type, structure, "threshold")
    if not allow and (lo < tlo - 1e-9 or hi > thi + 1e-9):
        raise RangeError(f"the fitted TDF spans thresholds [{lo:.4g}, {hi:.4g}], outside the valid range "
                         f"[{tlo:.4g}, {thi:.4g}] of {tpms_type} {structure}; narrow the threshold range")
    return {"min": lo, "max": hi, "valid_range": [tlo, thi]}


def layer_porosity(tbss, tpms_type, structure, tdf_volume, periods, resolution, by, thresholds_by_layer,
                   threads=None, clip=None, skin=0.0) -> list[dict]:
    """Achieved porosity of every parametric layer (one slab of periods along ``by``) vs its target.

    Each layer's sub-box of the parameter cube is polygonised on the same
    samples as the whole scaffold, mapped, and its mesh volume compared with
    the TBSS volume of the sub-box (:meth:`porecad.splines.TBSS.volume`), or
    with ``clip`` that of the body inside it (:func:`porecad.maps.tbss.clipped_domain`).
    The target is the porosity of the layer's threshold in the discrete TDF.
    """
    from ..calibration import porosity_of_threshold
    from ..maps.tbss import tbss_scaffold
    from ..mesh.validate import signed_volume
    a = "uvw".index(by)
    n = len(thresholds_by_layer)
    out = []
    for k, c in enumerate(thresholds_by_layer):
        lo, hi = [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]
        lo[a], hi[a] = k / n, (k + 1) / n
        res = tbss_scaffold(tbss, tpms_type, structure, tdf_volume, periods, resolution, box=(lo, hi),
                            threads=threads, clip=clip, skin=skin)
        vol = float(signed_volume(res["vertices"], res["faces"]))
        total = res["domain"]["volume"] if clip is not None else tbss.volume(lo, hi)
        target = float(porosity_of_threshold(tpms_type, structure, float(c)))
        out.append({"layer": k, "threshold": float(c), "target_porosity": target,
                    "porosity": 1.0 - vol / total, "error": 1.0 - vol / total - target})
    return out




def uniform_porosity(tdf_spec: dict):
    """The porosity a ``[tdf]`` table asks for everywhere (``porosity_range = [p, p]``), else None."""
    pr = tdf_spec.get("porosity_range")
    if pr is None or tdf_spec.get("edits") or abs(float(pr[0]) - float(pr[1])) > 1e-12:
        return None
    return float(pr[0])


#: mesh passes that calibrate a clipped scaffold's threshold in the body, and the porosity error that ends them
CALIBRATION_STEPS, CALIBRATION_TOL = 4, 0.002


def calibrate_in_body(tbss, tpms_type, structure, tdf_volume, periods, resolution, clip, skin, target,
                      threads=None, progress=None):
    """The TDF shifted so that the scaffold cut to the body has the ``target`` porosity there.

    The calibration curve holds for whole cells of the parameter cube; in
    the body the porosity by volume drifts from it where the TBSS stretches
    its cells unevenly and the cut leaves partial cells (the femur at the
    bench's 4 periods: +0.04; a solid skin: far less). Each step meshes the scaffold (no crossing
    search), measures ``1 - V(mesh) / V(cut domain)`` and moves the
    parameter-space porosity by the error (then by the secant of the last
    two steps), through the calibration curve, as a uniform shift of the TDF's control values (a B-spline's values
    shift with them), at most :data:`CALIBRATION_STEPS` times, until within
    :data:`CALIBRATION_TOL`. Returns ``(tdf_volume, report)``.
    """
    from ..calibration import checked_range, porosity_of_threshold, threshold_for_porosity
    from ..maps.tbss import clipped_domain, tbss_scaffold
    from ..mesh.validate import signed_volume
    from ..splines import BSplineVolume
    dom = clipped_domain(tbss, clip, tpms_type, structure, tdf_volume, periods, resolution, threads=threads)
    tlo, thi = checked_range(tpms_type, structure, "threshold")
    plo, phi = sorted(float(porosity_of_threshold(tpms_type, structure, c)) for c in (tlo, thi))
    c0 = float(threshold_for_porosity(tpms_type, structure, target))

    def shifted(param):  # the TDF whose (uniform) threshold gives ``param`` in the parameter cube, and the shift
        shift = float(threshold_for_porosity(tpms_type, structure, param)) - c0
        return BSplineVolume(tdf_volume.control + shift, tdf_volume.degrees, tdf_volume.knots), shift

    param = float(target)
    steps, vol = [], tdf_volume
    for k in range(CALIBRATION_STEPS):
        res = tbss_scaffold(tbss, tpms_type, structure, vol, periods, resolution, threads=threads, clip=clip,
                            skin=skin, domain=False, progress=progress)
        achieved = 1.0 - float(signed_volume(res["vertices"], res["faces"])) / dom["volume"]
        steps.append({"parametric_porosity": param, "porosity": achieved})
        if abs(achieved - target) <= CALIBRATION_TOL or k == CALIBRATION_STEPS - 1:
            break
        slope = 1.0  # the first step: the error moved as it is; then the secant of the last two
        if len(steps) > 1:
            dp = steps[-1]["parametric_porosity"] - steps[-2]["parametric_porosity"]
            da = steps[-1]["porosity"] - steps[-2]["porosity"]
            if abs(dp) > 1e-9 and 0.2 < da / dp < 5.0:
                slope = da / dp
        param = float(np.clip(param - (achieved - target) / slope, plo + 1e-3, phi - 1e-3))
        vol, _ = shifted(param)
    # the closest step (the last one may have overshot)
    best = min(steps, key=lambda st: abs(st["porosity"] - target))
    vol, shift = shifted(best["parametric_porosity"])
    return vol, {"target": float(target), "steps": steps, "threshold_shift": shift}


BODY_FITS = ("auto", "radial", "sliced", "hex")
TDF_METHODS = ("layer", "fill", "function")
#: largest parametric sample count (prod(periods) x resolution³)
MAX_PARAM_SAMPLES = 400_000_000


def check_samples(periods, resolution: int) -> None:
    """Refuse, before the work, more than :data:`MAX_PARAM_SAMPLES` parametric samples."""
    samples = float(np.prod(np.asarray(periods, dtype=np.float64))) * float(resolution) ** 3
    if samples > MAX_PARAM_SAMPLES:
        raise ResourceError(f"{' x '.join(str(int(p)) for p in periods)} periods at {resolution} samples per period "
                            f"edge are {samples:,.0f} samples (at most {MAX_PARAM_SAMPLES:,}); lower the resolution"
                            " or raise the cell size")


@dataclasses.dataclass(frozen=True)
class TbssSpec:
    """A checked ``tbss`` recipe (see the module docstring for the keys)."""

    body: dict | None
    type: str | None
    structure: str | None
    periods: tuple | None
    allow: bool
    tdf: dict
    resolution: int
    layers_report: bool
    cell_size: float | None = None

    @classmethod
    def from_recipe(cls, r):
        from ..fields.tpms import get_type
        from ..maps.tbss import check_periods
        from ..solids import check_structure
        t = r.table("tpms")
        allow = t.flag("allow_closed_pores", False)
        d = r.table("tdf")
        tdf: dict = {}
        m = r.table("mesh")
        resolution = m.integer("resolution", 16, lo=2, hi=512)
        m.done()
        a = r.table("analysis")
        layers_report = a.flag("layers", True)
        a.done()
        edits = []
        for e in d.tables("edits", max_len=64):
            # TPMS values are of order 1: a threshold beyond ±10 selects all or nothing (and 1e308 overflows the fit)
            edits.append({"where": e.checked("where", _check_condition), "threshold": e.number("threshold", lo=-10, hi=10)})
            e.done()
        if edits:
            tdf["edits"] = edits
            tdf["edit_grid"] = d.integer("edit_grid", 100, lo=4, hi=400)
        if d.has("file"):
            tdf["file"] = d.path("file")
            d.done()
            t.done()
            if r.has("body"):
                raise r.error("body", "a TDF file holds its own body; give no [body] with tdf.file")
            return cls(None, None, None, None, allow, tdf, resolution, layers_report)
        ttype = t.checked("type", lambda v: get_type(str(v)).name, "G")
        structure = t.checked("structure", check_structure, "sheet")
        if structure == "surface":
            raise t.error("structure", "a TBSS scaffold needs a solid structure: pore, rod or sheet")
        cell_size = None
        if t.has("cell_size"):
            if t.has("periods"):
                raise t.error("cell_size", "give periods or a cell size, not both")
            cell_size = t.number("cell_size", positive=True, hi=1e9)
            periods = None
        else:
            periods = t.checked("periods", check_periods, (4, 4, 4))
            if float(np.max(periods)) > 1000:
                raise t.error("periods", f"at most 1000 periods per direction, got {tuple(periods)}")
            check_samples(periods, resolution)
        t.done()
        b = r.table("body")
        kind = b.choice("kind", BODY_KINDS + ("mesh",), "disc")
        body = {"kind": kind}
        if kind == "mesh":
            body["path"] = b.path("path")
            body["fit"] = b.choice("fit", BODY_FITS, "auto")
            body["control"] = _three(b, "control", 8, 4, 64)
            body["clip"] = b.flag("clip", True)
            if b.has("margin"):
                if body["fit"] == "sliced":
                    raise b.error("margin", "a margin inflates a radial or hex fit; the sliced fit takes none")
                body["margin"] = b.number("margin", nonneg=True, hi=1e6)
            if b.has("skin"):
                body["skin"] = b.number("skin", nonneg=True, hi=1e6)
                if body["skin"] > 0 and not body["clip"]:
                    raise b.error("skin", "a skin wraps a scaffold cut to the body; it needs clip = true")
        else:
            body["params"] = _primitive_params(b.table("params"), kind)
        b.done()
        method = d.choice("method", TDF_METHODS, "layer")
        tdf.update(method=method, grid=_three(d, "grid", 100, 4, 400), control=_three(d, "control", 20, 2, 128),
                   degree=d.integer("degree", 3, lo=1, hi=5), tol=d.number("tol", 1e-4, positive=True, hi=1.0),
                   max_iter=d.integer("max_iter", 200, lo=1, hi=100_000))
        if method == "layer":
            tdf["by"] = d.choice("by", ("u", "v", "w", "sides", "boundary"), "w")
            # one layer per period along ``by`` (with a cell size: once the periods are known)
            default_layers = int(periods["uvw".index(tdf["by"])]) if tdf["by"] in "uvw" and periods is not None \
                else None
            tdf["layers"] = d.integer("layers", default_layers, lo=1, hi=1000)
            if d.has("layer_values"):
                tdf["layer_values"] = d.numbers("layer_values", max_len=1000)
        elif method == "fill":
            tdf["quantity"] = d.choice("quantity", ("mean", "gaussian"), "mean")
        else:
            tdf["expr"] = d.checked("expr", _check_expression)
        if d.has("threshold_range") and d.has("porosity_range"):
            raise d.error("porosity_range", "give a threshold range or a porosity range, not both")
        if d.has("threshold_range"):
            tdf["threshold_range"] = d.numbers("threshold_range", length=2)
        if d.has("porosity_range"):
            tdf["porosity_range"] = d.numbers("porosity_range", length=2, lo=0.0, hi=1.0)
        d.done()
        return cls(body, ttype, structure, None if periods is None else tuple(int(p) for p in periods), allow, tdf,
                   resolution, layers_report, cell_size)

    def asked_porosity(self):
        """The uniform porosity the recipe asks for (``tdf.porosity_range = [p, p]``), else None."""
        return uniform_porosity(self.tdf)

    def inputs(self) -> list:
        return [p for p in ((self.body or {}).get("path"), self.tdf.get("file")) if p]


def _three(table, key, default, lo, hi):
    """One integer or three, as a 3-tuple."""
    v = table.data.get(key, default)
    if isinstance(v, (list, tuple)):
        return tuple(table.integers(key, length=3, lo=lo, hi=hi))
    return (table.integer(key, default, lo=lo, hi=hi),) * 3


#: the numeric parameters of the primitive bodies (mm; degrees for the disc's wedge)
PRIMITIVE_PARAMS = {"disc": {"width": 1, "depth": 1, "height": 1, "wedge_deg": 1, "dome": 1, "center": 3},
                    "box": {"size": 3, "origin": 3}, "cylinder": {"radius": 1, "height": 1, "center": 3},
                    "tube": {"r_inner": 1, "r_outer": 1, "height": 1, "center": 3}}


def _primitive_params(p, kind) -> dict:
    """The checked ``[body.params]`` of a primitive body (sizes positive, positions finite)."""
    out = {}
    for k, n in PRIMITIVE_PARAMS[kind].items():
        if not p.has(k):
            continue
        if n == 1:
            out[k] = p.number(k, lo=-90.0, hi=90.0) if k == "wedge_deg" else \
                p.number(k, nonneg=k == "dome", positive=k != "dome", hi=1e6)
        else:
            out[k] = p.numbers(k, length=3, lo=-1e6, hi=1e6, positive=k == "size")
    p.done()
    return out


def _check_expression(text):
    """A TDF expression or edit condition, parsed and checked now (:mod:`porecad.expressions`)."""
    from ..expressions import check_expression
    from ..grading.tdf_field import TDF_VARIABLES
    return check_expression(text, TDF_VARIABLES)


def _check_condition(text):
    return _check_expression(text)


def run(spec: TbssSpec, progress=None, options=None) -> Result:
    """Build the TBSS scaffold of ``spec`` (nothing written)."""
    from ..io.tdf_file import TDFRecord, read_tdf, write_tdf
    from ..maps.tbss import boundary_band_intersections, check_periods, tbss_scaffold
    from ..mesh.validate import signed_volume
    from ..solids import check_structure
    from ..splines import TBSS, BSplineVolume
    from ..fields.tpms import get_type

    options = options or RunOptions()
    timer = Timer()
    tdf_spec = dict(spec.tdf)
    resolution = spec.resolution
    report = {}
    warnings = []
    if tdf_spec.get("file"):
        with timer("read"):
            rec = read_tdf(tdf_spec["file"])
            tpms_type, structure = get_type(rec.tpms_type).name, check_structure(rec.structure)
            periods = check_periods(rec.periods)
            tbss = TBSS(rec.tbss_control, rec.tbss_degrees, rec.tbss_knots, periodic=rec.tbss_periodic)
            jac = tbss.check_jacobian()
            tdf_volume = BSplineVolume(rec.tdf_control[..., None], rec.tdf_degrees, rec.tdf_knots)
        report["tdf"] = {"file": str(tdf_spec["file"]), "control": list(rec.tdf_control.shape)}
        report["tbss"] = {"kind": "tdf-file", "control_grid": list(rec.tbss_control.shape[:3]),
                          "min_jacobian": jac["min_det"]}
        thresholds = None
        clip = None
    else:
        tpms_type, structure = spec.type, spec.structure
        with timer("tbss"):
            tbss, tinfo, clip = build_tbss(dict(spec.body))
        tinfo.pop("time_s", None)
        report["tbss"] = tinfo
        if spec.periods is None:  # from the cell size: the solid's mean line lengths along u, v, w
            from ..maps.tbss import periods_for_cell
            periods, lengths = periods_for_cell(tbss, spec.cell_size)
            check_samples(periods, resolution)
            report["cell_size"] = {"requested": float(spec.cell_size), "line_lengths": lengths.tolist(),
                                   "achieved": (lengths / periods).tolist()}
            if tdf_spec.get("method") == "layer" and tdf_spec.get("by") in ("u", "v", "w") \
                    and tdf_spec.get("layers") is None:
                tdf_spec["layers"] = int(periods["uvw".index(tdf_spec["by"])])
        else:
            periods = np.asarray(spec.periods, dtype=np.int64)
        with timer("tdf"):
            tdf_volume, dinfo, thresholds = build_tdf(tdf_spec, tbss, tpms_type, structure)
        report["tdf"] = dinfo
    if tdf_spec.get("edits"):
        with timer("edit"):
            tdf_volume, report["tdf"]["edits"] = apply_edits(tdf_volume, tdf_spec["edits"], tbss,
                                                             int(tdf_spec.get("edit_grid", 100)))
    report["tdf"]["fitted_range"] = check_tdf_range(tdf_volume, tpms_type, structure, spec.allow)
    requested = resolution
    skin = 0.0
    body_mesh = clip  # the body's (vertices, faces) for the promise check
    if clip is not None:
        from ..maps.tbss import body_clip, sample_spacing
        skin = float(spec.body.get("skin", 0.0))
        report["tbss"]["skin"] = skin
        if skin > 0:
            ext = np.ptp(clip[0], axis=0)
            if skin >= 0.5 * float(ext.min()):
                raise InputError(f"skin thickness {skin:g} mm fills the body (smallest extent {ext.min():.3g} mm)")
            delta = sample_spacing(tbss, periods, resolution)
            if skin < 1.5 * delta:
                warnings.append(Finding(
                    "skin-thin", f"the skin ({skin:g} mm) is thinner than 1.5 samples ({1.5 * delta:.3g} mm): "
                    "where a pore meets it, it is lost between samples; raise the resolution or the skin",
                    {"skin": skin, "min_skin": 1.5 * delta}))
        # exact a few samples (and the skin) deep; finer samples stay within
        clip = body_clip(*clip, tbss, periods, resolution, skin=skin)
    target = uniform_porosity(tdf_spec) if thresholds is not None else None
    if clip is not None and target is not None:
        with timer("calibrate"):
            tdf_volume, report["porosity_calibration"] = calibrate_in_body(
                tbss, tpms_type, structure, tdf_volume, periods, resolution, clip, skin, target, options.threads,
                stage_progress(progress, "calibrate"))
        report["tdf"]["fitted_range"] = check_tdf_range(tdf_volume, tpms_type, structure, spec.allow)
    check_intersections = bool(options.check_intersections)
    for attempt in range(MAX_REFINEMENTS + 1):
        res = tbss_scaffold(tbss, tpms_type, structure, tdf_volume, periods, resolution, threads=options.threads,
                            progress=stage_progress(progress, "mesh"), clip=clip, skin=skin)
        # a cut surface runs through the cube's inside, where the band check does not look
        if check_intersections or clip is not None:  # the whole mesh (slivers can cross where the map is very anisotropic)
            from ..maps.mapped_refine import refine_mapped_crossings
            # flat triangles of the mapped mesh crossing where the map bends strongly: split them in the
            # parameter domain (new vertices mapped exactly) before raising the resolution everywhere
            res["vertices"], res["params"], res["faces"], fix = refine_mapped_crossings(
                res["vertices"], res["params"], res["faces"], tbss.map_points, tbss.jacobian,
                periodic=tuple(getattr(tbss, "periodic", (False,) * 3)))
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
    timer.timings.update(res["timings"])
    vertices, faces = res["vertices"], res["faces"]
    total_volume = tbss.volume()
    if clip is not None:  # the domain is the body inside the TBSS
        dom = res["domain"]
        total_volume = dom["volume"]
        body_ext = np.asarray(report["tbss"]["body_hi"]) - np.asarray(report["tbss"]["body_lo"])
        t = report["tbss"]
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
    with timer("validate"):
        # the loop above already searched the whole mesh for crossings when asked to
        mesh_rep, chk, vertices = validated_report(vertices, faces, total_volume, check_intersections=False,
                                         what="the mapped scaffold")
    report.update(mesh_rep)
    if check_intersections:
        report["self_intersections"] = crossings
    mesh_param = 1.0 - float(signed_volume(res["params"], faces))
    sample_param = 1.0 - res["inside_fraction"]
    if abs(mesh_param - sample_param) > 0.02 and not any(getattr(tbss, "periodic", ())):  # a seam opens it
        warnings.append(Finding(
            "resolution-coarse", f"the resolution is coarse for this structure's walls: parametric porosity "
            f"{mesh_param:.3f} by mesh volume but {sample_param:.3f} by samples; raise the resolution",
            {"porosity_mesh": mesh_param, "porosity_samples": sample_param}))
    report.update({"type": tpms_type, "structure": structure, "periods": periods.tolist(),
                   "resolution": resolution, "tbss_volume": tbss.volume(),
                   "domain_volume": total_volume})
    if clip is None:
        report["porosity_parametric"] = 1.0 - res["inside_fraction"]
    dinfo = report["tdf"]
    if thresholds is not None and dinfo.get("method") == "layer" and dinfo.get("by") in ("u", "v", "w") \
            and spec.layers_report:
        from ..grading.tdf_field import layer_index
        with timer("layers"):
            layer, n = layer_index(thresholds.shape, dinfo["by"], tdf_spec.get("layers"))
            per = [float(np.mean(thresholds[layer == k])) for k in range(n)]
            if n == int(periods["uvw".index(dinfo["by"])]):
                report["layers"] = layer_porosity(tbss, tpms_type, structure, tdf_volume, periods, resolution,
                                                  dinfo["by"], per, options.threads, clip, skin)
    report["warnings"] = warnings
    report["timings"] = timer.total()

    def write(path, force):
        vol = tdf_volume
        rec = TDFRecord(version=1, tpms_type=tpms_type, structure=structure, periods=tuple(float(p) for p in periods),
                        tdf_degrees=tuple(vol.degrees), tdf_knots=tuple(vol.knots), tdf_control=vol.control[..., 0],
                        tbss_degrees=tuple(tbss.degrees), tbss_knots=tuple(tbss.knots), tbss_control=tbss.control,
                        tbss_periodic=tuple(bool(p) for p in tbss.periodic))
        write_tdf(path, rec, force=force)

    fr = report["tdf"]["fitted_range"]
    design = {"type": tpms_type, "structure": structure, "threshold_min": fr["min"], "threshold_max": fr["max"]}
    from ..maps.domain_surface import tbss_surface
    from .contract import DeferredDomain
    return Result(report, vertices, faces, domain_volume=total_volume, domain=DeferredDomain(tbss_surface, tbss),
                  design=design, extra_outputs={"tdf": write}, check=chk, body=body_mesh)


JOB = Job("tbss", TbssSpec, run, outputs=("mesh", "report", "recipe", "tdf"),
          summary=("type", "structure", "periods", "resolution", "tbss_volume"),
          title="heterogeneous TPMS scaffolds in trivariate B-spline solids (001)")
