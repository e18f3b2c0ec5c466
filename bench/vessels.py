"""Skeleton-marching evaluation (issue 9, acceptance 3) beside document 003 Table 3.4.

Run ``python bench/vessels.py [--voxel 0.1] [--repeat 3] [--json]``.

Three vessels in the roles of 003 Table 3.4's examples (synthetic: 003's
data are not public):

* ``A``: one segment (a straight tube, r = 1 mm, 3 mm long);
* ``B``: an unbranched vessel (a helix, r = 1 mm, 12 segments; 003: 13 knots);
* ``C``: a branched vessel (a binary tree of 3 generations: 7 vessels) split
  into 60 segments (003: 59).

For each: the vessel field (swept-tube segments, Li's union n = 2, δ = 0.2)
is evaluated on the voxel grid with every segment over the **whole grid**
("globalised", 003's global columns) and over its **bounding box** only
(localised), serially; then localised with 2 workers (threads: the numba
kernels release the GIL; and processes) vs 1. Times are the best of
``--repeat`` runs, after one warm-up (JIT compile). 003's times include its
RBF solves on an Intel Xeon E5-2680 / Tesla K40M; ours are tube evaluations
on this 2-core VM, so compare the *ratios*. Runtime about 2 minutes with
``--repeat 1`` (the global evaluation of B dominates).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "src"))

# 003 Table 3.4 (seconds): global CPU, global GPU, local CPU, local GPU
TABLE34 = {"A": (316, 36.70, 5.79, 5.40, 5.61), "B": (4196, 437.02, 25.12, 15.30, 12.09),
           "C": (17503, 1823.99, 93.48, 52.25, 35.24)}


def datasets():
    from porecad.vessels.graph import from_polylines
    from porecad.vessels.phantoms import straight
    A = straight(1.0, 3.0).graph(0.25)
    s = np.linspace(0, 3 * np.pi, 300)
    helix = np.stack([6 * np.cos(s), 6 * np.sin(s), 2.0 * s], axis=1)
    B = from_polylines([helix], [np.full(len(s), 1.0)])
    lines, radii = [], []

    def grow(p, d, r, L, gen):
        q = p + L * d
        t = np.linspace(0, 1, max(3, int(L / 0.25)))[:, None]
        lines.append(p + t * (q - p))
        radii.append(np.full(len(t), r))
        if gen == 0:
            return
        ax = np.cross(d, [0.0, 1.0, 0.0] if gen % 2 else [1.0, 0.0, 0.0])
        ax /= np.linalg.norm(ax)
        for sgn in (1, -1):
            a = np.deg2rad(35) * sgn
            grow(q, np.cos(a) * d + np.sin(a) * ax, 0.75 * r, 0.8 * L, gen - 1)

    grow(np.zeros(3), np.array([0, 0, 1.0]), 1.2, 10.0, 2)
    C = from_polylines(lines, radii)
    return {"A": (A, None), "B": (B, 4.5), "C": (C, 0.75)}


def timed(fn, repeat):
    fn()  # warm-up (JIT, pools)
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main(argv=None):
    from porecad.mesh.polygonise import Grid
    from porecad.fields.blends import Blend
    from porecad.vessels.model import evaluate_grid
    from porecad.vessels.segments import march
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxel", type=float, default=0.1)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    blend = Blend("li", 2, 0.2)
    rows = []
    for name, (g, L) in datasets().items():
        g.validate()
        pad = 0.2 + 3 * a.voxel
        segs = march(g, length=L, pad=pad)
        lo, hi = g.bounds()
        grid = Grid.from_box(lo - pad, hi + pad, spacing=a.voxel)
        axes = grid.axis(0), grid.axis(1), grid.axis(2)

        def run(local, workers=1, executor="thread"):
            return lambda: evaluate_grid(segs, g, *axes, pad, blend, local=local, workers=workers,
                                         executor=executor)
        st = {}
        evaluate_grid(segs, g, *axes, pad, blend, local=True, stats=st)
        row = {"dataset": name, "segments": len(segs), "grid": list(grid.shape), "samples": grid.n_samples,
               "box_samples": st["evaluated_samples"],
               "global_1": timed(run(False), a.repeat), "local_1": timed(run(True), a.repeat),
               "local_2_threads": timed(run(True, 2), a.repeat),
               "local_2_processes": timed(run(True, 2, "process"), a.repeat)}
        row["global_over_local"] = row["global_1"] / row["local_1"]
        row["threads_speedup"] = row["local_1"] / row["local_2_threads"]
        row["processes_speedup"] = row["local_1"] / row["local_2_processes"]
        row["global_1_over_local_2"] = row["global_1"] / min(row["local_2_threads"], row["local_2_processes"])
        n, gc, gg, lc, lg = TABLE34[name]
        row["003"] = {"points": n, "global_cpu_over_local_cpu": gc / lc, "local_cpu_over_local_gpu": lc / lg,
                      "global_cpu_over_local_gpu": gc / lg}
        rows.append(row)
    if a.json:
        print(json.dumps({"cpus": os.cpu_count(), "voxel": a.voxel, "rows": rows}))
        return 0
    print(f"# per-segment field evaluation, voxel {a.voxel} mm, {os.cpu_count()} CPUs, best of {a.repeat}")
    print(f"{'':3} {'segs':>4} {'samples':>10} {'in boxes':>10} {'global s':>9} {'local s':>8} "
          f"{'2 thr s':>8} {'2 proc s':>8} | {'glob/loc':>8} {'thr x':>6} {'proc x':>6} | "
          f"{'003 gC/lC':>9} {'003 lC/lG':>9} {'003 gC/lG':>9}")
    for r in rows:
        t = r["003"]
        print(f"{r['dataset']:3} {r['segments']:4d} {r['samples']:10,d} {r['box_samples']:10,d} {r['global_1']:9.3f} "
              f"{r['local_1']:8.3f} {r['local_2_threads']:8.3f} {r['local_2_processes']:8.3f} | "
              f"{r['global_over_local']:8.2f} {r['threads_speedup']:6.2f} {r['processes_speedup']:6.2f} | "
              f"{t['global_cpu_over_local_cpu']:9.2f} {t['local_cpu_over_local_gpu']:9.2f} "
              f"{t['global_cpu_over_local_gpu']:9.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
