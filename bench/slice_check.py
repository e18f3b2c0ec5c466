"""Slices against the job's own mesh (issue 40, acceptance 1) for the demo disc and the femur infill.

    python bench/slice_check.py disc|femur [--pixel 0.05] [--bands 4] [--band-layers 5]
    python bench/slice_check.py femur --voxel 0.1 --slab 10 --at 0.3

Runs the job in memory (its mesh, after the body calibration and the mesh passes that correct its
porosity), slices the recipe from its field into PNG ZIPs for a few bands of layers spread over the
height, and compares each layer's solid area read back with Pillow (sum of grey / 255 x pixel²) with
the area of the job mesh's section at the same z (trimesh section, even-odd rings in shapely).
Prints one JSON object; bench/slice.md keeps the results.

``--slab H --at F`` (a body too large to mesh whole at a fine voxel): the job is planned and
calibrated on the whole body exactly as it runs (:func:`plan_lattice`, then :func:`hold_porosity`
with the job's regions), and the field its first mesh pass meshes is meshed by the job's mesher
(``polygonise``, capped, the job's chunk size) on the job's own grid restricted to the planes of a
slab H mm high centred at the fraction F of the body's height; every layer of the slab that lies more
than one voxel from the slab's cut faces is compared with that mesh's section. The job's further mesh
passes (taken when the porosity of its whole mesh misses the target by more than 0.004) cannot be
replayed on a slab; the layers' mean signed difference measures that miss (x the solid fraction).
"""

from __future__ import annotations

import argparse
import functools
import gc
import io
import json
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))


def section_area(mesh, z):
    from shapely.geometry import Polygon
    s = mesh.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1])
    if s is None:
        return 0.0
    polys = [Polygon(d[:, :2]).buffer(0) for d in s.discrete if len(d) >= 4]
    return functools.reduce(lambda a, b: a.symmetric_difference(b), polys).area if polys else 0.0


