"""Every method on every corpus body (issue 20): success or one-line refusal, validity, porosity, time, memory.

Usage::

    python bench/bodies.py                           # all bodies x all methods, 5 min each
    python bench/bodies.py --bodies blob-4k bunny --methods tbss hex20 --timeout 120
    python bench/bodies.py --markdown bench/bodies-table.md --json bench/bodies-results.json

Each case runs the ``porecad`` command (``python -m porecad.cli ...``, the
stable command shapes of the README) in its own process under a time limit;
the peak memory is that process's maximum resident set (``wait4``). The
written mesh is then checked here, independently of the job's own report:
closed, manifold, self-intersecting face pairs (:func:`porecad.mesh.validate.check_solid`).

Methods (``cell`` = the body's largest extent / 12):

* ``infill-cut`` / ``infill-skin`` / ``infill-whole``: gyroid pore at ``--porosity 0.6``, ``--cell-size cell``;
  the porosity error is achieved − 0.6: the void fraction of the body by mesh volume (cut, skin), of the kept
  cells for ``whole`` (the body outside complete cells is left empty, so its void fraction of the body is not
  what a porosity asks for; the report's ``porosity_cells``);
* ``tbss``: gyroid sheet at porosity 0.6, periods ``round(extent / cell)`` per axis, ``--fit auto``;
  coverage = the volume of the body inside the TBSS / body volume (the report's ``covered_fraction``);
* ``hex8`` / ``hex20``: P pore at porosity 0.6 in an 8×8×8 hexahedral parameterisation, cut to the body;
  coverage = mapped hex volume / body volume;
* ``tis``: TIS-P at relative threshold 0.176 over about 1000 BCC tets, cut to the body (``tis-D``, ``tis-G``,
  only when named: the same with the D and G types);
* ``arbf``: local ARBF (IMQ, shape 0.1, iso 0) over about 1000 tets.

``extent err``: the largest relative difference of the written scaffold's bounding-box sides from the
body's.

Times are wall-clock on this machine: on 2 cores shared with other jobs they are inflated; say so when
quoting them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

METHODS = ("infill-cut", "infill-skin", "infill-whole", "tbss", "hex8", "hex20", "tis", "arbf")
#: run only when asked (``--methods tis-D tis-G``): the TIS row with the D and G types (issue 20, acceptance 4)
EXTRA_METHODS = ("tis-D", "tis-G")
TARGET = 0.6


def command(method, body, out, extent):
    cell = extent / 12.0
    base = [sys.executable, "-m", "porecad.cli"]
    if method.startswith("infill-"):
        return base + ["infill", body, "G", "--structure", "pore", "--porosity", str(TARGET), "--cell-size",
                       f"{cell:.6g}", "--boundary", method.split("-")[1], "-o", out, "--json", "--force"]
    if method == "tbss":
        return base + ["tbss", body, "G", "--structure", "sheet", "--porosity-range", str(TARGET), str(TARGET),
                       "--fit", "auto", "--periods", "4", "4", "4", "--resolution", "12", "-o", out, "--json",
                       "--force"]
    if method in ("hex8", "hex20"):
        return base + ["hex", body, "P", "--grid", "8", "8", "8", "--element", method, "--porosity", str(TARGET),
                       "--resolution", "12", "-o", out, "--json", "--force"]
    if method == "tis" or method.startswith("tis-"):
        kind = method.split("-")[1] if "-" in method else "P"
        return base + ["tis", body, "--type", kind, "--relative-threshold", "0.176", "--tets", "1000", "-o", out,
                       "--json", "--force"]
    if method == "arbf":
        return base + ["arbf", body, "--tets", "1000", "--local", "--basis", "imq", "--shape", "0.1", "--iso", "0",
                       "-o", out, "--json", "--force"]
    raise ValueError(method)


def _hwm_mb(pid):
    """The process's resident high-water mark (``VmHWM``, MB), or 0 when it cannot be read."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


