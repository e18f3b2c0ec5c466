"""Vessels from a thoracic contrast CT (issue 55): the aortic-arch phantom, its shortcut and its frames.

Usage::

    python bench/vessel_arch.py --markdown bench/vessel_arch.md

The phantom (:func:`porecad.vessels.arch_phantom.arch_phantom`, r = 6 mm, 1 × 1 × 1.5 mm voxels, 20 HU
noise): an aortic arch whose root runs into a contrast-filled chamber (the heart) that reaches the spine,
the spine beside the descending aorta, all as bright as the lumen. Cases, each ``porecad vessel`` in its own
process and measured as ``bench/vessel_ct.py`` does (Dice, precision, recall at the voxel centres; distances
from the written surface to the true one); ``radius_max`` is the report's largest local radius against the
true largest:

* ``two-seeds``: the two ends of the aorta (root, descending end) — the path must climb the arch;
* variants with two seeds at the ends: ``taper`` (6 mm → 3 mm), ``stenosis`` (to 0.4 r), ``bright-large``
  (chamber 450 HU of radius 3 r, bone 600 HU of radius 2.2 r), ``shortcut`` (that and a stenosis to 0.2 r:
  the path through the chamber and the spine is cheaper than through the vessel; the warning says where);
* ``seed-in-chamber``: a seed in the chamber and the descending end — a path that must leave the vessel:
  the ``path-not-tube`` warning says where and which seed to move;
* ``centreline-ras`` / ``centreline-ras-image``: the true centreline as a VMTK-style ``.vtp`` in RAS (no
  frame in the file), without and with ``--image``; the mean surface distance between the two solids both
  ways (trimesh: points sampled on one, nearest distance to the other).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from vessel_ct import run

VARIANTS = {"taper": dict(taper=0.5), "stenosis": dict(stenosis=0.6),
            "bright-large": dict(chamber_hu=450.0, bone_hu=600.0, chamber_scale=3.0, bone_scale=2.2),
            "shortcut": dict(chamber_hu=450.0, bone_hu=600.0, chamber_scale=3.0, bone_scale=2.2, stenosis=0.8)}


def case(folder, name, ph, args):
    rep = folder / f"{name}.json"
    row = run(folder, name, ph, [*args, "--report", rep])
    d = json.loads(rep.read_text()) if rep.exists() else {}
    rmax = (d.get("input") or {}).get("radius_max")
    row["radius_max"] = f"{rmax:.1f} / {float(ph.axis[1].max()):.1f}" if rmax else ""
    row["where"] = "; ".join(f"{w['values'].get('at')} mm, seed {w['values'].get('seed')}"
                             for w in d.get("warning_details", []) if w.get("code") == "path-not-tube")
    return row


def surface_gap(a, b, n=4000):
    """Mean distance (mm) of ``n`` points sampled on mesh ``a`` to mesh ``b``'s surface."""
    import trimesh
    from scipy.spatial import cKDTree
    P, _ = trimesh.sample.sample_surface(a, n, seed=0)
    S, _ = trimesh.sample.sample_surface_even(b, 300_000, seed=1)
    return float(cKDTree(S).query(P)[0].mean())


def main(argv=None):
    import trimesh
    from porecad.io.slicer import write_centreline_vtp
    from porecad.vessels.arch_phantom import arch_phantom
    from porecad.vessels.ct_phantom import to_ras, write_ct_phantom
    ap = argparse.ArgumentParser()
    ap.add_argument("--markdown")
    ap.add_argument("--voxel", type=float, default=0.6)
    a = ap.parse_args(argv)
    rows = []
    v = ["--voxel", a.voxel]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        ph = arch_phantom(seed=1)
        p = write_ct_phantom(folder, ph, "lps")
        ends = [["--seed", *map(float, s)] for s in ph.ends]
        rows.append(case(folder, "two-seeds", ph, ["--image", p["ct"], *ends[0], *ends[1], *v]))
        rows.append(case(folder, "seed-in-chamber", ph, ["--image", p["ct"], "--seed",
                                                          *map(float, ph.chamber[0].mean(0)), *ends[1], *v]))
        for name, kw in VARIANTS.items():
            sub = folder / name
            phv = arch_phantom(seed=1, **kw)
            pv = write_ct_phantom(sub, phv, "lps")
            e = [["--seed", *map(float, s)] for s in phv.ends]
            rows.append(case(sub, name, phv, ["--image", pv["ct"], *e[0], *e[1], *v]))
        g = ph.graph
        write_centreline_vtp(folder / "c.vtp", g.branches(), to_ras(g.points), g.radii, None)
        rows.append(run(folder, "centreline-ras", ph, [folder / "c.vtp", *v], with_metrics=False))
        rows.append(run(folder, "centreline-ras-image", ph, [folder / "c.vtp", "--image", p["ct"], *v],
                        with_metrics=False))
        m0, m1 = (trimesh.load(str(folder / f"{n}.stl"), force="mesh")
                  for n in ("centreline-ras", "centreline-ras-image"))
        rows[-1]["msd_mm"] = f"{surface_gap(m1, m0):.3f} / {surface_gap(m0, m1):.3f} (to / from plain)"
    keys = ["case", "rc", "wall_s", "cpu_s", "peak_mb", "segments", "dice", "precision", "recall", "msd_mm",
            "p95_mm", "radius_max", "closed", "warnings", "where", "error"]
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        lines.append("| " + " | ".join(str(r.get(k, "")) for k in keys) + " |")
    text = "\n".join(lines)
    print(text)
    if a.markdown:
        Path(a.markdown).write_text("# Vessels on the arch phantom (python bench/vessel_arch.py)\n\n"
                                    "Noise seed 1, `--voxel 0.6`; `radius_max`: the report's largest local radius "
                                    "/ the true largest (mm); `where`: the `path-not-tube` warning's place "
                                    "(LPS mm) and the seed it names to move.\n\n" + text + "\n")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
