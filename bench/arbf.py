"""ARBF pore networks (issue 7): local solve on the femur, local vs global, porosity tables (000 ch.5).

Run ``python bench/arbf.py [--tets 1000] [--resolution 16] [--json]``.

* **Femur, local solve** (acceptance 3): ``../shared/data/femur.stl`` (a
  femur-sized capsule where the shared data is absent) tetrahedralised on a
  BCC lattice to about 1000 tets (000 §5.4 used 989), 13 centres per tet,
  IMQ with ``c = 0.1`` at iso 0; one system per tet holding the centres of
  the tets sharing a vertex with it (000 Fig. 5.5, femur variant), and for
  comparison the face ring. Times the solves alone (with the jump of ``Φ``
  across shared faces), then the whole job for each ring (solve, grid
  evaluation, cut to the body, marching cubes, validation, pore-network
  analysis; no porosity table).
* **Local vs global** on meshes small enough for both: RMS of
  ``Φ_local − Φ_global`` at random points inside the domain, relative to the
  RMS of ``Φ_global``.
* **Porosity tables** (acceptance 2, 000 Figs. 5.11-5.12): porosity of the
  meshed scaffold (mesh volume) against the iso-value and the shape
  parameter on the single hex, the icosahedron and the 2×2×2 hexes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

FEMUR = Path(__file__).resolve().parents[2] / "shared" / "data" / "femur.stl"


def femur_body():
    from porecad.bodies import load_body
    if FEMUR.exists():
        v, f, _ = load_body(FEMUR)
        return v, f, str(FEMUR)
    import trimesh
    cap = trimesh.creation.capsule(height=120.0, radius=14.0, count=[48, 48])
    return np.asarray(cap.vertices), np.asarray(cap.faces), "capsule (femur.stl absent)"


def femur_bench(tets: int, resolution: int, path_out: Path | None):
    import tempfile

    from porecad.jobs import run_recipe
    from porecad.fields import rbf
    from porecad.volmesh import bcc_tet_mesh
    v, f, name = femur_body()
    t = time.perf_counter()
    p, tt, _ = bcc_tet_mesh(v, f, target_tets=tets)
    t_mesh = time.perf_counter() - t
    cc = rbf.mesh_centres(p, tt, "tet")
    rows = []
    for ring in ("vertex", "face"):
        t = time.perf_counter()
        fld = rbf.solve_local(cc, "imq", 0.1, ring=ring)
        t_solve = time.perf_counter() - t
        jump = rbf.face_jumps(fld, cc)
        rows.append({"ring": ring, "solve_s": t_solve, "patch_mean": fld.info["patch_size"]["mean"],
                     "patch_max": fld.info["patch_size"]["max"], "condition_max": fld.info["condition_number"],
                     "face_jump_rms": jump["rms"], "face_jump_max": jump["max"]})
    body_path = FEMUR if FEMUR.exists() else None
    if body_path is None:
        import trimesh
        tmp = Path(tempfile.mkdtemp()) / "capsule.stl"
        trimesh.Trimesh(v, f).export(tmp)
        body_path = tmp
    jobs = []
    for ring in ("vertex", "face"):
        out = {"mesh": str(path_out.with_name(f"{path_out.stem}-{ring}{path_out.suffix}"))} if path_out else {}
        recipe = {"domain": {"kind": "body", "path": str(body_path), "tets": tets},
                  "arbf": {"basis": "imq", "shape": 0.1, "iso": 0.0, "local": True, "ring": ring, "table": False},
                  "mesh": {"resolution": resolution}, "output": out}
        t = time.perf_counter()
        rep = run_recipe({"job": "arbf", **recipe}, force=True)
        t_job = time.perf_counter() - t
        net = rep["network"]
        jobs.append({"ring": ring, "total_s": t_job, "timings": rep["timings"], "triangles": rep["triangles"],
                     "porosity": rep["porosity"], "porosity_samples": rep["porosity_samples"],
                     "grid": rep["grid"]["shape"], "closed": rep["closed"], "manifold": rep["manifold"],
                     "pore_components": net["pore_components"], "largest_pore_fraction": net["largest_fraction"],
                     "open_outer_faces": f"{net['open_outer_faces']}/{net['outer_faces']}",
                     "solid_pieces": net["mesh_solid_pieces"]})
    return {"body": name, "tets": int(len(tt)), "centres": cc.centres.n, "bcc_s": t_mesh, "solves": rows,
            "jobs": jobs}


def local_vs_global():
    import trimesh

    from porecad import volmesh as vm
    from porecad.fields import rbf
    from porecad.volmesh import hexshapes as hs
    cap = trimesh.creation.capsule(height=30.0, radius=10.0, count=[24, 24])
    pc, tc, _ = vm.bcc_tet_mesh(np.asarray(cap.vertices), np.asarray(cap.faces), target_tets=150)
    meshes = {"icosahedron (20 tets)": (*vm.icosahedron_tets(10.0), "tet"),
              "hex rod (4 hexes)": (*hs.hex_rod(4, 10.0), "hex"),
              "hex 3x3x3": (*hs.hex_grid(3, 3, 3, 10.0), "hex"),
              f"capsule BCC ({len(tc)} tets)": (pc, tc, "tet")}
    out = []
    for name, (p, t, kind) in meshes.items():
        cc = rbf.mesh_centres(p, t, kind)
        tl = vm.TetLocator(p, t if kind == "tet" else t[:, hs.HEX_TETS].reshape(-1, 4))
        x = np.random.default_rng(1).uniform(p.min(0), p.max(0), (60000, 3))
        x = x[tl.locate(x)[0] >= 0]
        for basis, c in (("imq", 0.1), ("gaussian", 4.0), ("gaussian", 5.0)):
            t0 = time.perf_counter()
            g = rbf.solve_global(cc.centres, basis, c, cc.scale)
            tg = time.perf_counter() - t0
            t0 = time.perf_counter()
            lo = rbf.solve_local(cc, basis, c)
            tl_ = time.perf_counter() - t0
            pg, pl = g.phi(x), lo.phi(x)
            rms = float(np.sqrt(np.mean((pl - pg) ** 2)))
            out.append({"mesh": name, "centres": cc.centres.n, "basis": basis, "shape": c,
                        "global_s": tg, "local_s": tl_, "rms_diff": rms,
                        "rms_rel": rms / float(np.sqrt(np.mean(pg ** 2))),
                        "global_phi_rms": float(np.sqrt(np.mean(pg ** 2))),
                        "porosity_global": float(np.mean(pg < 0)), "porosity_local": float(np.mean(pl < 0))})
    return out


def porosity_tables(resolution: int):
    from porecad.jobs import run_recipe
    isos = (-0.5, -0.25, 0.0, 0.25, 0.5)
    out = {}
    for mesh, basis, shapes in (("hex", "imq", (0.05, 0.1, 0.2, 0.4)), ("icosahedron", "imq", (0.05, 0.1, 0.2, 0.4)),
                                ("hex2x2x2", "imq", (0.05, 0.1, 0.2, 0.4)), ("hex", "gaussian", (3.0, 4.0, 5.0, 6.0))):
        grid = []
        for c in shapes:
            row = []
            for iso in isos:
                r = run_recipe({"job": "arbf", "domain": {"kind": mesh}, "arbf": {"basis": basis, "shape": c, "iso": iso,
                                                                 "table": False},
                              "mesh": {"resolution": resolution}})
                row.append(r["porosity"])
            grid.append(row)
        out[f"{mesh} {basis}"] = {"iso": list(isos), "shape": list(shapes), "porosity": grid}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tets", type=int, default=1000)
    ap.add_argument("--resolution", type=int, default=16, help="femur grid samples per mean tet edge")
    ap.add_argument("--table-resolution", type=int, default=24)
    ap.add_argument("--out", type=Path, help="write the femur scaffold here")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    from porecad.jobs import run_recipe
    run_recipe({"job": "arbf", "domain": {"kind": "tet"}, "arbf": {"local": True, "table": False}, "mesh": {"resolution": 8}})  # compile
    res = {}
    res["femur"] = fem = femur_bench(args.tets, args.resolution, args.out)
    if not args.json:
        print(f"Femur ({fem['body']}): {fem['tets']} BCC tets ({fem['bcc_s']:.1f} s), {fem['centres']} centres, "
              "IMQ c = 0.1, iso 0")
        print(f"  {'ring':6s} {'solve s':>8s} {'patch mean':>10s} {'max':>5s} {'cond max':>9s} "
              f"{'face jump rms':>13s} {'max':>6s}")
        for r in fem["solves"]:
            print(f"  {r['ring']:6s} {r['solve_s']:8.2f} {r['patch_mean']:10.1f} {r['patch_max']:5d} "
                  f"{r['condition_max']:9.2e} {r['face_jump_rms']:13.4f} {r['face_jump_max']:6.3f}")
        for j in fem["jobs"]:
            tm = j["timings"]
            print(f"  whole job, {j['ring']} ring, {args.resolution} samples/edge, grid {j['grid']}: "
                  f"{j['total_s']:.1f} s [solve {tm['solve_s']:.1f}, evaluate {tm['evaluate_s']:.1f}, polygonise "
                  f"{tm['polygonise_s']:.1f}, validate {tm['validate_s']:.1f}]; {j['triangles']:,} triangles, closed "
                  f"{j['closed']}, manifold {j['manifold']}; porosity {j['porosity']:.3f} (samples "
                  f"{j['porosity_samples']:.3f}); largest pore network {100 * j['largest_pore_fraction']:.2f} % of "
                  f"the pore space ({j['pore_components']} components); opens on {j['open_outer_faces']} outer tet "
                  f"faces; {j['solid_pieces']} solid pieces", flush=True)
    res["local_vs_global"] = lvg = local_vs_global()
    if not args.json:
        print("\nLocal (vertex ring) vs global: RMS of Φ_local - Φ_global inside the domain")
        print(f"  {'mesh':24s} {'N':>5s} {'basis':9s} {'c':>4s} {'global s':>8s} {'local s':>7s} {'rms':>8s} "
              f"{'rel':>7s} {'Φg rms':>7s} {'por g':>6s} {'por l':>6s}")
        for r in lvg:
            print(f"  {r['mesh']:24s} {r['centres']:5d} {r['basis']:9s} {r['shape']:4g} {r['global_s']:8.2f} "
                  f"{r['local_s']:7.2f} {r['rms_diff']:8.4f} {100 * r['rms_rel']:6.2f}% {r['global_phi_rms']:7.2f} "
                  f"{r['porosity_global']:6.3f} {r['porosity_local']:6.3f}", flush=True)
    res["porosity"] = tabs = porosity_tables(args.table_resolution)
    if not args.json:
        for name, t in tabs.items():
            print(f"\nPorosity (mesh volume) — {name}: rows c, columns iso")
            print("  " + f"{'c':>6s}" + "".join(f"{iso:>8g}" for iso in t["iso"]))
            for c, row in zip(t["shape"], t["porosity"]):
                print("  " + f"{c:6g}" + "".join(f"{p:8.3f}" for p in row))
    if args.json:
        json.dump(res, sys.stdout, indent=1, default=float)
        print()


if __name__ == "__main__":
    main()