def run_case(argv, timeout, with_cpu=False):
    """Run one command; (returncode or None on timeout, stdout, stderr, wall s, peak MB[, CPU s]).

    The peak is the child's own ``VmHWM`` polled every 0.1 s (``ru_maxrss`` from ``wait4`` is not used: Linux
    carries the parent's high-water mark across fork and exec, so it reads at least the bench's own size).
    The CPU time (user + system, from ``wait4``) is the child's own.
    """
    t = time.perf_counter()
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        p = subprocess.Popen(argv, stdout=fo, stderr=fe, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        code, peak, cpu = None, 0.0, 0.0
        while True:
            peak = max(peak, _hwm_mb(p.pid))
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                code = os.waitstatus_to_exitcode(status)
                cpu = ru.ru_utime + ru.ru_stime
                p.returncode = code
                break
            if time.perf_counter() - t > timeout:
                p.kill()
                _, status, ru = os.wait4(p.pid, 0)
                cpu = ru.ru_utime + ru.ru_stime
                p.returncode = -9
                code = None
                break
            time.sleep(0.1)
        wall = time.perf_counter() - t
        fo.seek(0)
        fe.seek(0)
        if with_cpu:
            return code, fo.read(), fe.read(), wall, peak, cpu
        return code, fo.read(), fe.read(), wall, peak


def check_mesh(path):
    from porecad.io import read_mesh
    from porecad.mesh.validate import check_solid
    v, f = read_mesh(path)
    if len(f) > 6_000_000:
        r = check_solid(v, f, check_self_intersections=False)
        r["self_intersections"] = None
    else:
        r = check_solid(v, f, check_self_intersections=True)
    import trimesh  # pieces and volume measured with another library than porecad's own
    m = trimesh.Trimesh(v, f, process=False)
    pieces = sum(1 for p in m.split(only_watertight=False) if p.volume > 0)
    return {"closed": bool(r["closed"]), "manifold": bool(r["manifold"]), "self_intersections": r["self_intersections"],
            "out_triangles": int(len(f)), "out_extent": np.ptp(v, axis=0).tolist(), "pieces": int(pieces),
            "file_volume": float(m.volume)}


def summarise(method, rep):
    out = {"porosity": rep.get("porosity"), "domain_volume": rep.get("domain_volume"),
           "report_coverage": rep.get("coverage"), "codes": sorted({d["code"] for d in rep.get("warning_details") or []})}
    if method == "infill-whole":
        # whole cells: the porosity asked for is that of the kept cells (the body outside them is empty)
        out["porosity"] = rep.get("porosity_cells")
        out["porosity_body"] = rep.get("porosity")
    if method == "tbss":
        out["coverage"] = (rep.get("tbss") or {}).get("covered_fraction")
        out["min_scaled_jacobian"] = (rep.get("tbss") or {}).get("min_scaled_jacobian")
    elif method in ("hex8", "hex20"):
        body_vol = (rep.get("body") or {}).get("body_volume")
        if body_vol and rep.get("hex_volume"):
            out["coverage"] = rep["hex_volume"] / body_vol
        out["min_scaled_jacobian"] = rep.get("min_scaled_jacobian")
    return out


def main(argv=None):
    from porecad import datasets
    from porecad.io import write_mesh

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bodies", nargs="+", default=list(datasets.BODIES))
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS + EXTRA_METHODS)
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per case (default 300)")
    ap.add_argument("--markdown", help="also write the table (markdown) here")
    ap.add_argument("--json", help="also write the results (JSON) here")
    args = ap.parse_args(argv)

    rows = []
    with tempfile.TemporaryDirectory(prefix="porecad-bodies-") as tmp:
        for name in args.bodies:
            try:
                v, f = datasets.body(name)
            except Exception as err:  # noqa: BLE001 - a missing femur is reported, the rest runs
                rows.append({"body": name, "method": "-", "status": f"no body: {err}"})
                print(f"{name}: {err}", file=sys.stderr)
                continue
            path = str(Path(tmp) / f"{name}.stl")
            write_mesh(path, v, f, force=True)
            extent = float(np.ptp(v, axis=0).max())
            for method in args.methods:
                out = str(Path(tmp) / f"{name}-{method}.stl")
                code, so, se, wall, peak, cpu = run_case(command(method, path, out, extent), args.timeout,
                                                         with_cpu=True)
                row = {"body": name, "triangles": int(len(f)), "method": method, "time_s": round(wall, 1),
                       "cpu_s": round(cpu, 1), "peak_mb": round(peak)}
                if code is None:
                    row["status"] = f"timeout after {args.timeout:g} s"
                elif code != 0:
                    lines = [ln for ln in se.strip().splitlines() if ln.strip()]
                    row["status"] = "refused: " + (lines[-1] if lines else f"exit {code}")
                    row["traceback"] = "Traceback" in se
                else:
                    try:
                        rep = json.loads(so.strip().splitlines()[-1])
                    except (ValueError, IndexError):
                        rep = {}
                    row["status"] = "ok"
                    row.update(summarise(method, rep))
                    if row.get("porosity") is not None and (method.startswith("infill") or method == "tbss"):
                        row["porosity_error"] = row["porosity"] - TARGET
                    if os.path.exists(out):
                        row.update(check_mesh(out))
                        os.remove(out)
                        body_ext = np.ptp(v, axis=0)
                        row["extent_error"] = float(np.max(np.abs(np.array(row["out_extent"]) - body_ext) / body_ext))
                        if row.get("domain_volume"):
                            row["porosity_file"] = 1.0 - row["file_volume"] / row["domain_volume"]
                rows.append(row)
                print(_line(row), flush=True)
                _save(rows, args)  # after every case: a run stopped midway keeps its table
    print(_table(rows))
    return 0


