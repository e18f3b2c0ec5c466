"""Simulation benchmarks and validation (issue 23): stiffness, permeability, volume meshes.

Run ``python bench/simulate.py [--parts stiffness,permeability,spheres,convergence,fecheck,sweep,volmesh]
[--json]``. Each timed job runs in its own subprocess (peak memory = its ru_maxrss; numba kernels
are cached on disk after the first run, so times exclude compilation). Numbers on a shared 2-core
machine are inflated by the load of other processes: the load average is printed with each job.

* ``stiffness``: homogenised stiffness of a gyroid sheet cell (60 % porosity) at 64^3 and 128^3
  voxels (goal: under 60 s and 10 min, under 4 GB).
* ``permeability``: full permeability tensor of the same cell at 64^3.
* ``spheres``: simple cubic arrays of spheres against Zick & Homsy (1982) Table 2 at 48^3 and 64^3.
* ``convergence``: gyroid sheet at 60 % porosity, k_xx at 24, 32, 48, 64, 96 voxels per cell.
* ``fecheck``: gyroid and Schwarz P sheets at porosities 0.5, 0.6, 0.7: voxel FE (64^3) against
  scikit-fem on a periodic quadratic tet mesh (P2, CG + pyamg), C11, C12, C44 and times.
* ``sweep``: porosity sweeps of gyroid and P sheets (48^3) with the Gibson-Ashby fit beside the
  published exponents (Gibson & Ashby 1997 eq. 5.6; Deshpande, Ashby & Fleck 2001).
* ``volmesh``: tet meshes of a gyroid sheet cell, the femur infill (5 mm gyroid cells, 60 % porosity,
  6.9 M triangles, meshed at 1.25 mm) and a TBSS disc scaffold: quality distribution, volume error,
  meshio round trip. Measured figures: ``bench/simulate-volmesh.md``; the other parts:
  ``bench/simulate-results.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ZICK_HOMSY_SC = {0.027: 2.008, 0.064: 2.810, 0.125: 4.292, 0.216: 7.442, 0.343: 15.4}


def gyroid(porosity=0.6, ttype="G"):
    return {"job": "tpms", "tpms": {"type": ttype, "structure": "sheet", "porosity": porosity, "cell_size": 1.0},
            "domain": {"kind": "box", "cells": [1, 1, 1]}, "sampling": {"resolution": 40}}


def _rss_mb():
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def job_stiffness(n, ttype="G", porosity=0.6):
    from porecad.simulate.cell_voxels import recipe_cell_voxels
    from porecad.simulate.homogenise import homogenise_stiffness
    solid, h, _ = recipe_cell_voxels(gyroid(porosity, ttype), n)
    t = time.perf_counter()
    out = homogenise_stiffness(np.where(solid, 0, -1).astype(np.int32), h, [(1.0, 0.3)])
    return {"voxels": n, "time_s": time.perf_counter() - t, "iterations": out["iterations"],
            "levels": out["levels"], "C11": out["C"][0][0], "C12": out["C"][0][1], "C44": out["C"][3][3],
            "solid_fraction": out["solid_fraction"], "estimate_mb": out["estimate_bytes"] / 2**20,
            "peak_rss_mb": _rss_mb()}


def job_permeability(n, directions=(0, 1, 2)):
    from porecad.simulate.cell_voxels import recipe_cell_voxels
    from porecad.simulate.stokes import stokes_permeability
    solid, h, _ = recipe_cell_voxels(gyroid(), n)
    t = time.perf_counter()
    out = stokes_permeability(~solid, h, directions=list(directions))
    return {"voxels": n, "time_s": time.perf_counter() - t, "k_mm2": out["permeability_mm2"],
            "tortuosity": out["tortuosity"], "iterations": out["iterations"], "porosity": out["porosity"],
            "unknowns": out["unknowns"], "peak_rss_mb": _rss_mb()}


def job_sphere(n, c):
    from porecad.simulate.stokes import stokes_permeability
    a = n * (3 * c / (4 * np.pi)) ** (1 / 3)
    z, y, x = np.mgrid[0:n, 0:n, 0:n] + 0.5 - n / 2
    solid = x * x + y * y + z * z <= a * a
    t = time.perf_counter()
    out = stokes_permeability(~solid, 1.0, directions=[0])
    k = out["permeability_mm2"][0][0]
    K = n ** 3 / (6 * np.pi * a * k)
    return {"voxels": n, "c": c, "c_voxel": float(solid.mean()), "K": K, "K_zick_homsy": ZICK_HOMSY_SC[c],
            "error": K / ZICK_HOMSY_SC[c] - 1, "time_s": time.perf_counter() - t}


def job_fecheck(ttype, porosity, voxels=64, size=1 / 20):
    from porecad.pipeline import plan_tpms
    from porecad.simulate.tet_homogenise import tet_homogenise_stiffness
    from porecad.simulate.tetmesh_solid import periodic_volume_mesh
    vox = job_stiffness(voxels, ttype, porosity)
    plan = plan_tpms(gyroid(porosity, ttype))
    t = time.perf_counter()
    m = periodic_volume_mesh(plan.field, np.zeros(3), np.ones(3), size)
    tm = time.perf_counter() - t
    r = tet_homogenise_stiffness(m["points"], m["tets"], np.zeros(3), np.ones(3), 1.0, 0.3, order=2,
                                 direct_limit=0)
    C = r["C"]
    return {"type": ttype, "porosity": porosity, "voxel": vox,
            "skfem": {"C11": C[0][0], "C12": C[0][1], "C44": C[3][3], "dofs": r["dofs"], "tets": len(m["tets"]),
                      "solid_fraction": r["solid_fraction"], "mesh_s": tm, "solve_s": r["time_s"],
                      "solver": r["solver"]},
            "diff": {k: vox[k] / v - 1 for k, v in (("C11", C[0][0]), ("C12", C[0][1]), ("C44", C[3][3]))},
            "peak_rss_mb": _rss_mb()}


def job_sweep(ttype, voxels=48):
    from porecad.simulate.properties import porosity_sweep
    t = time.perf_counter()
    out = porosity_sweep(gyroid(0.6, ttype), [0.5, 0.6, 0.7, 0.8], voxels, 1.0, 0.3)
    out["time_s"] = time.perf_counter() - t
    return out


def job_volmesh(which):
    import tempfile

    import meshio

    from porecad.io import read_mesh
    from porecad.simulate.tetmesh_solid import volume_mesh, write_volume_mesh
    with tempfile.TemporaryDirectory() as tmp:
        stl = os.path.join(tmp, "s.stl")
        t = time.perf_counter()
        if which == "gyroid":
            from porecad.pipeline import run_recipe
            rec = gyroid()
            rec["output"] = {"mesh": stl}
            run_recipe(rec)
        elif which == "femur":
            here = os.path.dirname(os.path.abspath(__file__))
            cands = [os.path.join(here, "..", "..", "shared", "data", "femur.stl"),
                     os.path.join(here, "..", "..", "..", "shared", "data", "femur.stl")]
            femur = next((c for c in cands if os.path.exists(c)), cands[0])
            from porecad.cli import main
            # 5 mm gyroid cells at 60 % porosity at the default sampling (about 6.9 million triangles);
            # the volume mesh coarsens it by quadric decimation first (simulate.surface_coarsen)
            if main(["infill", femur, "G", "--porosity", "0.6", "--cell-size", "5", "-o", stl]):
                raise SystemExit("femur infill failed")
        else:
            from porecad.cli import main
            main(["tbss", "disc", "G", "--structure", "sheet", "--periods", "3", "3", "2", "--resolution", "12",
                  "-o", stl])
        build_s = time.perf_counter() - t
        v, f = read_mesh(stl)
        t = time.perf_counter()
        # the femur infill is meshed at 1.25 mm (its solid channels are about 2 mm across)
        m = volume_mesh(v, f, size=1.25 if which == "femur" else None)
        mesh_s = time.perf_counter() - t
        out = os.path.join(tmp, "m.vtu")
        write_volume_mesh(out, m["points"], m["cells"], m["cell_type"])
        loaded = len(meshio.read(out).cells_dict["tetra"])
    return {"which": which, "surface_triangles": int(len(f)), "build_s": build_s, "mesh_s": mesh_s,
            "quality": m["quality"], "volume_error": m["volume_error"], "surface": m["surface"],
            "sliver_repair": m["sliver_repair"], "meshio_tets": loaded, "peak_rss_mb": _rss_mb()}


JOBS = {"stiffness": job_stiffness, "permeability": job_permeability, "sphere": job_sphere,
        "fecheck": job_fecheck, "sweep": job_sweep, "volmesh": job_volmesh}


def run_child(name, *args, timeout=3000):
    cmd = [sys.executable, __file__, "--child", json.dumps([name, list(args)])]
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if r.returncode != 0:
        return {"job": name, "args": list(args), "error": (r.stderr.strip().splitlines() or ["?"])[-1]}
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out.update({"job": name, "args": list(args), "wall_s": time.perf_counter() - t,
                "load_average": os.getloadavg()[0]})
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="stiffness,permeability,spheres,convergence,fecheck,sweep,volmesh")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--child")
    a = ap.parse_args()
    if a.child:
        name, args = json.loads(a.child)
        print(json.dumps(JOBS[name](*args), default=float))
        return
    parts = a.parts.split(",")
    results = []

    def emit(r):
        results.append(r)
        if not a.json:
            print(json.dumps(r, default=float), flush=True)

    if "stiffness" in parts:
        for n in (64, 128):
            emit(run_child("stiffness", n))
    if "permeability" in parts:
        emit(run_child("permeability", 64))
    if "spheres" in parts:
        for n in (48, 64):
            for c in (0.064, 0.125, 0.216, 0.343):
                emit(run_child("sphere", n, c))
    if "convergence" in parts:
        for n in (24, 32, 48, 64, 96):
            emit(run_child("permeability", n, [0]))
    if "fecheck" in parts:
        for ttype in ("G", "P"):
            for p in (0.5, 0.6, 0.7):
                emit(run_child("fecheck", ttype, p))
    if "sweep" in parts:
        for ttype in ("G", "P"):
            emit(run_child("sweep", ttype))
    if "volmesh" in parts:
        for which in ("gyroid", "tbss", "femur"):
            emit(run_child("volmesh", which))
    if a.json:
        print(json.dumps(results, default=float))


if __name__ == "__main__":
    main()
