"""TIS vs TPMS (issue 6, acceptance 4) beside document 002 Tables 2-5.

Run ``python bench/tis.py [--resolutions 100 200 300 400 500] [--json]``.

* Table 5: one period of the P surface at a resolution of N samples per axis.
  TPMS: one unit cell sampled N³ and polygonised (our chunked marching cubes,
  the open surface, C = 0). TIS: one regular tetrahedron, λ = 1, N samples
  per edge, relative threshold 0.16 (002's display setting), polygonised on
  its barycentric lattice (surface triangles counted without the caps; the
  time includes them). 002 ran C code on a 2.2 GHz i7; this machine is a
  2-core VM.
* Table 3: porosity at the five relative thresholds per type (200 samples).
* Table 4: surface area per unit volume (TIS surface without caps, tet of
  unit volume; TPMS one unit cell at C = 0).
* Table 2: mean curvature of the TIS surfaces, exact from the field (the
  chain rule through the barycentric map), at the display thresholds; the
  TPMS for comparison. Shows the asymmetry 002 reports for TIS.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

TABLE5 = {100: (0.108, 74216, 0.083, 27379), 200: (1.212, 299672, 0.674, 112381),
          300: (3.895, 675848, 2.930, 254074), 400: (9.749, 1203704, 7.361, 454630),
          500: (18.524, 1882376, 14.708, 708986)}
TABLE3 = {"P": [(0.118, 18.36), (0.157, 35.80), (0.196, 49.36), (0.235, 61.17), (0.275, 71.86)],
          "D": [(0.569, 57.35), (0.618, 66.88), (0.667, 75.73), (0.716, 83.04), (0.765, 89.90)],
          "G": [(0.431, 44.03), (0.480, 57.29), (0.529, 67.76), (0.578, 76.09), (0.627, 84.04)]}
TABLE4 = {"TPMS": {"P": 2.353180, "D": 3.828864, "G": 3.083422}, "TIS": {"P": 3.798055, "D": 2.367160, "G": 2.654556}}
TABLE2 = {"TPMS": {"P": (-12.66, 12.59, -0.49, 3.78), "D": (-14.99, 13.83, -1.29, 3.32), "G": (-14.34, 18.32, -0.79, 2.85)},
          "TIS": {"P": (-33.19, 21.09, -2.88, 4.11), "D": (-14.88, 12.16, -0.94, 4.32), "G": (-26.48, 15.17, -2.79, 4.51)}}
DISPLAY = {"P": 0.16, "D": 0.67, "G": 0.5}


def unit_tet():
    from porecad.volmesh import regular_tetrahedron
    edge = (6 * np.sqrt(2)) ** (1 / 3)  # volume 1
    return regular_tetrahedron(edge)


def tis_surface(kind, rel, n, pts=None, tets=None):
    from porecad.maps.tis_mesh import tis_lattice_mesh
    if pts is None:
        pts, tets = unit_tet()
    t = time.perf_counter()
    res = tis_lattice_mesh(pts, tets, kind, 1.0, relative=rel, subdivisions=n - 1)
    dt = time.perf_counter() - t
    surf = res.faces[: len(res.faces) - res.n_cap_faces]
    return res, surf, dt


def tpms_surface(kind, n):
    from porecad.fields.tpms import TPMSField
    from porecad.mesh.polygonise import Grid, polygonise
    field = TPMSField(kind, cell_size=1.0)
    grid = Grid.from_box((0, 0, 0), (1, 1, 1), samples_per_axis=n)
    t = time.perf_counter()
    res = polygonise(field.sample_grid, grid, caps=False)
    return res, time.perf_counter() - t


def area(v, f):
    return float(0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum())


def tis_mean_curvature(kind, rel, n=100):
    """Exact mean curvature at the TIS surface vertices of the unit-volume tet (chain rule)."""
    from porecad.maps.tis_mesh import tis_curvatures
    pts, tets = unit_tet()
    res, surf, _ = tis_surface(kind, rel, n, pts, tets)
    H, _, bmin = tis_curvatures(pts, tets, kind, 1.0, res.vertices[np.unique(surf)])
    # away from the tet's faces (the surface is only C0 there)
    return H[(bmin > 0.02) & np.isfinite(H)]


def tis_grid_surface(n):
    """TIS-P on a Cartesian grid of n samples per axis of the tet's bounding cube (002's sampling)."""
    from porecad.maps.tis_mesh import tis_grid_mesh
    pts, tets = unit_tet()
    edge = np.linalg.norm(pts[tets[0, 1]] - pts[tets[0, 0]])
    side = edge / np.sqrt(2)  # the regular tet spans a cube of this side
    t = time.perf_counter()
    g = tis_grid_mesh(pts, tets, "P", 1.0, relative=0.16, resolution=(n - 1) * edge / side + 1)
    return g, time.perf_counter() - t


def tpms_mean_curvature(kind, n=100):
    from porecad.analysis.curvature import field_curvatures
    from porecad.fields.tpms import TPMSField
    res, _ = tpms_surface(kind, n)
    field = TPMSField(kind, cell_size=1.0)
    H, _ = field_curvatures(field, res.vertices, project=True)
    return H[np.isfinite(H)]


def stats(h):
    return {"min": float(h.min()), "max": float(h.max()), "median": float(np.median(h)), "mean": float(h.mean()),
            "std": float(h.std()), "skew": float(np.mean((h - h.mean()) ** 3) / h.std() ** 3)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolutions", type=int, nargs="+", default=[100, 200, 300, 400, 500])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out = {"table5": [], "table3": {}, "table4": {}, "table2": {}}
    tis_surface("P", 0.16, 20)  # compile
    tpms_surface("P", 20)
    for n in args.resolutions:
        res, surf, t_tis = tis_surface("P", 0.16, n)
        tp, t_tpms = tpms_surface("P", n)
        g, t_grid = tis_grid_surface(n) if n <= 300 else (None, None)
        ref = TABLE5.get(n)
        row = {"resolution": n, "tpms_s": t_tpms, "tpms_triangles": int(len(tp.faces)), "tis_s": t_tis,
               "tis_triangles": int(len(surf)), "tis_triangles_with_caps": int(len(res.faces))}
        if g is not None:
            row.update(tis_grid_s=t_grid, tis_grid_triangles_with_caps=int(len(g["faces"])))
        if ref:
            row["paper"] = {"tpms_s": ref[0], "tpms_triangles": ref[1], "tis_s": ref[2], "tis_triangles": ref[3]}
        out["table5"].append(row)
        if not args.json:
            paper = f"   002: TPMS {ref[0]:7.3f} s {ref[1]:>9,}  TIS {ref[2]:7.3f} s {ref[3]:>8,}" if ref else ""
            grid = f"  TIS-grid {t_grid:6.2f} s {len(g['faces']):>8,}" if g is not None else ""
            print(f"N={n:4d}  TPMS {t_tpms:7.3f} s {len(tp.faces):>9,}  TIS {t_tis:7.3f} s {len(surf):>8,}{grid}{paper}",
                  flush=True)
    for kind, rows in TABLE3.items():
        pts, tets = unit_tet()
        got = []
        for rel, ref in rows:
            res, _, _ = tis_surface(kind, rel, 200, pts, tets)
            from porecad.mesh.validate import signed_volume
            got.append({"relative": rel, "porosity": 100 * (1 - signed_volume(res.vertices, res.faces)),
                        "porosity_samples": 100 * res.sample_porosity, "paper": ref})
        out["table3"][kind] = got
        if not args.json:
            print(f"Table 3 TIS-{kind}: " + "  ".join(f"{g['relative']:.3f}: {g['porosity']:.2f} ({g['paper']:.2f})"
                                                 for g in got))
    for kind in ("P", "D", "G"):
        res, surf, _ = tis_surface(kind, DISPLAY[kind], 200)
        tp, _ = tpms_surface(kind, 200)
        out["table4"][kind] = {"tis": area(res.vertices, surf), "tpms": area(tp.vertices, tp.faces),
                               "paper_tis": TABLE4["TIS"][kind], "paper_tpms": TABLE4["TPMS"][kind]}
        ht, hp = tis_mean_curvature(kind, DISPLAY[kind]), tpms_mean_curvature(kind)
        out["table2"][kind] = {"tis": stats(ht), "tpms": stats(hp), "paper_tis": TABLE2["TIS"][kind],
                               "paper_tpms": TABLE2["TPMS"][kind]}
        if not args.json:
            a = out["table4"][kind]
            print(f"Table 4 {kind}: area/volume TIS {a['tis']:.4f} (002 {a['paper_tis']:.4f})  "
                  f"TPMS {a['tpms']:.4f} (002 {a['paper_tpms']:.4f})")
            for fam in ("tis", "tpms"):
                s = out["table2"][kind][fam]
                p = out["table2"][kind]["paper_" + fam]
                print(f"Table 2 {fam.upper():4s} {kind}: H min {s['min']:7.2f} max {s['max']:6.2f} mean {s['mean']:6.2f} "
                      f"median {s['median']:6.2f} std {s['std']:5.2f} skew {s['skew']:+.2f}   "
                      f"(002: min {p[0]}, max {p[1]}, mean {p[2]}, std {p[3]})")
    if args.json:
        json.dump(out, sys.stdout, indent=1)
        print()


if __name__ == "__main__":
    main()
