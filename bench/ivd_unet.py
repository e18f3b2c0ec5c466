"""The two-stage 3D U-Net on generated spine phantoms (issue 10, acceptance 1; 000 §6.2.4, Table 6.5).

Run ``python bench/ivd_unet.py [--train 8] [--test 4] [--iterations 400] [--threads 2] [--with-2d] [--json]``.

Trains the localiser + per-disc segmentation network (000 §6.2.4) on CPU with
``--threads`` torch threads on ``--train`` phantoms (Dixon opp, wat, fat —
000 Table 6.3's best combination; 3 and 4 discs; 2 × 1.25 × 1.25 mm voxels),
then segments ``--test`` held-out phantoms (other seeds, 4 discs each) and
reports Dice/DOC, Hausdorff, HD95 and mean surface distance (000 §6.2.6)
against their labels, the training and inference times, and the budget check
(Dice ≥ 0.85 within 15 minutes in total). The trained checkpoint then drives
``porecad ivd --segmenter unet`` on one held-out phantom (TPMS scaffolds).
With ``--with-2d`` the 2-D slice U-Nets (§6.2.3) are trained and scored too
(000 Table 6.4's directions and their merge).

000's numbers for orientation (real MR, 6 training subjects, GPU): 3D DOC
89.0 ± 1.4 %, HD 0.8 mm; 2D 81.8 %; ~0.5 s inference per 36×256×256 volume.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BUDGET_S = 15 * 60
TARGET_DICE = 0.85


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", type=int, default=8)
    ap.add_argument("--test", type=int, default=4)
    ap.add_argument("--iterations", type=int, default=400, help="segmentation-network steps (localiser: 2x)")
    ap.add_argument("--features", default="16,32,64")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--with-2d", action="store_true")
    ap.add_argument("--out", help="keep the checkpoint and the ivd outputs here (default: a temp dir)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    import torch

    from porecad.imaging.metrics import evaluate_labels
    from porecad.imaging.phantom import spine_phantom, write_phantom
    from porecad.seg.checkpoint import save_checkpoint
    from porecad.seg.predict import predict_3d
    from porecad.seg.train import phantom_subjects, train_3d

    torch.set_num_threads(args.threads)
    channels = ["opp", "wat", "fat"]
    features = tuple(int(x) for x in args.features.split(","))
    log = (lambda m: print(m, file=sys.stderr, flush=True))
    t_all = time.perf_counter()
    t = time.perf_counter()
    train = phantom_subjects(args.train, channels, seed=1000 + args.seed)
    test = phantom_subjects(args.test, channels, seed=9000 + args.seed, n_discs=(4,))
    t_data = time.perf_counter() - t
    t = time.perf_counter()
    nets, meta, hist = train_3d(train, channels, iterations=args.iterations, loc_iterations=2 * args.iterations,
                                features=features, seed=args.seed, log=log)
    t_train = time.perf_counter() - t
    results = []
    t = time.perf_counter()
    for (img, lab) in test:
        ti = time.perf_counter()
        pred, centres = predict_3d(img, meta, nets["localiser"], nets["segmenter"])
        r = evaluate_labels(lab, pred, [2.0, 1.25, 1.25])
        results.append({"discs_true": int(lab.max()), "discs_found": int(pred.max()), **r["all"],
                        "mean_disc_dice": r["mean_disc_dice"], "time_s": time.perf_counter() - ti})
    t_test = time.perf_counter() - t
    total = time.perf_counter() - t_all
    dice = [r["dice"] for r in results]
    summary = {"device": "cpu", "threads": args.threads, "train_phantoms": args.train, "test_phantoms": args.test,
               "iterations": args.iterations, "loc_iterations": 2 * args.iterations, "features": list(features),
               "data_s": t_data, "train_s": t_train, "test_s": t_test, "total_s": total,
               "dice_mean": float(np.mean(dice)), "dice_std": float(np.std(dice)),
               "hd_mean": float(np.mean([r["hd"] for r in results])),
               "hd95_mean": float(np.mean([r["hd95"] for r in results])),
               "msd_mean": float(np.mean([r["msd"] for r in results])),
               "per_phantom": results,
               "final_losses": {k: float(np.mean(v[-20:])) for k, v in hist.items()},
               "pass": bool(np.mean(dice) >= TARGET_DICE and total <= BUDGET_S)}

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="ivd-bench-"))
    out.mkdir(parents=True, exist_ok=True)
    ck = save_checkpoint(out / "ivd_unet3d.pt", "porecad-ivd-unet3d", meta, nets, force=True)
    # the checkpoint drives the whole image -> scaffold pipeline on a held-out phantom
    from porecad.jobs.ivd_job import run_ivd
    sub = out / "heldout"
    sub.mkdir(exist_ok=True)
    write_phantom(sub, spine_phantom(4, seed=9000 + args.seed), force=True)
    t = time.perf_counter()
    rep = run_ivd(sub, out / "scaffolds", segmenter="unet", methods=["tpms"], checkpoint=ck, force=True)
    summary["ivd_unet"] = {"discs": len(rep["discs"]), "dice": rep["metrics"]["all"]["dice"],
                           "scaffolds_closed": all(d["scaffolds"]["tpms"]["closed"] and
                                                   d["scaffolds"]["tpms"]["manifold"] for d in rep["discs"]),
                           "porosities": [d["scaffolds"]["tpms"]["porosity"] for d in rep["discs"]],
                           "time_s": time.perf_counter() - t}
    if args.with_2d:
        from porecad.seg.slices import predict_2d, predict_probabilities, train_2d
        from porecad.imaging.metrics import dice as dice_fn
        t = time.perf_counter()
        n2, m2, _ = train_2d(train, channels, iterations=args.iterations, seed=args.seed, log=log)
        t2 = time.perf_counter() - t
        per = {"x": [], "y": [], "z": [], "merged": []}
        for img, lab in test:
            probs = predict_probabilities(img, m2, n2)
            for a in ("x", "y", "z"):
                per[a].append(dice_fn(lab > 0, probs[a] > 0.5))
            merged, _ = predict_2d(img, m2, n2)
            per["merged"].append(dice_fn(lab > 0, merged > 0))
        summary["unet2d"] = {"train_s": t2, **{k: float(np.mean(v)) for k, v in per.items()}}
    summary["checkpoint"] = str(ck)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"3D two-stage U-Net, CPU, {args.threads} threads: train {t_train:.0f} s on {args.train} phantoms "
              f"({args.iterations} + {2 * args.iterations} steps), total {total:.0f} s (budget {BUDGET_S} s)")
        print(f"held-out Dice {summary['dice_mean']:.4f} ± {summary['dice_std']:.4f} (target ≥ {TARGET_DICE}); "
              f"HD {summary['hd_mean']:.2f} mm, HD95 {summary['hd95_mean']:.2f} mm, "
              f"MSD {summary['msd_mean']:.2f} mm; inference {t_test / max(args.test, 1):.2f} s per volume")
        print(f"porecad ivd --segmenter unet: {summary['ivd_unet']['discs']} discs, Dice "
              f"{summary['ivd_unet']['dice']:.4f}, scaffolds closed+manifold {summary['ivd_unet']['scaffolds_closed']}")
        if args.with_2d:
            u = summary["unet2d"]
            print(f"2D U-Nets ({u['train_s']:.0f} s): Dice x {u['x']:.4f}, y {u['y']:.4f}, z {u['z']:.4f}, "
                  f"merged {u['merged']:.4f}")
        print("PASS" if summary["pass"] else "FAIL")
    return 0 if summary["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
