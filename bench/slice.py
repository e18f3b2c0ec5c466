"""Benchmark of ``porecad slice`` (issue 40): field route against the mesh route, time and peak memory.

    python bench/slice.py cube [--size 20] [--pixel 0.025]        # the gyroid-sheet cube, both routes
    python bench/slice.py femur [--pixel 0.05] [--layers N]        # the femur infill (5 mm cells), field route
    python bench/slice.py femur --layers N --at F --compare /tmp/oldsrc  # the same with another source tree
                                                                   # (issue 54: old vs new, side by side)

Each measurement runs in a fresh process (peak memory = its max RSS). The field route slices the
recipe to a PNG ZIP (no printability checks: their time is reported apart); the mesh route is what a
user does today: ``porecad build`` at the same sampling, then a trimesh section of every layer.
Areas are checked from the written PNGs (Pillow) against the mesh sections (shapely).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
FEMUR = HERE.parent.parent / "shared" / "data" / "femur.stl"


def cube_recipe(size, cell, voxel, d):
    return {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": cell},
            "domain": {"kind": "box", "cells": [int(size / cell)] * 3}, "sampling": {"voxel": voxel},
            "output": {"mesh": str(Path(d) / "cube.stl")}}


def femur_recipe(voxel, d):
    return {"job": "infill", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": 5.0},
            "domain": {"kind": "mesh", "path": str(FEMUR)},  # the job's default voxel (calibration, mesh)
            "output": {"mesh": str(Path(d) / "femur.stl")}}


def cpu_seconds() -> float:
    """User + system CPU seconds of this process (all its threads) so far."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def child(kind, recipe, out, pixel, layer, layers, at=0.5):
    """Run one measurement in this process; print a JSON line."""
    t = time.perf_counter()
    if kind == "field":
        from porecad.printing import Printer, from_source, slice_to
        from porecad.printing.raster import LayerGrid
        part = from_source(recipe, Path(out).parent)
        t_plan = time.perf_counter() - t
        if layers:  # a band of the part's layers at the fraction ``at`` of its height (the femur: memory is per band)
            mid = part.lo[2] + at * (part.hi[2] - part.lo[2])
            part.lo[2], part.hi[2] = mid - layers * layer / 2, mid + layers * layer / 2
        grid = LayerGrid.around(part.lo, part.hi, pixel, layer)
        c0 = cpu_seconds()
        r = slice_to(part, out, Printer(build=(1e4, 1e4, 1e4)), pixel=pixel, layer=layer, check=False)
        res = {"seconds": time.perf_counter() - t, "plan_s": t_plan, "slice_s": r["seconds_slices"],
               "slice_cpu_s": cpu_seconds() - c0, "body": type(getattr(part.field, "b", None)).__name__,
               "area_mm3": sum(r["layer_area"]) * layer,
               "layers": r["layers"], "image": r["image"], "pixels": grid.nx * grid.ny * grid.n_layers,
               "bytes": os.path.getsize(out)}
    else:
        import numpy as np
        from porecad.jobs import run_recipe
        run_recipe(recipe, force=True)
        t_mesh = time.perf_counter() - t
        import trimesh
        m = trimesh.load(recipe["output"]["mesh"])
        lo, hi = m.bounds
        zs = lo[2] + (np.arange(int(round((hi[2] - lo[2]) / layer))) + 0.5) * layer
        secs = m.section_multiplane(plane_origin=[0, 0, 0], plane_normal=[0, 0, 1], heights=list(zs))
        res = {"seconds": time.perf_counter() - t, "mesh_s": t_mesh, "layers": len(secs),
               "triangles": len(m.faces), "stl_bytes": os.path.getsize(recipe["output"]["mesh"])}
    res["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(res))


def measure(kind, recipe, out, pixel, layer, layers=0, at=0.5, src=None):
    env = dict(os.environ, PYTHONPATH=str(src or HERE.parent / "src"))
    cmd = [sys.executable, __file__, "--child", kind, json.dumps(recipe), str(out), str(pixel), str(layer),
           str(layers), str(at)]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def main():
    if sys.argv[1:2] == ["--child"]:
        kind, recipe, out, pixel, layer, layers, at = sys.argv[2:9]
        return child(kind, json.loads(recipe), out, float(pixel), float(layer), int(layers), float(at))
    ap = argparse.ArgumentParser()
    ap.add_argument("case", choices=["cube", "femur"])
    ap.add_argument("--size", type=float, default=20.0)
    ap.add_argument("--cell", type=float, default=2.5)
    ap.add_argument("--pixel", type=float, default=None)
    ap.add_argument("--layers", type=int, default=0, help="femur: slice this many layers from the middle")
    ap.add_argument("--at", type=float, default=0.5, help="femur: where the layers are, a fraction of the height")
    ap.add_argument("--compare", default=None, help="femur: also slice with this source tree (the old code)")
    ap.add_argument("--mesh-route", action="store_true", help="cube: also the mesh route at the same sampling")
    a = ap.parse_args()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as d:
        if a.case == "cube":
            px = a.pixel or 0.025
            recipe = cube_recipe(a.size, a.cell, px, d)
            res = {"case": f"gyroid sheet cube {a.size:g} mm, {a.cell:g} mm cells, {px * 1000:g} µm pixels and layers",
                   "field": measure("field", recipe, Path(d) / "cube.zip", px, px)}
            if a.mesh_route:
                res["mesh"] = measure("mesh", recipe, None, px, px)
                res["ratio"] = res["mesh"]["seconds"] / res["field"]["seconds"]
        else:
            px = a.pixel or 0.05
            res = {"case": f"femur infill, G sheet 5 mm cells, {px * 1000:g} µm pixels and layers",
                   "field": measure("field", femur_recipe(px, d), Path(d) / "femur.zip", px, px, a.layers, a.at)}
            if a.compare:
                res["compared"] = measure("field", femur_recipe(px, d), Path(d) / "old.zip", px, px, a.layers, a.at,
                                          src=a.compare)
        for f in (res["field"], res.get("compared")):
            if f is not None:
                f["pixels_per_s"] = f["pixels"] / f["slice_s"]
                if "slice_cpu_s" in f:
                    f["pixels_per_cpu_s"] = f["pixels"] / f["slice_cpu_s"]
        if "compared" in res:
            res["speedup_wall"] = res["field"]["pixels_per_s"] / res["compared"]["pixels_per_s"]
            res["speedup_cpu"] = res["field"]["pixels_per_cpu_s"] / res["compared"]["pixels_per_cpu_s"]
    res["load_average"] = {"before": [round(x, 2) for x in load0], "after": [round(x, 2) for x in os.getloadavg()]}
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
