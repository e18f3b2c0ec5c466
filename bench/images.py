"""Images in bounded time (issue 20, item 6): three image jobs, their wall and CPU time and peak memory.

Usage::

    python bench/images.py                      # the full-size CT-like volume, the three cases
    python bench/images.py --shape 40 100 12    # a small volume (same anatomy, coarser voxels)
    python bench/images.py --markdown bench/images-table.md --json bench/images-results.json

Cases (each is the ``porecad`` command of the README, run in its own process):

1. ``infill-ct``: ``porecad infill CT.nii.gz G --body-threshold 300 --porosity 0.7 -L 3 -o bone.stl`` on
   :func:`porecad.datasets.ct_volume` (157 × 393 × 34 voxels of 0.88 × 0.88 × 1.5 mm: a bone-like body with a
   cortical shell and a fatty canal, and a branching contrast-filled vessel beside it, in HU with noise);
2. ``vessel``: ``porecad vessel --image VESSEL.nii.gz --voxel 0.5 -o v.stl`` on the same volume without the
   bone (a contrast CT of the vessel: air, fat, muscle and the iodine-filled lumen, noise; no segmentation);
3. ``disc``: the README's disc example, ``porecad phantom spine -o spine/ --discs 3 --seed 0`` then
   ``porecad infill spine/01_Labels.nii.gz P --label 2 --porosity 0.6 -L 2 --boundary skin -o disc.stl``
   (the phantom's generation is timed separately).

Peak memory is the process's own resident high-water mark (``VmHWM``), CPU time its user + system time
(``wait4``). On the shared 2-core development machine the wall times are inflated by the other jobs; the
CPU times are not.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bodies import run_case  # noqa: E402  (the same process runner and memory measure)


def write_inputs(folder: Path, shape, seed: int) -> dict:
    """CT.nii.gz (bone and vessel) and VESSEL.nii.gz (the vessel only) in ``folder``."""
    from porecad import datasets
    from porecad.imaging.io import write_volume
    spacing = [s * n / m for s, n, m in zip(datasets.CT_SPACING, datasets.CT_SHAPE, shape)]
    ct = datasets.ct_volume(shape=shape, spacing=spacing, seed=seed)
    vessel = datasets.ct_volume(shape=shape, spacing=spacing, seed=seed, bone=False)
    paths = {"ct": folder / "CT.nii.gz", "vessel": folder / "VESSEL.nii.gz"}
    write_volume(paths["ct"], ct["ct"], ct["geometry"], force=True)
    write_volume(paths["vessel"], vessel["ct"], vessel["geometry"], force=True)
    return {"paths": paths, "spacing": spacing, "bone_voxels": int(ct["bone"].sum()),
            "vessel_voxels": int(vessel["vessel"].sum())}


def cases(folder: Path, paths: dict, vessel_voxel: float):
    base = [sys.executable, "-m", "porecad.cli"]
    return [
        ("infill-ct", base + ["infill", str(paths["ct"]), "G", "--body-threshold", "300", "--porosity", "0.7", "-L",
                              "3", "-o", str(folder / "bone.stl"), "--json", "--force"]),
        ("vessel", base + ["vessel", "--image", str(paths["vessel"]), "--voxel", str(vessel_voxel), "-o",
                           str(folder / "v.stl"), "--json", "--force"]),
        ("phantom", base + ["phantom", "spine", "-o", str(folder / "spine"), "--discs", "3", "--seed", "0",
                            "--force"]),
        ("disc", base + ["infill", str(folder / "spine" / "01_Labels.nii.gz"), "P", "--label", "2", "--porosity",
                         "0.6", "-L", "2", "--boundary", "skin", "-o", str(folder / "disc.stl"), "--json",
                         "--force"]),
    ]


def summary(name: str, rep: dict) -> str:
    if name == "vessel":
        return (f"{rep.get('branches')} branches, {rep.get('triangles')} triangles, closed {rep.get('closed')}, "
                f"manifold {rep.get('manifold')}, threshold {rep.get('input', {}).get('threshold', 0):.0f}")
    if name.startswith("infill") or name == "disc":
        return (f"{rep.get('triangles')} triangles, porosity {rep.get('porosity', 0):.4f} "
                f"(asked {rep.get('target_porosity')}), closed {rep.get('closed')}, manifold {rep.get('manifold')}, "
                f"grid {'x'.join(map(str, rep.get('grid', {}).get('shape', [])))}")
    return ""


def main(argv=None):
    from porecad import datasets
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shape", type=int, nargs=3, default=list(datasets.CT_SHAPE),
                    help="voxels of the CT-like volume (default 157 393 34; the spacing scales to keep the field of view)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--vessel-voxel", type=float, default=0.5, help="the vessel job's grid spacing, mm (default 0.5)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per case (default 600)")
    ap.add_argument("--keep", help="keep the inputs and outputs in this folder")
    ap.add_argument("--markdown", help="also write the table (markdown) here")
    ap.add_argument("--json", help="also write the results (JSON) here")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="porecad-images-") as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        inputs = write_inputs(folder, tuple(args.shape), args.seed)
        print(f"CT-like volume {tuple(args.shape)} at {[round(s, 3) for s in inputs['spacing']]} mm: "
              f"bone {inputs['bone_voxels']} voxels, vessel {inputs['vessel_voxels']} voxels", flush=True)
        rows = []
        for name, argv_ in cases(folder, inputs["paths"], args.vessel_voxel):
            code, so, se, wall, peak, cpu = run_case(argv_, args.timeout, with_cpu=True)
            row = {"case": name, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "peak_mb": round(peak)}
            if code is None:
                row["result"] = f"timeout after {args.timeout:g} s"
            elif code != 0:
                lines = [ln for ln in se.strip().splitlines() if ln.strip()]
                row["result"] = "failed: " + (lines[-1] if lines else f"exit {code}")
            else:
                try:
                    rep = json.loads(so.strip().splitlines()[-1]) if name != "phantom" else {}
                except (ValueError, IndexError):
                    rep = {}
                row["result"] = "ok " + summary(name, rep)
                row["warnings"] = rep.get("warnings", [])
                row["timings"] = rep.get("timings", {})
            rows.append(row)
            print(f"{name:>10} {row['wall_s']:7.1f} s wall {row['cpu_s']:7.1f} s CPU {row['peak_mb']:6d} MB  "
                  f"{row['result']}", flush=True)
    table = ["| case | wall s | CPU s | peak MB | result |", "|---|---|---|---|---|"]
    table += [f"| {r['case']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['peak_mb']} | {r['result']} |"
              for r in rows]
    text = "\n".join(table)
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    if args.json:
        Path(args.json).write_text(json.dumps({"shape": args.shape, "rows": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