def recipe_of(case):
    from porecad.jobs.tpms_job import demo_recipe
    if case == "disc":
        r = demo_recipe("/nonexistent")
        r.pop("output")
        return r
    femur = HERE.parent.parent / "shared" / "data" / "femur.stl"
    return {"job": "infill", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": 5.0},
            "domain": {"kind": "mesh", "path": str(femur)}}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("case", choices=["disc", "femur"])
    ap.add_argument("--pixel", type=float, default=0.05)
    ap.add_argument("--bands", type=int, default=4)
    ap.add_argument("--band-layers", type=int, default=5)
    ap.add_argument("--voxel", type=float, default=None, help="the job's sampling voxel (default: the recipe's)")
    ap.add_argument("--fine", type=float, default=0.04, help="voxel of the fine mesh of each band (mm)")
    ap.add_argument("--slab", type=float, default=None, help="mesh only a slab this high (mm) of the job's grid")
    ap.add_argument("--at", type=float, default=0.5, help="the slab's centre as a fraction of the body's height")
    a = ap.parse_args()
    if a.slab:
        return slab_check(a, recipe_of(a.case))
    import trimesh
    from PIL import Image

    from porecad.jobs.runner import parse, run_job
    from porecad.printing import Printer, from_source, slice_to
    recipe = recipe_of(a.case)
    if a.voxel:
        recipe["sampling"] = {"voxel": a.voxel}
    t = time.perf_counter()
    job, spec, _, _ = parse(recipe)
    result = run_job(job, spec)
    mesh = trimesh.Trimesh(result.vertices, result.faces, process=False)
    t_job = time.perf_counter() - t
    part = from_source(recipe)
    lo, hi = part.lo.copy(), part.hi.copy()
    from porecad.mesh.polygonise import Grid, polygonise
    errs, rows, fine_errs = [], [], []
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        for b in range(a.bands):
            z0 = lo[2] + (b + 0.5) / a.bands * (hi[2] - lo[2])
            part.lo[2], part.hi[2] = z0, z0 + a.band_layers * a.pixel
            out = Path(d) / f"b{b}.zip"
            pad = 4 * a.fine  # a fine mesh of the same field around the band (its caps lie outside the layers)
            fgrid = Grid.from_box([lo[0] - pad, lo[1] - pad, part.lo[2] - pad], [hi[0] + pad, hi[1] + pad,
                                  part.hi[2] + pad], spacing=a.fine)
            res = polygonise(part.field.sample_grid, fgrid, caps=True)
            fine = trimesh.Trimesh(res.vertices, res.faces, process=False)
            slice_to(part, out, Printer(build=(1e4, 1e4, 1e4)), pixel=a.pixel, layer=a.pixel, check=False)
            with zipfile.ZipFile(out) as z:
                man = json.loads(z.read("manifest.json"))
                for k in range(man["layer_count"]):
                    g = np.asarray(Image.open(io.BytesIO(z.read(f"layers/{k:05d}.png"))), dtype=float)
                    area = g.sum() / 255 * a.pixel ** 2
                    zk = man["origin"][2] + (k + 0.5) * man["layer_height"]
                    ref = section_area(mesh, zk)
                    ref_fine = section_area(fine, zk)
                    if ref > 1.0:
                        errs.append((area - ref) / ref)
                        fine_errs.append((area - ref_fine) / ref_fine)
                        rows.append({"z": round(zk, 4), "png_mm2": round(area, 4), "job_mesh_mm2": round(ref, 4),
                                     "fine_mesh_mm2": round(ref_fine, 4)})
    e = np.abs(np.asarray(errs))
    print(json.dumps({"case": a.case, "pixel": a.pixel, "job_voxel": a.voxel or "recipe's", "job_s": round(t_job, 1), "mesh_triangles": len(mesh.faces),
                      "slice_and_compare_s": round(time.perf_counter() - t, 1), "layers_compared": len(errs),
                      "max_rel_err": float(e.max()), "median_rel_err": float(np.median(e)),
                      "mean_signed_err": float(np.mean(errs)), "fine_voxel": a.fine,
                      "fine_max_rel_err": float(np.max(np.abs(fine_errs))),
                      "fine_median_rel_err": float(np.median(np.abs(fine_errs))), "calibration": result.report.get("calibration")
                      or (result.report.get("threshold_info") or {}).get("calibration"), "layers": rows[:6]},
                     indent=1, default=str))


def maxrss_mb():
    import resource
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)


