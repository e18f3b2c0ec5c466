"""Time to first result (issue 22, item 4): ``porecad demo`` with an empty numba cache, then warm.

Run ``python bench/first_run.py [--repeat N] [--warm M]``. Each run is a fresh process with
``NUMBA_CACHE_DIR`` pointing at a new empty folder (cold: every kernel is
compiled, as after ``pip install``), followed by one run on the filled cache
(warm). Before each cold run the package's bytecode (``__pycache__`` folders of
``porecad``) is deleted, as a fresh ``pip install -e .`` leaves it. Reported: wall time, CPU time (user + system, the background compile helper included) and
the peak memory of the largest process so far. Goals: issue 22, a cold run under 15 s on 2 cores;
issue 53, at most 12 CPU s cold and 6 warm (``/usr/bin/time``'s user + system of the command, which
does not count the background compile helper it does not wait for).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import resource
import shutil
import subprocess
import sys
import tempfile
import time


def _demo(cache: str, out: str, force: bool) -> dict:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    cmd = [sys.executable, "-m", "porecad", "demo", "-o", out] + (["--force"] if force else [])
    t = time.perf_counter()
    p = subprocess.run(cmd, env={**os.environ, "NUMBA_CACHE_DIR": cache}, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"porecad demo failed: {(p.stderr.strip().splitlines() or ['?'])[-1]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "peak_mb": after.ru_maxrss / 1024,
            "report": os.path.exists(os.path.join(out, "demo_report", "report.html"))}


def _drop_bytecode() -> int:
    """Delete porecad's ``__pycache__`` folders (a fresh editable install has none); returns how many."""
    import porecad
    root = pathlib.Path(porecad.__file__).parent
    found = [p for p in root.rglob("__pycache__") if p.is_dir()]
    for p in found:
        shutil.rmtree(p, ignore_errors=True)
    return len(found)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="cold runs (each on a new empty cache)")
    ap.add_argument("--warm", type=int, default=1, help="warm runs after each cold one")
    args = ap.parse_args()
    print(f"{'run':<6} {'wall s':>7} {'cpu s':>7} {'peak MB':>8}  report.html  load before-after")
    for _ in range(max(1, args.repeat)):
        with tempfile.TemporaryDirectory() as d:
            cache, out = os.path.join(d, "numba-cache"), os.path.join(d, "demo")
            for name, force in [("cold", False)] + [("warm", True)] * max(0, args.warm):
                if name == "cold":
                    _drop_bytecode()
                load = os.getloadavg()[0]
                r = _demo(cache, out, force)
                print(f"{name:<6} {r['wall_s']:7.2f} {r['cpu_s']:7.2f} {r['peak_mb']:8.0f}  {str(r['report']):<11}  "
                      f"{load:.1f}-{os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
