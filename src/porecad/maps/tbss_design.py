"""The stages of a TBSS design (document 001): the solid, the TDF, its edits, its range and calibration.

Each takes plain values (the ``[body]`` and ``[tdf]`` tables as :class:`TbssBody`
and :class:`TdfSpec`, the TBSS and TDF as :mod:`porecad.splines` objects) and
returns them with a dict for the report; :func:`porecad.jobs.tbss_job.run`
runs them in order:

* :func:`build_tbss` — ``[body]`` → the TBSS (a primitive, or fitted to a
  mesh), its report, and the body mesh the scaffold is cut to (or None);
* :func:`build_tdf` — ``[tdf]`` and the TBSS → the TDF (a B-spline volume of
  thresholds), its report and the discrete thresholds it was fitted to;
* :func:`apply_edits` — local edits of the TDF (001 §3.2);
* :func:`check_tdf_range` — the fitted TDF inside the valid threshold range;
* :func:`calibrate_in_body` — the TDF shifted so that a scaffold cut to the
  body has the asked porosity there;
* :func:`layer_porosity` — the achieved porosity of each layer.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import InputError, RangeError, ResourceError

BODY_KINDS = ("disc", "box", "cylinder", "tube")


@dataclasses.dataclass(frozen=True)
class TbssBody:
    """A checked ``[body]``: a primitive (:data:`BODY_KINDS`, its ``params``) or a mesh to fit (``kind = "mesh"``)."""

    kind: str
    params: dict = dataclasses.field(default_factory=dict)  # a primitive's sizes and position (its keywords)
    path: str | None = None      # mesh: the body; then how it is fitted (fit, control grid)
    fit: str | None = None
    control: tuple | None = None
    clip: bool | None = None     # fit a margin larger, cut the scaffold to the body
    margin: float | None = None  # None: the fit's own
    skin: float | None = None    # a clipped scaffold wrapped in a solid shell that thick (None: none)


@dataclasses.dataclass(frozen=True)
class TdfSpec:
    """A checked ``[tdf]``: a TDF ``file``, or the ``method`` of the discrete TDF (with its keys), its range and
    its LSPIA fit; and local ``edits``, ``(where, threshold)`` pairs on an ``edit_grid``³ grid (001 §3.2)."""

    file: str | None = None
    method: str | None = None    # layer, fill or function
    by: str | None = None        # layer: along u, v, w, sides or boundary
    layers: int | None = None    # layer (None: one per period along by)
    layer_values: list | None = None
    quantity: str | None = None  # fill: mean or gaussian curvature
    expr: str | None = None      # function: a formula in u, v, w
    threshold_range: list | None = None
    porosity_range: list | None = None
    grid: tuple | None = None    # the fit: the parametric grid, the control grid, degree, tolerance, iterations
    control: tuple | None = None
    degree: int | None = None
    tol: float | None = None
    max_iter: int | None = None
    edits: tuple = ()
    edit_grid: int | None = None


def build_tbss(body: TbssBody):
    """The TBSS of a ``[body]`` table, a dict describing it, and the body mesh the scaffold is cut to (or None).

    A mesh body with ``clip`` (the default) is fitted ``margin`` larger
    (default :func:`porecad.splines.meshfit.cover_margin`) and its scaffold
    cut to the body's signed distance in field space
    (:func:`porecad.maps.tbss.tbss_scaffold` with ``clip``), so that the
    scaffold fills the body and keeps to its extents.
    """
    from ..splines import construct
    kind = body.kind
    t = time.perf_counter()
    clip = None
    if kind == "mesh":
        from ..bodies import load_body
        path = body.path
        if not path:
            raise InputError("a mesh body needs a path")
        # read and repaired (oriented outward, holes closed) as every job reads a body
        vertices, faces, load_report = load_body(path, check_intersections=False)
        from ..splines.meshfit import fit_tbss_to_mesh
        from ..splines.meshfit_grid import FoldedFit
        fit = body.fit
        margin = body.margin
        if margin is None:
            margin = "auto" if body.clip and fit != "sliced" else 0.0
        try:
            tbss, diag = fit_tbss_to_mesh(vertices, faces, method=fit, n_ctrl=body.control, inflate=margin,
                                          cover=bool(body.clip))
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
        if body.clip:
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
                "tube": construct.tube_tbss}[kind](**body.params)
        info = {"kind": kind}
    else:
        raise InputError(f"unknown TBSS body {kind!r}; use disc, box, cylinder, tube or a mesh file")
    jac = tbss.check_jacobian()
    info.update({"control_grid": list(tbss.control.shape[:3]), "degrees": list(tbss.degrees),
                 "min_jacobian": jac["min_det"], "max_jacobian": jac["max_det"],
                 "time_s": time.perf_counter() - t})
    return tbss, info, clip


def threshold_targets(spec: TdfSpec, tpms_type: str, structure: str, raw: np.ndarray):
    """Map a discrete TDF onto thresholds (001: linearly into the valid range), or via a porosity range.

    ``spec`` holds at most one of the two ranges (:class:`~porecad.jobs.tbss_job.TbssSpec` refuses both).
    """
    from ..calibration import checked_range, threshold_for_porosity
    from ..grading.tdf_field import default_threshold_range, to_threshold_range
    if spec.porosity_range is not None:
        lo, hi = (float(x) for x in spec.porosity_range)
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
    if spec.threshold_range is not None:
        lo, hi = (float(x) for x in spec.threshold_range)
    else:
        lo, hi = default_threshold_range(tpms_type, structure)
    tlo, thi = checked_range(tpms_type, structure, "threshold")
    for c in (lo, hi):
        if not tlo <= c <= thi:
            raise RangeError(f"threshold {c:g} is outside the valid range [{tlo:.3f}, {thi:.3f}] "
                             f"of {tpms_type} {structure}")
    return to_threshold_range(raw, lo, hi)


def build_tdf(spec: TdfSpec, tbss, tpms_type: str, structure: str):
    """Discrete TDF → thresholds → LSPIA-fitted scalar B-spline; returns ``(volume, info, discrete)``."""
    from ..grading import tdf_field as tdfm
    from ..splines.lspia import fit_grid
    t = time.perf_counter()
    method = spec.method
    shape = tuple(spec.grid)
    info = {"method": method, "grid": list(shape)}
    if method == "layer":
        raw = tdfm.layer_values(shape, spec.by, spec.layers, spec.layer_values)
        info.update(by=spec.by, layers=int(tdfm.layer_index(shape, spec.by, spec.layers)[1]))
    elif method == "fill":
        raw = tdfm.fill_values(tbss, shape, spec.quantity)
        info["quantity"] = spec.quantity
    elif method == "function":
        raw = tdfm.function_values(str(spec.expr), shape, tbss)
        info["expr"] = str(spec.expr)
    else:
        raise InputError(f"unknown TDF method {method!r}; use layer, fill or an expression")
    thresholds = threshold_targets(spec, tpms_type, structure, raw)
    t_discrete = time.perf_counter() - t
    control, degree = tuple(spec.control), int(spec.degree)
    t = time.perf_counter()
    volume, fit = fit_grid(thresholds, control, degree=degree, tol=float(spec.tol), max_iter=int(spec.max_iter))
    # a least-squares fit overshoots a step of the discrete TDF (a fill's rim, a layer's edge): hold the control
    # points within the thresholds asked, which lie in the valid range, so that the field never leaves it
    volume, held = hold_within(volume, float(thresholds.min()), float(thresholds.max()))
    info.update({"control": list(control), "degree": degree, "discrete_s": t_discrete, "held_control_points": held,
                 "fit_s": time.perf_counter() - t,
                 "lspia": {"iterations": int(fit.iterations), "converged": bool(fit.converged),
                           "rms_initial": float(fit.rms_history[0]), "rms": float(fit.rms),
                           "max_error": float(fit.max_error)},
                 "threshold_min": float(thresholds.min()), "threshold_max": float(thresholds.max())})
    return volume, info, thresholds


def apply_edits(volume, edits, tbss=None, grid: int = 100):
    """Local modification (001 §3.2): set the TDF at the grid vertices of a region, refit by local LSPIA.

    ``edits``: ``[("w > 0.8", 0.3), ...]`` — a boolean
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
    for where, value in edits:
        where, value = str(where), float(value)
        mask = function_values(where, shape, tbss) != 0
        if not mask.any():
            raise InputError(f"edit region {where!r} contains no vertex of the {grid}^3 parametric grid")
        check_edit_work(int(mask.sum()), volume.degrees, grid)
        values = volume.evaluate_grid(*grid_params(shape))[..., 0]
        values[mask] = value
        edited = np.argwhere(mask)
        lo, hi = float(values.min()), float(values.max())  # the edited field's own range
        volume, moved, fit = local_lspia(volume, values, edited)
        # fitting only the edited vertices lets the moved control points overshoot where the region meets
        # the rest (a step of the field): hold them within the range of the values asked
        volume, held = hold_within(volume, lo, hi, moved[..., None])
        out.append({"where": where, "threshold": value, "vertices": int(mask.sum()),
                    "moved_control_points": int(moved.sum()), "control_points": int(moved.size),
                    "held_control_points": held,
                    "iterations": int(fit.iterations), "rms": float(fit.rms), "max_error": float(fit.max_error)})
    return volume, out


def hold_within(volume, lo: float, hi: float, where=True):
    """``(volume, held)``: the scalar B-spline ``volume`` with its control points (those ``where`` is true)
    clipped to ``[lo, hi]`` (a B-spline is a convex combination of its control points: the field then never
    leaves the range), and how many were moved."""
    ctrl = volume.control
    out = where & ((ctrl < lo) | (ctrl > hi))
    held = int(np.count_nonzero(out))
    return (volume.with_control(np.where(out, np.clip(ctrl, lo, hi), ctrl)) if held else volume), held


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




def uniform_porosity(tdf: TdfSpec):
    """The porosity a ``[tdf]`` table asks for everywhere (``porosity_range = [p, p]``), else None."""
    pr = tdf.porosity_range
    if pr is None or tdf.edits or abs(float(pr[0]) - float(pr[1])) > 1e-12:
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
