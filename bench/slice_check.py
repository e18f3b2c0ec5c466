"""Slices against the job's own mesh (issue 40, acceptance 1) for the demo disc and the femur infill.

    python bench/slice_check.py disc|femur [--pixel 0.05] [--bands 4] [--band-layers 5]

Runs the job in memory (its mesh, after the body calibration and the mesh passes that correct its
porosity), slices the recipe from its field into PNG ZIPs for a few bands of layers spread over the
height, and compares each layer's solid area read back with Pillow (sum of grey / 255 x pixel²) with
the area of the job mesh's section at the same z (trimesh section, even-odd rings in shapely).
Prints one JSON object; bench/slice.md keeps the results.
"""

from __future__ import annotations

import argparse
import functools
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
    a = ap.parse_args()
    import trimesh
    from PIL import Image

    from porecad.jobs.runner import parse
    from porecad.printing import Printer, from_source, slice_to
    recipe = recipe_of(a.case)
    if a.voxel:
        recipe["sampling"] = {"voxel": a.voxel}
    t = time.perf_counter()
    job, spec, _, _ = parse(recipe)
    result = job.run(spec)
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


if __name__ == "__main__":
    main()