def _save(rows, args):
    if args.markdown:
        Path(args.markdown).write_text(_table(rows) + "\n")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float))


def _fmt(x, spec):
    return "" if x is None else format(x, spec)


def _line(r):
    return (f"{r['body']:>10} {r['method']:>12} {r.get('status', '')[:90]:<90} "
            f"{_fmt(r.get('porosity_error'), '+.4f'):>8} {_fmt(r.get('time_s'), '.1f'):>7}s wall "
            f"{_fmt(r.get('cpu_s'), '.1f'):>7}s CPU peak {_fmt(r.get('peak_mb'), '.0f')} MB")


def _table(rows):
    head = ("| body | tris | method | result | closed | manifold | self-int. | pieces | porosity | porosity (file) "
            "| err vs 0.6 | coverage | coverage (promise) | warnings | extent err | min SJ | wall s | CPU s | peak MB |")
    out = [head, "|" + "---|" * 19]
    for r in rows:
        out.append("| " + " | ".join([
            r["body"], str(r.get("triangles", "")), r["method"], r.get("status", "").replace("|", "/")[:160],
            str(r.get("closed", "")), str(r.get("manifold", "")), str(r.get("self_intersections", "")),
            str(r.get("pieces", "")), _fmt(r.get("porosity"), ".3f"), _fmt(r.get("porosity_file"), ".3f"),
            _fmt(r.get("porosity_error"), "+.3f"), _fmt(r.get("coverage"), ".3f"),
            _fmt(r.get("report_coverage"), ".3f"), " ".join(r.get("codes") or []),
            _fmt(r.get("extent_error"), ".3f"), _fmt(r.get("min_scaled_jacobian"), ".3f"), _fmt(r.get("time_s"), ".1f"), _fmt(r.get("cpu_s"), ".1f"),
            _fmt(r.get("peak_mb"), ".0f"),
        ]) + " |")
    return "\n".join(out)


if __name__ == "__main__":
    sys.exit(main())