def slab_check(a, recipe):
    """Slices of a slab of the body against the job's mesh of the same slab (see the module docstring)."""
    import trimesh
    from PIL import Image

    from porecad.lattice.plan import hold_porosity, plan_lattice
    from porecad.jobs.runner import parse
    from porecad.jobs.tpms_job import CHUNK_BYTES, regions_wanted
    from porecad.mesh.polygonise import Grid, default_threads, polygonise
    from porecad.mesh.validate import stored_coordinates
    from porecad.printing import Printer, from_source, slice_to
    if a.voxel:
        recipe["sampling"] = {"voxel": a.voxel}
    t = time.perf_counter()
    _, spec, _, _ = parse(recipe)
    plan = plan_lattice(spec)  # the job's plan and calibration, as tpms_job.run makes them
    n_regions, axis = regions_wanted(spec, plan, calibrating=True)
    hold_porosity(plan, n_regions, axis, allow=spec.tpms["allow_closed_pores"])
    t_plan = time.perf_counter() - t
    peak = {"plan_and_calibrate": maxrss_mb()}
    grid = plan.grid
    blo, bhi = (np.asarray(b, float) for b in plan.body.bounds)
    zc = blo[2] + a.at * (bhi[2] - blo[2])
    hz = grid.spacing[2]
    k0 = max(int(np.floor((zc - a.slab / 2 - grid.origin[2]) / hz)), 0)
    k1 = min(int(np.ceil((zc + a.slab / 2 - grid.origin[2]) / hz)), grid.shape[2] - 1)
    sub = Grid((grid.origin[0], grid.origin[1], grid.origin[2] + k0 * hz), grid.spacing,
               (grid.shape[0], grid.shape[1], k1 - k0 + 1))  # the job's own sample planes k0..k1
    t = time.perf_counter()
    res = polygonise(plan.field.sample_grid, sub, caps=plan.closed, chunk_bytes=CHUNK_BYTES,
                     threads=default_threads())
    mesh = trimesh.Trimesh(stored_coordinates(res.vertices), res.faces, process=False)
    t_mesh = time.perf_counter() - t
    peak["slab_mesh"] = maxrss_mb()
    xs, ys = sub.axis(0)[::8], sub.axis(1)[::8]  # the job's field against the slicer's, on the slab's middle plane
    zm = sub.axis(2)[sub.shape[2] // 2:sub.shape[2] // 2 + 1]
    job_plane = np.asarray(plan.field.sample_grid(xs, ys, zm), float)
    cal = plan.threshold_info.get("calibration") or {}
    threshold = plan.threshold_info.get("threshold")
    del plan, res  # a mesh body's distance bins at a fine voxel are large: one plan at a time
    gc.collect()
    t = time.perf_counter()
    part = from_source(recipe)  # the slicer's own plan of the recipe (its calibration is run again)
    t_part = time.perf_counter() - t
    peak["slicer_plan"] = maxrss_mb()
    z_lo, z_hi = sub.box_min[2], sub.box_max[2]
    part.lo[2], part.hi[2] = z_lo, z_hi
    errs, rows = [], []
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "slab.zip"
        slice_to(part, out, Printer(build=(1e4, 1e4, 1e4)), pixel=a.pixel, layer=a.pixel, check=False)
        t_slice = time.perf_counter() - t
        peak["slice"] = maxrss_mb()
        t = time.perf_counter()
        with zipfile.ZipFile(out) as z:
            man = json.loads(z.read("manifest.json"))
            for k in range(man["layer_count"]):
                zk = man["origin"][2] + (k + 0.5) * man["layer_height"]
                if not z_lo + hz < zk < z_hi - hz:
                    continue  # within one voxel of the slab's cut faces (the caps)
                g = np.asarray(Image.open(io.BytesIO(z.read(f"layers/{k:05d}.png"))), dtype=float)
                area = g.sum() / 255 * a.pixel ** 2
                ref = section_area(mesh, zk)
                if ref > 1.0:
                    errs.append((area - ref) / ref)
                    rows.append({"z": round(zk, 4), "png_mm2": round(area, 4), "job_mesh_mm2": round(ref, 4)})
    t_compare = time.perf_counter() - t
    field_diff = float(np.max(np.abs(job_plane - np.asarray(part.field.sample_grid(xs, ys, zm), float))))
    e = np.abs(np.asarray(errs))
    worst = int(np.argmax(e))
    print(json.dumps({
        "case": a.case, "pixel": a.pixel, "job_voxel": list(grid.spacing), "job_grid": list(grid.shape),
        "slab_mm": [float(z_lo), float(z_hi)], "slab_planes": [k0, k1], "at": a.at,
        "mesh_triangles": len(mesh.faces), "plan_and_calibrate_s": round(t_plan, 1), "slab_mesh_s": round(t_mesh, 1),
        "slicer_plan_s": round(t_part, 1), "slice_s": round(t_slice, 1), "compare_s": round(t_compare, 1),
        "peak_mb": maxrss_mb(), "peak_mb_after": peak,
        "layers_compared": len(errs), "max_rel_err": float(e.max()), "median_rel_err": float(np.median(e)),
        "mean_signed_err": float(np.mean(errs)), "worst": rows[worst],
        "field_max_abs_diff": field_diff,
        "calibration": {k: cal.get(k) for k in ("requested", "sample_porosity", "lattice_porosity", "mesh_bias")},
        "threshold": threshold, "layers": rows[:3]}, indent=1, default=str))


if __name__ == "__main__":
    main()
