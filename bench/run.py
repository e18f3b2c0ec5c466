"""Benchmarks: porecad against a plain numpy + scikit-image pipeline (and microgen) on the same jobs.

Run ``python bench/run.py [--repeat N] [--jobs P500,G4x128,G4x64] [--tools porecad] [--json]``
(best of N runs per tool). Each job runs in its own subprocess so
that peak memory (ru_maxrss) is measured per job; porecad's time includes
writing the binary STL and excludes one-off JIT compilation (cached on disk
after the first run). Jobs (issue 2, acceptance 7):

* ``P500``: the P surface of one period at 500^3 samples (002 Table 5's
  largest job: 18.5 s, 1,882,376 triangles there);
* ``G4x128``: a gyroid sheet |φ| ≤ 0.3 of 4x4x4 cells at 128 samples per cell
  (microgen runs out of memory on this job: killed at 24 GiB; the bench caps
  each job at 16 GiB);
* ``G4x64``: the same at 64 samples per cell, where microgen finishes;
* ``analyze2M``: ``porecad analyze --pores`` (validity, curvature, local
  thickness pore/strut sizes, interconnectivity; default voxel) of a
  2-million-triangle gyroid sheet scaffold (issue 8, acceptance 5);
* ``femur``: ``../shared/data/femur.stl`` filled with a gyroid pore solid
  (C = 0, 5 mm cells) at voxel = smallest extent / 200, against PyScaffolder
  1.5 at its grid size 200 (issue 3; PyScaffolder runs once: about 2 minutes).

Tools: porecad; ``numpy+skimage``, the plain pipeline as a user writes it (a
dense float32 meshgrid with trigonometry at every voxel, scikit-image marching
cubes, numpy STL records: about 2.4 GB for P500, as issue 2 states);
``numpy+skimage separable``, the same with porecad's separable evaluation
(per-axis terms broadcast together), to show what the mesher alone gains;
microgen 1.3 (``pip install microgen``) on the gyroid jobs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap

PORECAD = textwrap.dedent("""
    import json, resource, sys, time
    from porecad.pipeline import run_recipe
    job, out = sys.argv[1], sys.argv[2]
    def recipe(n, cells, tp, path):
        return {"job": "tpms", "tpms": tp, "domain": {"kind": "box", "cells": cells},
                "sampling": {"resolution": n}, "output": {"mesh": path}}
    if job == "P500":
        tp, cells, n = {"type": "P", "structure": "surface", "threshold": 0.0, "cell_size": 1.0}, [1, 1, 1], 500
    else:
        tp, cells = {"type": "G", "structure": "sheet", "threshold": 0.3, "cell_size": 1.0}, [4, 4, 4]
        n = int(job.split("x")[1])
    run_recipe(recipe(12, cells, tp, out), force=True)  # JIT warm-up (cached after the first run)
    t = time.perf_counter()
    r = run_recipe(recipe(n, cells, tp, out), force=True)
    dt = time.perf_counter() - t
    print(json.dumps({"time_s": dt, "triangles": r["triangles"],
                      "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
""")

ANALYZE = textwrap.dedent("""
    import json, resource, sys, time
    from porecad.pipeline import run_recipe
    from porecad.analysis.report import analyze_mesh
    out = sys.argv[2]
    rec = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "threshold": 0.3, "cell_size": 1.0},
           "domain": {"kind": "box", "cells": [4, 4, 4]}, "sampling": {"resolution": 41}, "output": {"mesh": out}}
    run_recipe(rec, force=True)
    small = out + ".small.stl"
    run_recipe({**rec, "sampling": {"resolution": 8}, "output": {"mesh": small}}, force=True)
    analyze_mesh(small, pores=True)  # JIT warm-up (cached after the first run)
    t = time.perf_counter()
    r, _ = analyze_mesh(out, pores=True)
    dt = time.perf_counter() - t
    print(json.dumps({"time_s": dt, "triangles": r["triangles"], "voxels": r["grid"],
                      "pore_size_mean": r["pore_size_mean"], "open_pore_fraction": r["open_pore_fraction"],
                      "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
""")

_PLAIN_WRITE = """
    tri = v[faces].astype(np.float32)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    rec = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = nrm, tri
    with open(out, "wb") as fh:
        fh.write(b"plain".ljust(80, b" ")); fh.write(np.uint32(len(faces)).tobytes()); rec.tofile(fh)
    dt = time.perf_counter() - t
    print(json.dumps({"time_s": dt, "triangles": int(len(faces)),
                      "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

# The plain pipeline as a user writes it (and as issue 2 measures it: about
# 4.8 s and 2.4 GB for P500): a dense float32 meshgrid, trigonometry at every
# voxel, scikit-image marching cubes, numpy STL records.
PLAIN = textwrap.dedent("""
    import json, resource, sys, time
    import numpy as np
    from skimage.measure import marching_cubes
    job, out = sys.argv[1], sys.argv[2]
    t = time.perf_counter()
    if job == "P500":
        x = np.linspace(0, 2 * np.pi, 500, dtype=np.float32)
        X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
        f = np.cos(X) + np.cos(Y) + np.cos(Z)
        del X, Y, Z
        v, faces, _, _ = marching_cubes(f, 0.0, spacing=(1 / 499,) * 3)
    else:
        n = 4 * (int(job.split("x")[1]) - 1) + 1
        x = np.linspace(0, 8 * np.pi, n, dtype=np.float32)
        X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
        g = np.sin(X) * np.cos(Y) + np.sin(Y) * np.cos(Z) + np.sin(Z) * np.cos(X)
        del X, Y, Z
        f = np.abs(g) - 0.3
        del g
        f = np.pad(f, 1, constant_values=1.0)  # close the sheet against the box
        v, faces, _, _ = marching_cubes(f, 0.0, spacing=(4 / (n - 1),) * 3)
""") + textwrap.dedent(_PLAIN_WRITE)

# The same with the separable evaluation that porecad uses (per-axis terms
# broadcast together: no trigonometry per voxel), to show what is left.
PLAIN_SEPARABLE = textwrap.dedent("""
    import json, resource, sys, time
    import numpy as np
    from skimage.measure import marching_cubes
    job, out = sys.argv[1], sys.argv[2]
    t = time.perf_counter()
    if job == "P500":
        x = np.linspace(0, 2 * np.pi, 500, dtype=np.float32)
        c = np.cos(x)
        f = c[:, None, None] + c[None, :, None] + c[None, None, :]
        v, faces, _, _ = marching_cubes(f, 0.0, spacing=(1 / 499,) * 3)
    else:
        n = 4 * (int(job.split("x")[1]) - 1) + 1
        x = np.linspace(0, 8 * np.pi, n, dtype=np.float32)
        s, c = np.sin(x), np.cos(x)
        g = (s[:, None, None] * c[None, :, None] + s[None, :, None] * c[None, None, :]
             + s[None, None, :] * c[:, None, None])
        f = np.abs(g) - 0.3
        f = np.pad(f, 1, constant_values=1.0)  # close the sheet against the box
        v, faces, _, _ = marching_cubes(f, 0.0, spacing=(4 / (n - 1),) * 3)
""") + textwrap.dedent(_PLAIN_WRITE)

MICROGEN = textwrap.dedent("""
    import json, resource, sys, time
    from microgen import Tpms
    from microgen.shape.surface_functions import gyroid
    job, out = sys.argv[1], sys.argv[2]
    t = time.perf_counter()
    g = Tpms(surface_function=gyroid, offset=0.6, cell_size=1.0, repeat_cell=4,
             resolution=int(job.split("x")[1]))
    m = g.generate_vtk(type_part="sheet")
    surf = m.extract_surface().triangulate()
    surf.save(out)
    dt = time.perf_counter() - t
    print(json.dumps({"time_s": dt, "triangles": int(surf.n_cells),
                      "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
""")


FEMUR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "femur.stl")

# issue 3, acceptance 1: the femur filled with a gyroid (pore, C = 0, 5 mm cells) at
# PyScaffolder's grid size 200 (voxel = smallest extent / 200)
PORECAD_FEMUR = textwrap.dedent("""
    import json, resource, sys, time
    from porecad.pipeline import run_recipe
    job, out, femur = sys.argv[1], sys.argv[2], sys.argv[3]
    def recipe(sampling):  # no voxel: smallest body extent / 200 (PyScaffolder's grid size 200)
        return {"job": "tpms", "tpms": {"type": "G", "structure": "pore", "threshold": 0.0, "cell_size": 5.0},
                "domain": {"kind": "mesh", "path": femur, "boundary": "cut"},
                "sampling": sampling, "output": {"mesh": out}}
    run_recipe(recipe({"voxel": 2.0}), force=True)  # JIT warm-up (cached after the first run)
    t = time.perf_counter()
    r = run_recipe(recipe({}), force=True)
    dt = time.perf_counter() - t
    print(json.dumps({"time_s": dt, "triangles": r["triangles"], "porosity": r["porosity"],
                      "valid": bool(r["closed"] and r["manifold"] and r["oriented"]),
                      "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
""")

PYSCAFFOLDER_FEMUR = textwrap.dedent("""
    import json, resource, sys, time
    import numpy as np
    import PyScaffolder
    from porecad.io import read_mesh
    from porecad.mesh.topology import edge_topology
    job, out, femur = sys.argv[1], sys.argv[2], sys.argv[3]
    v, f = read_mesh(femur)
    p = PyScaffolder.Parameter()
    p.surface_name, p.grid_size, p.coff, p.isolevel = "gyroid", 200, 2 * np.pi / 5, 0.0
    t = time.perf_counter()
    m = PyScaffolder.generate_scaffold(v.astype(np.float64), f.astype(np.int32), p)
    v, faces = np.asarray(m.v), np.asarray(m.f)
""") + textwrap.dedent(_PLAIN_WRITE).replace(
    '"triangles": int(len(faces)),',
    '"triangles": int(len(faces)), "porosity": m.porosity, '
    '"valid": bool(edge_topology(faces)["manifold"]),')

MEMORY_LIMIT = 16 << 30  # per job: a job that needs more fails cleanly instead of waking the OOM killer


def _limit_memory():
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _run(code, job, repeat):
    best = None
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as d:
            p = subprocess.run([sys.executable, "-c", code, job, os.path.join(d, "out.stl"), FEMUR],
                               capture_output=True, text=True, preexec_fn=_limit_memory)
        if p.returncode in (-9, 137) or "MemoryError" in p.stderr or "bad_alloc" in p.stderr:
            return {"error": f"out of memory (limit {MEMORY_LIMIT >> 30} GiB)"}
        if p.returncode != 0:
            return {"error": (p.stderr.strip().splitlines() or ["failed"])[-1]}
        r = json.loads(p.stdout.strip().splitlines()[-1])
        if best is None or r["time_s"] < best["time_s"]:
            best = r
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--jobs", default="P500,G4x128,G4x64,femur,analyze2M", help="comma-separated job names")
    ap.add_argument("--tools", default="", help="comma-separated tool names to run (default: all), e.g. porecad")
    args = ap.parse_args()
    wanted = {t.strip() for t in args.tools.split(",") if t.strip()}

    def keep(name):
        return not wanted or name in wanted or (name.startswith("porecad") and "porecad" in wanted)
    rows = []
    for job in args.jobs.split(","):
        if job not in ("P500", "G4x128", "G4x64", "femur", "analyze2M"):
            ap.error(f"unknown job {job!r}")
        if job == "analyze2M":
            if not keep("porecad"):
                continue
            rows.append({"job": job, "tool": "porecad analyze --pores", **_run(ANALYZE, job, args.repeat)})
            continue
        if job == "femur":
            for name, code, rep in (("porecad", PORECAD_FEMUR, args.repeat),
                                    ("PyScaffolder", PYSCAFFOLDER_FEMUR, 1)):
                if not keep(name):
                    continue
                rows.append({"job": job, "tool": name, **_run(code, job, rep)})
            continue
        tools = (("porecad", PORECAD), ("numpy+skimage", PLAIN),
                 ("numpy+skimage separable", PLAIN_SEPARABLE), ("microgen", MICROGEN))
        for name, code in tools:
            if (name == "microgen" and job == "P500") or not keep(name):
                continue
            r = _run(code, job, args.repeat)
            rows.append({"job": job, "tool": name, **r})
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{'job':<8} {'tool':<26} {'time s':>8} {'peak MB':>8} {'triangles':>10} {'speed-up':>8}")
    for r in rows:
        if "error" in r:
            print(f"{r['job']:<8} {r['tool']:<26} error: {r['error']}")
            continue
        ref = next((x for x in rows if x["job"] == r["job"] and x["tool"] == "porecad" and "time_s" in x), None)
        speed = f"{r['time_s'] / ref['time_s']:.1f}x" if ref and r is not ref else ""
        print(f"{r['job']:<8} {r['tool']:<26} {r['time_s']:8.2f} {r['peak_mb']:8.0f} {r['triangles']:10d} "
              f"{speed:>8}")
    print("speed-up = tool time / porecad time (porecad includes writing the binary STL)")


if __name__ == "__main__":
    main()
