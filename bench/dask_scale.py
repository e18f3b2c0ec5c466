"""Scale-out benchmark (issue 11, acceptance 2): a streamed gyroid sheet on 1 and 2 dask workers.

Run ``python bench/dask_scale.py [--samples 1500] [--cells 1] [--schedulers local:1,local:2]
[--chunk-mb 64] [--dir DIR] [--json]``.

Each run is ``porecad tpms G --structure sheet --porosity 0.7 --cells C C C
--resolution R --stream --scheduler S -o DIR/bench.stl --json`` in a fresh
process, with ``C * (R - 1) + 1 = --samples`` samples per axis (1500^3 =
3.4e9 samples by default). The peak resident memory of the whole process
tree (the porecad process, the local cluster's nannies and workers) is
polled with psutil every 0.1 s; samples/s is the grid samples over the
chunk loop's wall time (sampling, meshing, welding, checking and writing the
streamed STL). The STL is deleted after each run. The first run of a fresh
checkout also compiles the numba kernels (cached on disk afterwards): run
once on a small size first (``--samples 200``) to warm the cache.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time


def tree_peak(proc: subprocess.Popen, interval: float = 0.1) -> dict:
    """Poll the RSS of ``proc`` and its descendants until it exits; return ``{"peak": bytes}``."""
    import psutil
    result = {"peak": 0}

    def poll():
        root = psutil.Process(proc.pid)
        while proc.poll() is None:
            total = 0
            try:
                procs = [root] + root.children(recursive=True)
            except psutil.Error:
                break
            for p in procs:
                try:
                    total += p.memory_info().rss
                except psutil.Error:
                    pass
            result["peak"] = max(result["peak"], total)
            time.sleep(interval)

    t = threading.Thread(target=poll, daemon=True)
    t.start()
    result["thread"] = t
    return result


def run_one(samples: int, cells: int, scheduler: str, chunk_mb: float, directory: str) -> dict:
    if (samples - 1) % cells:
        raise SystemExit(f"--samples - 1 = {samples - 1} must be a multiple of --cells {cells}")
    resolution = (samples - 1) // cells + 1
    out = os.path.join(directory, "bench.stl")
    cmd = [sys.executable, "-m", "porecad.cli", "tpms", "G", "--structure", "sheet", "--porosity", "0.7",
           "--cells", str(cells), str(cells), str(cells), "--resolution", str(resolution), "--stream",
           "--scheduler", scheduler, "--chunk-mb", str(chunk_mb), "-o", out, "--force", "--json"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    mem = tree_peak(proc)
    stdout, stderr = proc.communicate()
    mem["thread"].join()
    wall = time.perf_counter() - t0
    size = os.path.getsize(out) if os.path.exists(out) else None
    if os.path.exists(out):
        os.unlink(out)
    if proc.returncode != 0:
        return {"scheduler": scheduler, "error": stderr.strip().splitlines()[-1:] or ["failed"]}
    r = json.loads(stdout)
    s = r["scale"]
    return {"scheduler": scheduler, "samples": s["samples"], "chunks": s["chunks"], "workers": s["workers"],
            "triangles": r["triangles"], "closed": r["closed"], "stl_bytes": size,
            "chunk_loop_s": s["seconds"], "wall_s": wall, "samples_per_s": s["samples_per_s"],
            "peak_tree_rss_bytes": mem["peak"], "retries": s["retries"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1500, help="samples per axis (default 1500)")
    ap.add_argument("--cells", type=int, default=1, help="gyroid cells per axis (default 1)")
    ap.add_argument("--schedulers", default="local:1,local:2")
    ap.add_argument("--chunk-mb", type=float, default=64.0)
    ap.add_argument("--dir", help="where the STL is written (default: a temporary directory)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(dir=args.dir) as d:
        for sched in args.schedulers.split(","):
            rows.append(run_one(args.samples, args.cells, sched.strip(), args.chunk_mb, d))
            if not args.json:
                print(json.dumps(rows[-1]), file=sys.stderr)
    if args.json:
        print(json.dumps(rows))
        return
    print(f"gyroid sheet, porosity 0.7, {args.cells}^3 cells, {args.samples}^3 samples, streamed binary STL")
    print(f"{'scheduler':>10} {'workers':>7} {'chunks':>6} {'triangles':>11} {'STL GB':>7} {'loop s':>8} "
          f"{'Msamples/s':>10} {'peak RSS GB':>11}")
    for r in rows:
        if "error" in r:
            print(f"{r['scheduler']:>10} failed: {r['error']}")
            continue
        print(f"{r['scheduler']:>10} {r['workers']:>7} {r['chunks']:>6} {r['triangles']:>11,} "
              f"{(r['stl_bytes'] or 0) / 1e9:>7.2f} {r['chunk_loop_s']:>8.1f} {r['samples_per_s'] / 1e6:>10.1f} "
              f"{r['peak_tree_rss_bytes'] / 2**30:>11.2f}")


if __name__ == "__main__":
    main()
