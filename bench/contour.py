"""Benchmark of marching cubes (issue 54): contouring throughput of ``polygonise`` on the P surface.

    python bench/contour.py [--resolution 500] [--repeat 3] [--threads 2] [--old DIR]

Figures, each the best of ``--repeat`` runs (wall and CPU = user + sys, best taken apart):

* ``job``: ``porecad tpms P --structure surface --threshold 0 --cell-size 1 --cells 1 1 1
  --resolution N --json`` in a child process: its wall and CPU (as ``/usr/bin/time``) and the
  job's own ``polygonise_s`` (sampling + marching + welding, wall);
* ``polygonise``: the same field and grid in this process, with the CPU split of the stage
  (``stats``: sampling, marching on the worker threads, welding in the calling thread);
* ``contour``: ``polygonise`` of the field sampled beforehand (``GridArraySampler`` hands out
  views): marching + welding only, the contouring figure.

Triangles per second are given per wall second and per CPU second over the threads
(``triangles / (cpu / threads)``, what the threads would do on idle cores): on a shared
machine the wall clock counts other processes' time. With ``--old DIR`` (copies of an older
``polygonise.py``, ``_mc_kernel.py`` and ``mc_tables.py``) the in-process figures are also
measured for that version, in the same process, alternating, and the two meshes are compared
(bit-identical vertices and faces).

``--fresh N --old-src SRC`` instead runs the CLI job ``N`` times in fresh processes, alternating
this tree with an older source tree (``SRC`` put first on ``PYTHONPATH``, e.g. a copy of ``src``
made before a change), and prints each run's own timings (``polygonise_s``, ``validate_s``,
``total_s``, the ``contour`` CPU split), the process's wall and CPU and the load average, then
the median of each (after one uncounted run of each, which fills numba's caches); the reports
must agree on everything but timings.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


# runs the CLI with an older polygonise swapped in (``sys.argv[1]``: the folder of :func:`_load_old`)
_OLD_CLI = ("import sys, importlib, porecad.mesh\n"
            "sys.path.insert(0, sys.argv.pop(1))\n"
            "sys.modules['porecad.mesh.polygonise'] = importlib.import_module('old_porecad_mc.polygonise')\n"
            "from porecad.cli.main import main\n"
            "sys.exit(main(sys.argv[1:]))\n")


def _job(n, threads, old_root=None):
    args = ["tpms", "P", "--structure", "surface", "--threshold", "0", "--cell-size", "1", "--cells", "1", "1", "1",
            "--resolution", str(n), "--json"]
    cmd = [sys.executable, "-m", "porecad"] if old_root is None else [sys.executable, "-c", _OLD_CLI, old_root]
    cmd += args
    if threads:
        cmd += ["--threads", str(threads)]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    rep = json.loads(out)
    return {"wall": wall, "cpu": (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime),
            "polygonise_s": rep["timings"]["polygonise_s"], "triangles": rep["triangles"]}


def _fresh_job(n, threads, src=None):
    """One CLI job in a fresh process (``src`` first on ``PYTHONPATH``): its report and the process's wall and CPU."""
    args = [sys.executable, "-m", "porecad", "tpms", "P", "--structure", "surface", "--threshold", "0", "--cell-size",
            "1", "--cells", "1", "1", "1", "--resolution", str(n), "--json"]
    if threads:
        args += ["--threads", str(threads)]
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = os.pathsep.join([str(src)] + [p for p in [env.get("PYTHONPATH")] if p])
    load = os.getloadavg()[0]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(args, check=True, capture_output=True, text=True, env=env).stdout
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return json.loads(out), wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime), load


def _comparable(rep):
    """A job report without its timings and CPU figures (what two versions must agree on)."""
    return {k: v for k, v in rep.items() if k not in ("timings", "contour", "estimate")}


def fresh_table(n, threads, runs, old_src):
    """``runs`` fresh-process jobs of each version, alternating old and new; prints a row per run and medians."""
    import statistics
    rows = {"old": [], "new": []}
    ref = {}
    for src in (old_src, None):   # fill numba's caches (a first run after an edit compiles): not counted
        _fresh_job(n, threads, src)
    print("version  load  polygonise_s  M tri/s  sample_cpu  contour_cpu  validate_s  total_s  proc wall  proc CPU")
    for _ in range(runs):
        for name, src in (("old", old_src), ("new", None)):
            rep, wall, cpu, load = _fresh_job(n, threads, src)
            t, c = rep["timings"], rep.get("contour") or {}
            row = {"load": load, "polygonise_s": t["polygonise_s"], "rate": rep["triangles"] / t["polygonise_s"] / 1e6,
                   "sample_cpu_s": c.get("sample_cpu_s", float("nan")),
                   "contour_cpu_s": c.get("contour_cpu_s", float("nan")),
                   "validate_s": t["validate_s"], "total_s": t["total_s"], "wall": wall, "cpu": cpu}
            rows[name].append(row)
            print(f"{name:7s} {load:5.2f} {row['polygonise_s']:12.3f} {row['rate']:8.1f} {row['sample_cpu_s']:11.3f} "
                  f"{row['contour_cpu_s']:12.3f} {row['validate_s']:11.3f} {row['total_s']:8.3f} {wall:10.2f} "
                  f"{cpu:9.2f}")
            ref.setdefault(name, _comparable(rep))
    same = ref["old"] == ref["new"]
    print(f"reports agree (all but timings): {same}; triangles {ref['new'].get('triangles')}, closed "
          f"{ref['new'].get('closed')}, manifold {ref['new'].get('manifold')}")
    for name, rs in rows.items():
        med = {k: statistics.median(r[k] for r in rs) for k in rs[0]}
        print(f"median {name}: polygonise_s {med['polygonise_s']:.3f} ({med['rate']:.1f} M tri/s), validate_s "
              f"{med['validate_s']:.3f}, total_s {med['total_s']:.3f}, contour CPU {med['contour_cpu_s']:.3f}, "
              f"process wall {med['wall']:.2f} CPU {med['cpu']:.2f}, load {med['load']:.2f}")
    return rows, same


