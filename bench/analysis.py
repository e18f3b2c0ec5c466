"""Analysis times, memory and accuracy beside PoreSpy on the same voxel images (issue 22).

    python bench/analysis.py                       # cube and gyroid cases
    python bench/analysis.py --femur MESH.stl      # also a body scaffold (domain: ../shared/data/femur.stl)
    python bench/analysis.py --femur MESH.stl --skin 1.0

Cases (each in a fresh process after one warm-up run, so numba compiles are
not timed; peak memory is the process's maximum resident set):

* ``cube``: a 10 mm cube with six straight 2 mm channels and a closed 2 mm
  sphere (manifold3d, 96-gons): every pore is 1.9989 mm across.
* ``gyroid``: G sheet, porosity 0.6, cell 1 mm, 3x3x3 cells, the central
  cell as a window; wall thickness from ``tests/thickness_reference.py``
  (mean 0.13734, d50 0.13920, max 0.14331 mm).
* ``femur``: a body scaffold (``porecad infill femur.stl G --porosity 0.7
  --voxel 0.5``: 3.46 M triangles) in the femur body.

PoreSpy (``porespy.filters.local_thickness``, method ``dt``) runs on the very
voxel image porecad measured (for a sampled body, on one sample block), so
the difference is the method, not the sampling. The machine is shared:
times are wall clock under whatever load there is.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FEMUR = HERE.parents[1] / "shared" / "data" / "femur.stl"
GYROID_REF = {"mean": 0.13734, "d50": 0.13920, "max": 0.14331}


def _cube():
    sys.path.insert(0, str(HERE.parent / "tests"))
    from test_thickness import channel_cube
    (v, f), _ = channel_cube(2.0)
    return v, f, None, 2.0 * np.cos(np.pi / 96)


def _gyroid():
    import tempfile

    from porecad.analysis.domain import BoxDomain
    from porecad.cli import main
    from porecad.io import read_mesh
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "g.stl")
        main(["tpms", "G", "--structure", "sheet", "--threshold", "0.6151071190834045", "--cells", "3", "3", "3",
              "--cell-size", "1", "--resolution", "30", "-o", out])
        v, f = read_mesh(out)
    return v, f, BoxDomain([1, 1, 1], [2, 2, 2]), None


def _porespy(fields, phase):
    import porespy
    im = fields["domain"] & (fields["solid"] if phase == "strut" else ~fields["solid"])
    t = time.perf_counter()
    lt = porespy.filters.local_thickness(im, method="dt")
    dt = time.perf_counter() - t
    d = 2.0 * lt[im] * fields["spacing"]
    return {"time_s": round(dt, 2), "mean": float(d.mean()), "d50": float(np.median(d)), "max": float(d.max()),
            "voxels": int(im.size)}


def run_case(name, mesh=None, skin=None):
    """One case in this process: warm-up, timed analysis, PoreSpy on the same image. Prints one JSON line."""
    from porecad.analysis.pores import pore_analysis
    from porecad.io import read_mesh
    if name == "cube":
        v, f, dom, true = _cube()
    elif name == "gyroid":
        v, f, dom, true = _gyroid()
    else:
        v, f = read_mesh(mesh)
        dom, true = read_mesh(FEMUR), None
    # warm-up (compiles, first-touch) on a small mesh
    wv, wf, _, _ = _cube()
    pore_analysis(wv, wf, spacing=0.5)
    t = time.perf_counter()
    rep = pore_analysis(v, f, domain=dom, skin=skin, keep_fields=True)
    dt = time.perf_counter() - t
    fields = rep.pop("_fields")
    out = {"case": name, "triangles": int(len(f)), "time_s": round(dt, 2), "voxel": rep["voxel"],
           "sampling": rep["size_sampling"]}
    for key in ("porosity_voxel", "pore_size_mean", "pore_size_d50", "pore_size_max", "strut_size_mean",
                "strut_size_d50", "strut_size_max", "open_pore_fraction", "closed_pores", "closed_pore_volume",
                "closed_by_skin", "lattice_open_pore_fraction"):
        if key in rep:
            out[key] = rep[key]
    if name == "femur":
        from porecad.mesh.validate import signed_volume
        out["porosity_mesh"] = 1.0 - float(signed_volume(v, f)) / float(signed_volume(*dom))
    if true is not None:
        out["pore_truth"] = true
    if name == "gyroid":
        out["strut_reference"] = GYROID_REF
    try:
        out["porespy_pore"] = _porespy(fields, "pore")
        if name != "cube":
            out["porespy_strut"] = _porespy(fields, "strut")
    except ImportError:
        out["porespy"] = "not installed (pip install porespy)"
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)
    print(json.dumps(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=["cube", "gyroid", "femur"])
    ap.add_argument("--femur", help="a body scaffold mesh inside ../shared/data/femur.stl")
    ap.add_argument("--skin", type=float)
    a = ap.parse_args()
    if a.case:
        run_case(a.case, a.femur, a.skin)
        return
    cases = ["cube", "gyroid"] + (["femur"] if a.femur else [])
    for c in cases:
        cmd = [sys.executable, __file__, "--case", c]
        if c == "femur":
            cmd += ["--femur", a.femur] + (["--skin", str(a.skin)] if a.skin else [])
        res = subprocess.run(cmd, capture_output=True, text=True)
        line = [x for x in res.stdout.splitlines() if x.startswith("{")]
        print(line[-1] if line else f'{{"case": "{c}", "error": {json.dumps(res.stderr[-500:])}}}', flush=True)


if __name__ == "__main__":
    main()
