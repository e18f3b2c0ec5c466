"""Studio latencies (issue 24, acceptance 2): preview after a parameter change, export vs the CLI.

Run ``python bench/studio.py [--repeats 5] [--export-voxel MM] [--skip-export] [--json]``.

Everything goes through the real HTTP server (in this process, on 127.0.0.1)
the way the page drives it: ``POST api/preview`` with the changed design,
then polling ``api/preview/N`` every 20 ms until the first (coarse) preview
mesh is ready; the latency is from the POST to that moment. Targets: a box
lattice under 1 s, the femur infill under 3 s, on 2 cores.

* box lattice: gyroid sheet, 3×3×3 cells of 2 mm, 40 samples per cell;
  the porosity steps through 0.60, 0.65, 0.70, ... (each a new design).
* femur infill: ``../shared/data/femur.stl``, gyroid sheet, cells of 5 mm
  (the README's example), the porosity stepping the same way.
* export: the femur infill at full resolution (the CLI's default voxel,
  smallest extent / 200, unless ``--export-voxel``), mesh and JSON report,
  by the studio (``POST api/export``, polled to done) and by
  ``porecad infill`` in a subprocess with the same options; target: the
  studio within 1.5× the CLI. The two meshes are compared (identical).

Wall and CPU times are given (CPU: this process's ``process_time`` over the
interval, all threads; for the CLI the child's user + system time): the
machine is shared, so wall times carry the load of other work. Warm-up
(numba compilation, a first run of each design) is done first and not timed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path


def _req(base, method, path, payload=None, raw=None, headers=None):
    data = raw if raw is not None else (json.dumps(payload).encode() if payload is not None else None)
    r = urllib.request.Request(base + path, data=data, method=method,
                               headers=headers or ({"content-type": "application/json"} if data else {}))
    with urllib.request.urlopen(r, timeout=3600) as resp:
        body = resp.read()
    return json.loads(body) if resp.headers.get("content-type", "").startswith("application/json") else body


def first_preview(base, design) -> tuple[float, float, dict]:
    """(wall s, cpu s, coarse level) from POST api/preview to the coarse mesh being ready."""
    t0, c0 = time.perf_counter(), time.process_time()
    gen = _req(base, "POST", "api/preview", {"design": design})["gen"]
    while True:
        s = _req(base, "GET", f"api/preview/{gen}")
        if "coarse" in s["levels"]:
            _req(base, "GET", f"api/preview/{gen}/coarse")  # the mesh the page fetches
            return time.perf_counter() - t0, time.process_time() - c0, s["levels"]["coarse"]
        if s["state"] in ("failed", "superseded"):
            raise RuntimeError(s.get("error"))
        time.sleep(0.02)


def wait_idle(studio):
    while True:
        s = studio.previews.state(studio.previews.gen)
        if s is None or s["state"] in ("done", "failed", "superseded"):
            return
        time.sleep(0.05)


def series(base, studio, design, values, repeats):
    rows = []
    first_preview(base, dict(design, value=values[0]))  # warm-up (compilation, body load caches)
    wait_idle(studio)
    for i in range(repeats):
        v = values[(i + 1) % len(values)]
        wall, cpu, level = first_preview(base, dict(design, value=v))
        rows.append({"porosity": v, "wall_s": wall, "cpu_s": cpu, "triangles": level["report"]["triangles"],
                     "sampling": level.get("sampling")})
        wait_idle(studio)  # let the refinement finish: each change starts from an idle studio
    walls = [r["wall_s"] for r in rows]
    return {"rows": rows, "median_wall_s": statistics.median(walls), "max_wall_s": max(walls),
            "median_cpu_s": statistics.median(r["cpu_s"] for r in rows)}


def export_vs_cli(base, studio, femur, voxel):
    from porecad.io import read_mesh
    design = {"job": "infill", "body": "femur.stl", "type": "G", "structure": "sheet", "control": "porosity",
              "value": 0.7, "cell_size": 5.0, "boundary": "cut"}
    if voxel:
        design["voxel"] = voxel
    t0, c0 = time.perf_counter(), time.process_time()
    n = _req(base, "POST", "api/export", {"design": design, "format": "stl", "report": False})["id"]
    while True:
        s = _req(base, "GET", f"api/export/{n}")
        if s["state"] != "running":
            break
        time.sleep(0.1)
    studio_wall, studio_cpu = time.perf_counter() - t0, time.process_time() - c0
    if s["state"] != "done":
        raise RuntimeError(s.get("error"))
    studio_mesh = studio.exports.folder(n) / "infill.stl"
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "infill.stl"
        cmd = [sys.executable, "-m", "porecad", "infill", str(femur), "G", "--structure", "sheet", "--porosity",
               "0.7", "-L", "5", "-o", str(out), "--report", str(Path(tmp) / "infill.report.json"),
               "--recipe", str(Path(tmp) / "infill.toml")]
        if voxel:
            cmd += ["--voxel", str(voxel)]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        cli_wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cli_cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        v1, f1 = read_mesh(studio_mesh)
        v2, f2 = read_mesh(out)
        identical = bool(len(f1) == len(f2) and (f1 == f2).all() and (v1 == v2).all())
    return {"voxel": voxel or "default (smallest extent / 200)", "triangles": s["summary"]["triangles"],
            "studio_wall_s": studio_wall, "studio_cpu_s": studio_cpu, "cli_wall_s": cli_wall, "cli_cpu_s": cli_cpu,
            "ratio_wall": studio_wall / cli_wall, "identical_mesh": identical}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--export-voxel", type=float, default=None)
    ap.add_argument("--skip-export", action="store_true")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    from porecad.datasets import femur_path
    from porecad.studio.launcher import make_studio
    from porecad.studio.server import Server
    femur = femur_path()
    server = Server(make_studio(None)).start()
    base = server.url
    out = {"cores": os.cpu_count(), "load_average": os.getloadavg()}
    try:
        box = {"job": "tpms", "type": "G", "structure": "sheet", "control": "porosity", "cell_size": 2.0,
               "cells": [3, 3, 3], "resolution": 40}
        values = [0.6, 0.65, 0.7, 0.75, 0.62, 0.68]
        out["box_lattice"] = series(base, server.studio, box, values, args.repeats)
        _req(base, "PUT", "api/upload?name=femur.stl", raw=femur.read_bytes(),
             headers={"content-type": "application/octet-stream"})
        infill = {"job": "infill", "body": "femur.stl", "type": "G", "structure": "sheet", "control": "porosity",
                  "cell_size": 5.0, "boundary": "cut"}
        out["femur_infill"] = series(base, server.studio, infill, values, args.repeats)
        if not args.skip_export:
            out["femur_export"] = export_vs_cli(base, server.studio, femur, args.export_voxel)
    finally:
        server.stop()
    out["load_average_after"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, indent=1))
        return
    for key, target in (("box_lattice", 1.0), ("femur_infill", 3.0)):
        r = out[key]
        print(f"{key:>13}: first preview after a change: median {r['median_wall_s']:.2f} s wall "
              f"(max {r['max_wall_s']:.2f}; CPU {r['median_cpu_s']:.2f} s), target < {target:g} s; "
              f"{r['rows'][0]['triangles']:,} triangles at {r['rows'][0]['sampling']}")
    if "femur_export" in out:
        e = out["femur_export"]
        print(f" femur export: studio {e['studio_wall_s']:.1f} s wall ({e['studio_cpu_s']:.1f} s CPU), CLI "
              f"{e['cli_wall_s']:.1f} s wall ({e['cli_cpu_s']:.1f} s CPU): ratio {e['ratio_wall']:.2f} (target ≤ 1.5); "
              f"{e['triangles']:,} triangles; identical mesh: {e['identical_mesh']}")
    print(f"load average before {out['load_average'][0]:.1f}, after {out['load_average_after'][0]:.1f} "
          f"on {out['cores']} cores")


if __name__ == "__main__":
    main()
