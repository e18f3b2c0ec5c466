"""Start-up and a small job, whole process (issue 54, item 3): ``porecad`` against the plain numpy pipeline.

Run ``python bench/startup.py [--repeat 3] [--help-repeat 5] [--resolution 500]``. Every number is one
fresh process, timed from outside: wall time and CPU time (user + system of the process and the children
it waited for; porecad's watched child is one of them). To time another checkout, set ``PYTHONPATH`` to
its ``src``.

1. ``porecad --help`` (best of ``--help-repeat``), next to ``python -c pass``.
2. The P surface at 500 samples per cell edge, alternating, best of ``--repeat`` each:
   ``porecad tpms P --structure surface --threshold 0 --cell-size 1 --cells 1 1 1 --resolution 500 -o p.stl``
   against what a user would write without porecad (``--kinds``): ``separable`` (:func:`plain`: the P
   field broadcast from one cosine per axis in float32, ``skimage.measure.marching_cubes``, a binary STL
   written with numpy: the fastest plain script we know), ``sparse-meshgrid`` and ``meshgrid`` (the
   textbook script, :func:`plain_meshgrid`: ``np.meshgrid`` in float64, scikit-image, trimesh's STL).
   One untimed porecad run first fills numba's cache.
3. How much of each process is importing: one more run of each under ``python -X importtime``, the
   cumulative times of the top-level imports added up (importtime's own overhead included).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time


def plain(path: str, n: int) -> None:
    """The P surface (level 0) of one unit cell on an n^3 grid, as a binary STL: numpy and scikit-image only."""
    import numpy as np
    from skimage.measure import marching_cubes

    t = np.linspace(0.0, 1.0, n, dtype=np.float32)
    c = np.cos(np.float32(2 * np.pi) * t)
    field = c[:, None, None] + c[None, :, None] + c[None, None, :]
    h = 1.0 / (n - 1)
    verts, faces, _, _ = marching_cubes(field, level=0.0, spacing=(h, h, h))
    corners = verts.astype(np.float32)[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    records = np.zeros(len(faces), dtype=[("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    records["normal"] = normals
    records["v"] = corners
    with open(path, "wb") as f:
        f.write(b"P surface, numpy + scikit-image".ljust(80, b" "))
        f.write(np.uint32(len(faces)).tobytes())
        records.tofile(f)


def plain_meshgrid(path: str, n: int, sparse: bool) -> None:
    """The same surface as a textbook script writes it: ``np.meshgrid`` (float64), scikit-image, trimesh's STL.

    ``sparse``: ``np.meshgrid(..., sparse=True)`` (the field is still a dense float64 array, its three
    coordinate arrays are not).
    """
    import numpy as np
    import trimesh
    from skimage.measure import marching_cubes

    x = np.linspace(0.0, 1.0, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij", sparse=sparse)
    field = np.cos(2 * np.pi * X) + np.cos(2 * np.pi * Y) + np.cos(2 * np.pi * Z)
    verts, faces, _, _ = marching_cubes(field, 0.0, spacing=(x[1] - x[0],) * 3)
    trimesh.Trimesh(verts, faces, process=False).export(path)


#: the plain pipelines: name -> what it runs (``--plain NAME:STL``)
PLAIN = {"separable": plain, "meshgrid": lambda path, n: plain_meshgrid(path, n, False),
         "sparse-meshgrid": lambda path, n: plain_meshgrid(path, n, True)}


def _porecad() -> list[str]:
    found = shutil.which("porecad", path=os.path.dirname(sys.executable)) or shutil.which("porecad")
    return [found] if found else [sys.executable, "-m", "porecad"]


def _timed(cmd: list[str], env=None) -> dict:
    """Run ``cmd``; wall and CPU seconds (the children it waited for included), its stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {(done.stderr.strip().splitlines() or ['?'])[-1]}")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return {"wall": wall, "cpu": cpu, "stderr": done.stderr}


def _best(runs: list[dict]) -> str:
    best = min(runs, key=lambda r: r["wall"])
    walls = " / ".join(f"{r['wall']:.2f}" for r in runs)
    return f"best {best['wall']:6.2f} s wall, {best['cpu']:6.2f} s CPU   (all: {walls})"


def import_seconds(stderr: str) -> float:
    """Seconds spent importing, from ``-X importtime`` output: the top-level imports' cumulative times."""
    total = 0
    for line in stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            _, cumulative, name = line.split("|")
            if name.startswith(" ") and not name.startswith("  ") and cumulative.strip().isdigit():
                total += int(cumulative)
    return total / 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs of each P job (alternating)")
    ap.add_argument("--help-repeat", type=int, default=5, help="runs of porecad --help")
    ap.add_argument("--resolution", type=int, default=500, help="samples per cell edge")
    ap.add_argument("--plain", metavar="KIND:STL", help=argparse.SUPPRESS)  # run a plain pipeline in this process
    ap.add_argument("--kinds", default="separable,sparse-meshgrid,meshgrid",
                    help="plain pipelines to time: " + ", ".join(PLAIN))
    args = ap.parse_args()
    if args.plain:
        kind, _, path = args.plain.partition(":")
        PLAIN[kind](path, args.resolution)
        return
    kinds = [k for k in args.kinds.split(",") if k]
    porecad = _porecad()
    print(f"load average {os.getloadavg()[0]:.1f}, {os.cpu_count()} CPUs, porecad: {' '.join(porecad)}")
    bare = [_timed([sys.executable, "-c", "pass"]) for _ in range(args.help_repeat)]
    helps = [_timed(porecad + ["--help"]) for _ in range(args.help_repeat)]
    print(f"{'python -c pass':<16} {_best(bare)}")
    print(f"{'porecad --help':<16} {_best(helps)}", flush=True)
    with tempfile.TemporaryDirectory() as d:
        job = porecad + ["tpms", "P", "--structure", "surface", "--threshold", "0", "--cell-size", "1", "--cells",
                         "1", "1", "1", "--resolution", str(args.resolution), "-o", os.path.join(d, "p.stl"),
                         "--force"]
        plains = {k: [sys.executable, __file__, "--resolution", str(args.resolution), "--plain",
                      f"{k}:{os.path.join(d, 'q.stl')}"] for k in kinds}
        first = _timed(job)  # fills numba's cache (a fresh tree compiles its kernels once): not counted
        print(f"{'P' + str(args.resolution) + ' first':<16} {first['wall']:6.2f} s wall (numba cache filled; "
              "not counted)", flush=True)
        runs = {"porecad": [], **{k: [] for k in kinds}}
        for _ in range(max(1, args.repeat)):
            runs["porecad"].append(_timed(job))
            for k in kinds:
                runs[k].append(_timed(plains[k]))
        best = {name: min(x["wall"] for x in r) for name, r in runs.items()}
        for name, r in runs.items():
            ratio = f"   porecad {best[name] / best['porecad']:.1f}x faster" if name != "porecad" else ""
            print(f"{'P' + str(args.resolution) + ' ' + name:<24} {_best(r)}{ratio}", flush=True)
        env = dict(os.environ, PYTHONPROFILEIMPORTTIME="1")
        for name, cmd in (("porecad", job), *((k, plains[k]) for k in kinds[:1])):
            r = _timed(cmd, env=env)
            imp = import_seconds(r["stderr"])
            print(f"{'imports ' + name:<16} {imp:6.2f} s in a {r['wall']:.2f} s run under -X importtime "
                  f"({imp / r['wall']:.0%} of it; {imp / best[name]:.0%} of the best timed run)")


if __name__ == "__main__":
    main()
