"""The ``tbss`` job: a heterogeneous scaffold in a trivariate B-spline solid (document 001).

Recipe (TOML, ``job = "tbss"``)::

    [body]   kind = "disc" | "box" | "cylinder" | "tube" | "mesh"
             path = "femur.stl"          # kind = "mesh": fitted, fit = "auto" | "radial" | "sliced" | "hex"
             control = [8, 8, 8]         # TBSS control grid of a fitted body
    [tpms]   type = "G", structure = "sheet", periods = [4, 4, 4]
    [tdf]    method = "layer" | "fill" | "function"
             by = "w"   layers = 4        # layer method: u, v, w, sides, boundary
             quantity = "mean"            # fill method: mean or gaussian curvature
             expr = "0.5 + 0.5 * w"       # function method
             threshold_range = [lo, hi]   # or porosity_range; default: the valid range, inset 10 %
             grid = 100  control = 20  degree = 3
    [tdf]    file = "scaffold.tdf"        # instead: regenerate from a TDF file
    [mesh]   resolution = 16              # samples per period edge
    [output] mesh = "out.stl", tdf = "out.tdf", report = "report.json"

Stages: TBSS (primitive or fit; Jacobian checked) → discrete TDF on the
parametric grid → linear map into the threshold range → LSPIA fit → volume
TPMS in the parameter cube → map through the TBSS → validate → write.
"""

from __future__ import annotations

import time

import numpy as np

from . import __version__
from .errors import InputError, MeshError, RangeError

BODY_KINDS = ("disc", "box", "cylinder", "tube")
#: how often a mapped scaffold whose curved boundary band intersects itself is rebuilt finer (x 1.5 each)
MAX_REFINEMENTS = 2


