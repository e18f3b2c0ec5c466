"""A bone's size at the defaults (issue 52): 150 mm bodies in 1.5 mm cells, measured from the written file.

    python bench/bone_size.py [--bodies femur,bunny,limbs] [--out DIR] [--extra "--stream"]

Each corpus body (``porecad.datasets.BODIES``) is scaled so that its largest
extent is 150 mm and filled with a gyroid pore at porosity 0.6 in 1.5 mm
cells with the command's defaults::

    porecad infill BODY150.stl G --porosity 0.6 -L 1.5 -o out.stl --json

run under ``/usr/bin/time`` (wall, user + system CPU, peak resident memory).
The written STL is then read back without porecad: its signed volume (numpy,
over the binary records), its pieces (vertices welded by their exact float32
coordinates, faces joined by scipy's connected components) and the body's
volume (trimesh) give the porosity and the piece count of the file.
Prints one Markdown table row per body.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

RECORD = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])


def scaled_body(name: str, folder: str) -> str:
    import trimesh

    from porecad import datasets
    fn, kw = datasets.BODIES[name]
    v, f = fn(**kw)
    v = np.asarray(v, float)
    s = 150.0 / np.ptp(v, axis=0).max()
    path = os.path.join(folder, f"{name}150.stl")
    trimesh.Trimesh((v - v.min(axis=0)) * s, f, process=False).export(path)
    return path


def stl_records(path: str) -> np.ndarray:
    raw = np.memmap(path, dtype=np.uint8, mode="r")
    n = int(np.frombuffer(raw[80:84], "<u4")[0])
    return np.ndarray((n,), dtype=RECORD, buffer=raw[84: 84 + RECORD.itemsize * n])


def file_volume(rec: np.ndarray, block: int = 4_000_000) -> float:
    centre = rec["v"][: min(len(rec), block)].reshape(-1, 3).astype(np.float64).mean(axis=0)
    total = 0.0
    for s in range(0, len(rec), block):
        p = rec["v"][s: s + block].astype(np.float64) - centre
        total += float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0
    return total


def file_pieces(rec: np.ndarray) -> int:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    xyz = np.ascontiguousarray(rec["v"]).reshape(-1, 3)
    _, ids = np.unique(xyz.view(np.dtype((np.void, 12))).ravel(), return_inverse=True)
    ids = ids.reshape(-1, 3)
    n = int(ids.max()) + 1
    r = np.concatenate([ids[:, 0], ids[:, 1]])
    c = np.concatenate([ids[:, 1], ids[:, 2]])
    k, _ = connected_components(coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(n, n)), directed=False)
    return int(k)


def run(body: str, folder: str, extra: list[str]) -> dict:
    import trimesh
    src = scaled_body(body, folder)
    out = os.path.join(folder, f"{body}-out.stl")
    cmd = ["/usr/bin/time", "-f", "TIME %e %U %S %M", "porecad", "infill", src, "G", "--porosity", "0.6", "-L", "1.5",
           "-o", out, "--json", "--force", *extra]
    p = subprocess.run(cmd, capture_output=True, text=True)
    line = [x for x in p.stderr.splitlines() if x.startswith("TIME ")][-1].split()
    wall, user, system, kb = float(line[1]), float(line[2]), float(line[3]), int(line[4])
    if p.returncode:
        return {"body": body, "error": p.stderr.strip().splitlines()[-2:], "wall": wall}
    report = json.loads(p.stdout[p.stdout.index("{"):])
    rec = stl_records(out)
    body_volume = trimesh.load(src).volume
    row = {"body": body, "extent": np.round(trimesh.load(src).extents, 0).tolist(),
           "voxel": round(float(np.min(report["grid"]["spacing"])), 3),
           "samples_per_cell": round(1.5 / float(np.min(report["grid"]["spacing"])), 1),
           "stream": bool((report.get("scale") or {}).get("stream")),
           "porosity_file": round(1.0 - file_volume(rec) / body_volume, 4), "porosity_report": round(report["porosity"], 4),
           "pieces_file": file_pieces(rec), "pieces_report": report.get("pieces"),
           "islands_dropped": report.get("islands_dropped"), "triangles": len(rec),
           "wall_s": wall, "cpu_s": round(user + system, 1), "peak_gb": round(kb / 1e6, 2),
           "estimate_gb": round(report["estimate"]["peak_bytes"] / 1e9, 2),
           "estimate_triangles": report["estimate"].get("triangles"),
           "warnings": [w.split(":")[0] for w in report.get("warnings", [])]}
    os.remove(out)
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", default="femur,bunny,limbs")
    ap.add_argument("--out", default=None, help="folder for the scaled bodies and outputs (default: a temp folder)")
    ap.add_argument("--extra", default="", help="more porecad infill options, e.g. --stream")
    a = ap.parse_args(argv)
    folder = a.out or tempfile.mkdtemp(prefix="porecad-bone-size-")
    print("| body | extent (mm) | voxel | samples/cell | streamed | porosity (file) | pieces (file) | islands dropped "
          "| triangles | est. triangles | peak GB | est. GB | wall s | CPU s | warnings |")
    print("|---" * 15 + "|")
    for b in a.bodies.split(","):
        r = run(b, folder, a.extra.split())
        if "error" in r:
            print(f"| {b} | error: {r['error']} |", flush=True)
            continue
        print(f"| {b} | {' x '.join(f'{e:.0f}' for e in r['extent'])} | {r['voxel']} | {r['samples_per_cell']} | "
              f"{r['stream']} | {r['porosity_file']} | {r['pieces_file']} | {r['islands_dropped']} | "
              f"{r['triangles'] / 1e6:.1f} M | {(r['estimate_triangles'] or 0) / 1e6:.1f} M | {r['peak_gb']} | "
              f"{r['estimate_gb']} | {r['wall_s']:.0f} | {r['cpu_s']:.0f} | {', '.join(r['warnings']) or '-'} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
