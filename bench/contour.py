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
measured for that version, in the same process, alternating.
"""

from __future__ import annotations

import argparse
import importlib
import json
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
    a = ap.parse_args(argv)
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