def _load_old(d):
    """The older polygonise from ``d`` as a package of its own (relative imports of this tree kept)."""
    tmp = Path(tempfile.mkdtemp()) / "old_porecad_mc"
    tmp.mkdir()
    (tmp / "__init__.py").write_text("")
    for name in ("_mc_kernel.py", "mc_tables.py"):
        shutil.copy(Path(d) / name, tmp / name)
    src = (Path(d) / "polygonise.py").read_text()
    src = src.replace("from ..errors", "from porecad.errors").replace("from .grid", "from porecad.mesh.grid")
    (tmp / "polygonise.py").write_text(src)
    sys.path.insert(0, str(tmp.parent))
    return importlib.import_module("old_porecad_mc.polygonise"), str(tmp.parent)


def _run(mod, sampler, grid, threads):
    t0, c0 = time.perf_counter(), time.process_time()
    res = mod.polygonise(sampler, grid, caps=False, threads=threads)
    return {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0, "triangles": len(res.faces),
            **{k: v for k, v in res.stats.items() if k.endswith("_cpu_s")}}


def _best(runs):
    keys = [k for k in runs[0] if k != "triangles"]
    return {"triangles": runs[0]["triangles"], **{k: min(r[k] for r in runs) for k in keys}}


def _rates(b, threads):
    mt = b["triangles"] / 1e6
    return f"{mt / b['wall']:6.1f} M/s wall, {mt / (b['cpu'] / threads):6.1f} M/s per CPU over {threads} threads"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", type=int, default=500)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--old", help="folder with an older polygonise.py, _mc_kernel.py, mc_tables.py")
    ap.add_argument("--no-job", action="store_true", help="skip the CLI job")
    ap.add_argument("--fresh", type=int, help="only the fresh-process table: this many CLI jobs per version")
    ap.add_argument("--old-src", help="with --fresh: an older source tree (put first on PYTHONPATH)")
    a = ap.parse_args(argv)
    if a.fresh:
        return fresh_table(a.resolution, a.threads, a.fresh, a.old_src)
    import numpy as np

    from porecad.fields.tpms import TPMSField
    new = importlib.import_module("porecad.mesh.polygonise")
    mods, old_root = {"new": new}, None
    if a.old:
        mods["old"], old_root = _load_old(a.old)
    n, th = a.resolution, a.threads
    h = 1.0 / (n - 1)
    field = TPMSField("P", 1.0)
    grid = new.Grid((0.0,) * 3, (h,) * 3, (n, n, n))
    F = field.sample_grid(grid.axis(0), grid.axis(1), grid.axis(2))
    pre = new.GridArraySampler(F, grid)
    small = new.Grid((0.0,) * 3, (h,) * 3, (n, n, 4))
    for m in mods.values():   # compile / load the kernels
        m.polygonise(field.sample_grid, small, caps=False)
    out = {}
    if not a.no_job:
        jobs = {"new job": [], "old job": []} if a.old else {"new job": []}
        for _ in range(a.repeat):
            for k in jobs:
                jobs[k].append(_job(n, th, old_root if k == "old job" else None))
        out.update({k: _best(v) for k, v in jobs.items()})
    for _ in range(a.repeat):
        for name, m in mods.items():
            for kind, s in (("polygonise", field.sample_grid), ("contour", pre)):
                out.setdefault(f"{name} {kind}", []).append(_run(m, s, grid, th))
    if a.old:   # the same mesh, bit for bit
        meshes = [m.polygonise(field.sample_grid, grid, caps=False, threads=th) for m in mods.values()]
        same = all(np.array_equal(getattr(meshes[0], k), getattr(meshes[1], k)) for k in ("vertices", "faces"))
        print(f"old and new meshes bit-identical: {same}")
    print(f"P surface, {n}^3 samples, {th} threads, best of {a.repeat}")
    for k, v in out.items():
        b = v if k.endswith("job") else _best(v)
        extra = ""
        if k.endswith("job"):
            extra = f" polygonise_s {b['polygonise_s']:.3f}"
        elif "mesh_cpu_s" in b:
            extra = f" (sample {b['sample_cpu_s']:.3f} mesh {b['mesh_cpu_s']:.3f} weld {b['weld_cpu_s']:.3f} CPU s)"
        print(f"{k:16s} tris {b['triangles']:9d} wall {b['wall']:.3f} s CPU {b['cpu']:.3f} s{extra}")
        if not k.endswith("job"):
            print(f"{'':16s} {_rates(b, th)}")
    return out


if __name__ == "__main__":
    main()