def _ints3(value, name, lo=1):
    v = np.broadcast_to(np.asarray(value), (3,))
    try:
        iv = v.astype(np.int64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be integers, got {value!r}") from None
    if np.any(iv != v) or np.any(iv < lo):
        raise InputError(f"{name} must be integers >= {lo}, got {value!r}")
    return tuple(int(x) for x in iv)


def build_tbss(body: dict):
    """The TBSS of a ``[body]`` table and a dict describing it."""
    from .splines import construct
    kind = str(body.get("kind", "disc"))
    t = time.perf_counter()
    if kind == "mesh":
        from .io import read_mesh
        path = body.get("path")
        if not path:
            raise InputError("a mesh body needs a path")
        vertices, faces = read_mesh(path)
        control = _ints3(body.get("control", 8), "body control grid", lo=4)
        from .splines.meshfit import fit_tbss_to_mesh
        tbss, diag = fit_tbss_to_mesh(vertices, faces, method=str(body.get("fit", "auto")), n_ctrl=control,
                                      untangle=body.get("untangle"))
        info = {"kind": "mesh", "path": str(path), **diag}
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
    return tbss, info


def threshold_targets(spec: dict, tpms_type: str, structure: str, raw: np.ndarray):
    """Map a discrete TDF onto thresholds (001: linearly into the valid range), or via a porosity range."""
    from .calibration import _checked_range, threshold_for_porosity
    from .grading.tdf import default_threshold_range, to_threshold_range
    if spec.get("threshold_range") is not None and spec.get("porosity_range") is not None:
        raise InputError("give a threshold range or a porosity range, not both")
    if spec.get("porosity_range") is not None:
        lo, hi = (float(x) for x in spec["porosity_range"])
        plo, phi = _checked_range(tpms_type, structure, "porosity")
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
    tlo, thi = _checked_range(tpms_type, structure, "threshold")
    for c in (lo, hi):
        if not tlo <= c <= thi:
            raise RangeError(f"threshold {c:g} is outside the valid range [{tlo:.3f}, {thi:.3f}] "
                             f"of {tpms_type} {structure}")
    return to_threshold_range(raw, lo, hi)


def build_tdf(spec: dict, tbss, tpms_type: str, structure: str):
    """Discrete TDF → thresholds → LSPIA-fitted scalar B-spline; returns ``(volume, info, discrete)``."""
    from .grading import tdf as tdfm
    from .splines.lspia import fit_grid
    t = time.perf_counter()
    method = str(spec.get("method", "layer"))
    shape = _ints3(spec.get("grid", 100), "TDF grid", lo=4)
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
    control = _ints3(spec.get("control", 20), "TDF control grid", lo=2)
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
    from .grading.tdf import function_values, grid_params
    from .splines.lspia import local_lspia
    shape = (grid, grid, grid)
    out = []
    for edit in edits:
        where = str(edit.get("where", ""))
        mask = function_values(where, shape, tbss) != 0
        if not mask.any():
            raise InputError(f"--edit region {where!r} contains no vertex of the {grid}^3 parametric grid")
        value = float(edit["threshold"])
        values = volume.evaluate_grid(*grid_params(shape))[..., 0]
        values[mask] = value
        edited = np.argwhere(mask)
        volume, moved, fit = local_lspia(volume, values, edited)
        out.append({"where": where, "threshold": value, "vertices": int(mask.sum()),
                    "moved_control_points": int(moved.sum()), "control_points": int(moved.size),
                    "iterations": int(fit.iterations), "rms": float(fit.rms), "max_error": float(fit.max_error)})
    return volume, out


def check_tdf_range(volume, tpms_type, structure, allow=False, samples=41) -> dict:
    """The fitted TDF's range on a dense sample; refuse values outside the valid threshold range."""
    from .calibration import _checked_range
    s = np.linspace(0.0, 1.0, samples)
    vals = volume.evaluate_grid(s, s, s)[..., 0]
    lo, hi = float(vals.min()), float(vals.max())
    tlo, thi = _checked_range(tpms_type, structure, "threshold")
    if not allow and (lo < tlo - 1e-9 or hi > thi + 1e-9):
        raise RangeError(f"the fitted TDF spans thresholds [{lo:.4g}, {hi:.4g}], outside the valid range "
                         f"[{tlo:.4g}, {thi:.4g}] of {tpms_type} {structure}; narrow the threshold range")
    return {"min": lo, "max": hi, "valid_range": [tlo, thi]}


def layer_porosity(tbss, tpms_type, structure, tdf_volume, periods, resolution, by, thresholds_by_layer,
                   threads=None) -> list[dict]:
    """Achieved porosity of every parametric layer (one slab of periods along ``by``) vs its target.

    Each layer's sub-box of the parameter cube is polygonised on the same
    samples as the whole scaffold, mapped, and its mesh volume compared with
    the TBSS volume of the sub-box (:meth:`porecad.splines.TBSS.volume`).
    The target is the porosity of the layer's threshold in the discrete TDF.
    """
    from .calibration import porosity_of_threshold
    from .maps.tbss import tbss_scaffold
    from .mesh.validate import signed_volume
    a = "uvw".index(by)
    n = len(thresholds_by_layer)
    out = []
    for k, c in enumerate(thresholds_by_layer):
        lo, hi = [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]
        lo[a], hi[a] = k / n, (k + 1) / n
        res = tbss_scaffold(tbss, tpms_type, structure, tdf_volume, periods, resolution, box=(lo, hi),
                            threads=threads)
        vol = float(signed_volume(res["vertices"], res["faces"]))
        total = tbss.volume(lo, hi)
        target = float(porosity_of_threshold(tpms_type, structure, float(c)))
        out.append({"layer": k, "threshold": float(c), "target_porosity": target,
                    "porosity": 1.0 - vol / total, "error": 1.0 - vol / total - target})
    return out


def run_tbss(recipe: dict, force: bool = False, progress=None, threads=None, check_intersections=False) -> dict:
    """Run a ``tbss`` recipe; write its outputs atomically; return the report."""
    from .fields.tpms import get_type
    from .io import write_mesh
    from .io.tdf import TDFRecord, read_tdf, write_tdf
    from .maps.tbss import boundary_band_intersections, check_periods, tbss_scaffold
    from .outputs import check_outputs, validated_report, write_report_output
    from .pipeline import _Stage
    from .solids import check_structure
    from .splines import TBSS, BSplineVolume

    t0 = time.perf_counter()
    out = dict(recipe.get("output", {}))
    check_outputs(out, ("mesh", "tdf", "report"), force)
    tdf_spec = dict(recipe.get("tdf", {}))
    resolution = int(recipe.get("mesh", {}).get("resolution", 16))
    allow = bool(recipe.get("tpms", {}).get("allow_closed_pores", False))
    timings = {}
    report = {"job": "tbss", "porecad_version": __version__}
    if tdf_spec.get("file"):
        t = time.perf_counter()
        rec = read_tdf(tdf_spec["file"])
        tpms_type, structure = get_type(rec.tpms_type).name, check_structure(rec.structure)
        periods = check_periods(rec.periods)
        tbss = TBSS(rec.tbss_control, rec.tbss_degrees, rec.tbss_knots, periodic=rec.tbss_periodic)
        jac = tbss.check_jacobian()
        tdf_volume = BSplineVolume(rec.tdf_control[..., None], rec.tdf_degrees, rec.tdf_knots)
        report["tdf"] = {"file": str(tdf_spec["file"]), "control": list(rec.tdf_control.shape)}
        report["tbss"] = {"kind": "tdf-file", "control_grid": list(rec.tbss_control.shape[:3]),
                          "min_jacobian": jac["min_det"]}
        timings["read_s"] = time.perf_counter() - t
        thresholds = None
    else:
        tp = dict(recipe.get("tpms", {}))
        tpms_type = get_type(str(tp.get("type", "G"))).name
        structure = check_structure(str(tp.get("structure", "sheet")))
        if structure == "surface":
            raise InputError("a TBSS scaffold needs a solid structure: pore, rod or sheet")
        periods = check_periods(tp.get("periods", (4, 4, 4)))
        if tdf_spec.get("method", "layer") == "layer" and tdf_spec.get("by", "w") in ("u", "v", "w"):
            tdf_spec.setdefault("layers", int(periods["uvw".index(tdf_spec.get("by", "w"))]))
        tbss, tinfo = build_tbss(dict(recipe.get("body", {})))
        timings["tbss_s"] = tinfo.pop("time_s")
        report["tbss"] = tinfo
        tdf_volume, dinfo, thresholds = build_tdf(tdf_spec, tbss, tpms_type, structure)
        timings["tdf_s"] = dinfo["discrete_s"] + dinfo["fit_s"]
        report["tdf"] = dinfo
    if tdf_spec.get("edits"):
        t = time.perf_counter()
        tdf_volume, report["tdf"]["edits"] = apply_edits(tdf_volume, tdf_spec["edits"], tbss,
                                                         int(tdf_spec.get("edit_grid", 100)))
        timings["edit_s"] = time.perf_counter() - t
    report["tdf"]["fitted_range"] = check_tdf_range(tdf_volume, tpms_type, structure, allow)
    requested = resolution
    for attempt in range(MAX_REFINEMENTS + 1):
        res = tbss_scaffold(tbss, tpms_type, structure, tdf_volume, periods, resolution, threads=threads,
                            progress=_Stage(progress)("mesh"))
        if check_intersections:  # the whole mesh (slivers can cross where the map is very anisotropic)
            from .mesh.validate import self_intersections
            crossings = int(self_intersections(res["vertices"], res["faces"])[1])
        else:
            crossings = boundary_band_intersections(res["vertices"], res["faces"], res["params"])
        if crossings == 0:
            break
        if attempt == MAX_REFINEMENTS:
            raise MeshError(f"the mapped scaffold intersects itself ({crossings} face pairs at resolution "
                            f"{resolution}); raise --resolution; nothing written")
        resolution = int(np.ceil(resolution * 1.5))
    if resolution != requested:
        report.setdefault("warnings", []).append(
            f"resolution raised from {requested} to {resolution}: at {requested} the flat boundary triangles "
            "mapped triangles crossed (flat boundary triangles where the TBSS bends the cube's faces, or "
            "slivers where it stretches strongly)")
    timings.update(res["timings"])
    vertices, faces = res["vertices"], res["faces"]
    t = time.perf_counter()
    total_volume = tbss.volume()
    # the loop above already searched the whole mesh for crossings when asked to
    mesh_rep, _ = validated_report(vertices, faces, total_volume, check_intersections=False, what="the mapped scaffold")
    report.update(mesh_rep)
    if check_intersections:
        report["self_intersections"] = crossings
    timings["validate_s"] = time.perf_counter() - t
    from .mesh.validate import signed_volume
    mesh_param = 1.0 - float(signed_volume(res["params"], faces))
    sample_param = 1.0 - res["inside_fraction"]
    if abs(mesh_param - sample_param) > 0.02 and not any(getattr(tbss, "periodic", ())):  # a seam opens it
        report.setdefault("warnings", []).append(
            f"the resolution is coarse for this structure's walls: parametric porosity {mesh_param:.3f} by mesh "
            f"volume but {sample_param:.3f} by samples; raise --resolution")
    report.update({"type": tpms_type, "structure": structure, "periods": periods.tolist(),
                   "resolution": resolution, "tbss_volume": total_volume,
                   "porosity_parametric": 1.0 - res["inside_fraction"]})
    dinfo = report["tdf"]
    if thresholds is not None and dinfo.get("method") == "layer" and dinfo.get("by") in ("u", "v", "w") \
            and recipe.get("analysis", {}).get("layers", True):
        from .grading.tdf import layer_index
        t = time.perf_counter()
        layer, n = layer_index(thresholds.shape, dinfo["by"], tdf_spec.get("layers"))
        per = [float(np.mean(thresholds[layer == k])) for k in range(n)]
        if n == int(periods["uvw".index(dinfo["by"])]):
            report["layers"] = layer_porosity(tbss, tpms_type, structure, tdf_volume, periods, resolution,
                                              dinfo["by"], per, threads)
        timings["layers_s"] = time.perf_counter() - t
    if out.get("mesh"):
        t = time.perf_counter()
        write_mesh(out["mesh"], vertices, faces, force=force)
        timings["write_s"] = time.perf_counter() - t
        report["mesh_file"] = str(out["mesh"])
    if out.get("tdf"):
        vol = tdf_volume
        rec = TDFRecord(version=1, tpms_type=tpms_type, structure=structure, periods=tuple(float(p) for p in periods),
                        tdf_degrees=tuple(vol.degrees), tdf_knots=tuple(vol.knots), tdf_control=vol.control[..., 0],
                        tbss_degrees=tuple(tbss.degrees), tbss_knots=tuple(tbss.knots), tbss_control=tbss.control,
                        tbss_periodic=tuple(bool(p) for p in tbss.periodic))
        write_tdf(out["tdf"], rec, force=force)
        report["tdf_file"] = str(out["tdf"])
    timings["total_s"] = time.perf_counter() - t0
    report["timings"] = timings
    if out.get("report"):
        fr = report["tdf"]["fitted_range"]
        design = {"type": tpms_type, "structure": structure, "threshold_min": fr["min"], "threshold_max": fr["max"]}
        write_report_output(out["report"], report, vertices, faces, domain_volume=total_volume, design=design,
                            force=force)
    return report
