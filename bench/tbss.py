"""TBSS scaffolds (issue 4, acceptance 5) beside document 001 Table 2.

Run ``python bench/tbss.py [--resolution N] [--json]`` (default 64 samples per
period: binary STLs of 390-1280 MB, the sizes of 001 Table 2; 3 min 43 s and
6.3 GB peak on the 2-core machine, 2026-11-27, most of it the Moai rows' cut to
the femur: 25-27 s of TPMS time a structure, 102 s before the lattice
evaluation of the body's distance and its reuse for the cut domain). Five models as in
001 Table 2, each as pore, rod and sheet structure with a layer TDF at 001's
TDF settings (a 100^3 parametric grid fitted by LSPIA with a 20^3 control
grid, cubic), and the columns of Table 2: TDF construction time, volume TPMS
in the parametric domain, mapping into the TBSS, and the storage of the
scaffold as a binary STL and as a TDF file.

001's models (Ball joint, Venus, Moai, Tooth, Isis) are not published; we
use our primitives and the fitted femur with the same TPMS types: disc/P,
cylinder/D, femur/I-WP, box/G and tube... (tube replaced by a second disc
with a curvature-filled TDF, P). 001 ran on a 3.6 GHz i7-4790; this machine
is a 2-core VM, so times compare in order of magnitude only.

001 Table 2 (seconds): TDF 2.73-2.75; TPMS 0.23-0.66; scaffold 1.96-6.65;
STL 394-1450 MB; TDF file 0.57-1.36 MB.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

FEMUR = Path(__file__).resolve().parents[2] / "shared" / "data" / "femur.stl"

TABLE2 = {  # model: (type, {structure: (tdf_s, tpms_s, scaffold_s, stl_mb)}, tdf_mb)
    "Ball joint": ("P", {"pore": (2.745, 0.326, 3.194, 741.367), "rod": (2.745, 0.319, 3.109, 721.599),
                         "sheet": (2.745, 0.658, 6.651, 1449.71)}, 0.810),
    "Venus": ("D", {"pore": (2.728, 0.293, 3.024, 701.682), "rod": (2.728, 0.286, 3.007, 695.564),
                    "sheet": (2.728, 0.528, 6.581, 1399.55)}, 0.947),
    "Moai": ("IWP", {"pore": (2.736, 0.290, 2.554, 557.324), "rod": (2.736, 0.284, 2.555, 554.906),
                     "sheet": (2.736, 0.583, 5.530, 1105.41)}, 0.824),
    "Tooth": ("G", {"pore": (2.732, 0.238, 1.974, 394.402), "rod": (2.732, 0.237, 1.956, 394.422),
                    "sheet": (2.732, 0.499, 4.156, 773.741)}, 0.567),
    "Isis": ("P", {"pore": (2.754, 0.238, 2.089, 473.401), "rod": (2.754, 0.234, 1.994, 454.359),
                   "sheet": (2.754, 0.521, 4.236, 908.205)}, 1.355),
}

OURS = [  # (model of Table 2, our body, TDF spec, periods)
    ("Ball joint", {"kind": "disc"}, {"method": "layer", "by": "w"}, (8, 8, 4)),
    ("Venus", {"kind": "cylinder"}, {"method": "layer", "by": "sides"}, (6, 6, 8)),
    ("Moai", {"kind": "mesh", "path": str(FEMUR), "fit": "sliced", "control": 8},
     {"method": "layer", "by": "w"}, (3, 3, 30)),
    ("Tooth", {"kind": "box"}, {"method": "function", "expr": "sin(pi * u) * sin(pi * v)"}, (6, 6, 6)),
    ("Isis", {"kind": "disc"}, {"method": "fill"}, (8, 8, 4)),
]


def run(resolution: int) -> list[dict]:
    from porecad.jobs import run_recipe
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for model, body, tdf, periods in OURS:
            if body["kind"] == "mesh" and not FEMUR.exists():
                continue
            tp, ref, ref_tdf_mb = TABLE2[model]
            for structure in ("pore", "rod", "sheet"):
                stl, tdf_file = os.path.join(d, "s.stl"), os.path.join(d, "s.tdf")
                recipe = {"job": "tbss", "body": body,
                          "tpms": {"type": tp, "structure": structure, "periods": list(periods)},
                          "tdf": {**tdf, "grid": 100, "control": 20}, "mesh": {"resolution": resolution},
                          "analysis": {"layers": False}, "output": {"mesh": stl, "tdf": tdf_file}}
                t = time.perf_counter()
                r = run_recipe(recipe, force=True)
                total = time.perf_counter() - t
                tm = r["timings"]
                rows.append({
                    "model": model, "body": body["kind"], "type": tp, "structure": structure,
                    "periods": list(periods), "triangles": r["triangles"],
                    "tdf_s": tm.get("tdf_s"), "tpms_s": tm["tpms_s"], "map_s": tm["map_s"],
                    "scaffold_s": tm["tpms_s"] + tm["map_s"], "total_s": total,
                    "stl_mb": os.path.getsize(stl) / 1e6, "tdf_mb": os.path.getsize(tdf_file) / 1e6,
                    "lspia_iterations": r["tdf"]["lspia"]["iterations"], "lspia_rms": r["tdf"]["lspia"]["rms"],
                    "porosity": r["porosity"],
                    "ref_tdf_s": ref[structure][0], "ref_tpms_s": ref[structure][1],
                    "ref_scaffold_s": ref[structure][2], "ref_stl_mb": ref[structure][3], "ref_tdf_mb": ref_tdf_mb,
                    "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                })
                os.remove(stl)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=64,
                    help="samples per period edge (64: STL sizes like 001's, 390-1280 MB)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from porecad.jobs import run_recipe
    run_recipe({"job": "tbss", "body": {"kind": "box"}, "tpms": {"type": "G", "structure": "sheet", "periods": [1, 1, 1]},
              "tdf": {"grid": 10, "control": 4}, "mesh": {"resolution": 6}, "output": {}})
    rows = run(args.resolution)
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{'model':<11}{'body':<9}{'type':<5}{'struct':<6}{'tris':>10} {'TDF s':>11} {'TPMS s':>11} "
          f"{'scaffold s':>11} {'STL MB':>15} {'TDF MB':>11} {'TDF/STL':>8}")
    for r in rows:
        print(f"{r['model']:<11}{r['body']:<9}{r['type']:<5}{r['structure']:<6}{r['triangles']:>10} "
              f"{r['tdf_s']:5.2f}/{r['ref_tdf_s']:<5.2f} {r['tpms_s']:5.2f}/{r['ref_tpms_s']:<5.2f} "
              f"{r['scaffold_s']:5.2f}/{r['ref_scaffold_s']:<5.2f} {r['stl_mb']:7.1f}/{r['ref_stl_mb']:<7.1f} "
              f"{r['tdf_mb']:5.3f}/{r['ref_tdf_mb']:<5.3f} {100 * r['tdf_mb'] / r['stl_mb']:7.3f}%")
    print("each cell: porecad / 001 Table 2 (3.6 GHz i7-4790; TDF s there includes its 100^3 grid and LSPIA); "
          f"peak RSS {max(r['peak_mb'] for r in rows):.0f} MB")


if __name__ == "__main__":
    sys.exit(main())
