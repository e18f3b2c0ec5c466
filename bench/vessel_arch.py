"""Vessels from a thoracic contrast CT (issue 55): the aortic-arch phantom, its shortcut and its frames.

Usage::

    python bench/vessel_arch.py --markdown bench/vessel_arch.md

The phantom (:func:`porecad.vessels.arch_phantom.arch_phantom`, r = 6 mm, 1 × 1 × 1.5 mm voxels, 20 HU
noise): an aortic arch whose root runs into a contrast-filled chamber (the heart) that reaches the spine,
the spine beside the descending aorta, all as bright as the lumen. Cases, each ``porecad vessel`` in its own
process and measured as ``bench/vessel_ct.py`` does (Dice, precision, recall at the voxel centres; distances
from the written surface to the true one):

* ``two-seeds``: the two ends of the aorta (root, descending end) — the path must climb the arch;
* ``seed-in-chamber``: a seed in the chamber and the descending end — a path that must leave the vessel:
  the ``path-not-tube`` warning says where;
* ``centreline-ras`` / ``centreline-ras-image``: the true centreline as a VMTK-style ``.vtp`` in RAS (no
  frame in the file), without and with ``--image``: both outputs in RAS (the report's ``frame``).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from vessel_ct import run


def main(argv=None):
    from porecad.io.slicer import write_centreline_vtp
    from porecad.vessels.arch_phantom import arch_phantom
    from porecad.vessels.ct_phantom import to_ras, write_ct_phantom
    ap = argparse.ArgumentParser()
    ap.add_argument("--markdown")
    ap.add_argument("--voxel", type=float, default=0.6)
    a = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        ph = arch_phantom(seed=1)
        p = write_ct_phantom(folder, ph, "lps")
        v = ["--voxel", a.voxel]
        ends = [["--seed", *map(float, s)] for s in ph.ends]
        rows.append(run(folder, "two-seeds", ph, ["--image", p["ct"], *ends[0], *ends[1], *v]))
        rows.append(run(folder, "seed-in-chamber", ph, ["--image", p["ct"], "--seed",
                                                         *map(float, ph.chamber[0].mean(0)), *ends[1], *v]))
        g = ph.graph
        write_centreline_vtp(folder / "c.vtp", g.branches(), to_ras(g.points), g.radii, None)
        rows.append(run(folder, "centreline-ras", ph, [folder / "c.vtp", *v], with_metrics=False))
        rows.append(run(folder, "centreline-ras-image", ph, [folder / "c.vtp", "--image", p["ct"], *v],
                        with_metrics=False))
    keys = ["case", "rc", "wall_s", "cpu_s", "peak_mb", "segments", "dice", "precision", "recall", "msd_mm",
            "p95_mm", "closed", "volume", "warnings", "error"]
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        lines.append("| " + " | ".join(str(r.get(k, "")) for k in keys) + " |")
    text = "\n".join(lines)
    print(text)
    if a.markdown:
        Path(a.markdown).write_text("# Vessels on the arch phantom (python bench/vessel_arch.py)\n\n" + text + "\n")


if __name__ == "__main__":
    main()
