"""``porecad ivd``, ``porecad seg`` and ``porecad phantom``: patient-specific porous discs (000 ch.6)."""

from __future__ import annotations

import sys

import click

from ..errors import InputError
from ..io.jsonable import dumps
from .console import run_job
from .options import FiniteRange, keyed_in, max_memory_option

option = keyed_in("ivd")

EXAMPLES = """
\b
Examples:
  porecad phantom spine -o spine/ --discs 3 --seed 0
  porecad ivd spine/ --segmenter classical --method tpms --method tis -o discs/ --json
  porecad ivd spine/ --segmenter classical --method all -o discs/
  porecad seg train --phantoms 12 -o ivd.pt --iterations 400
  porecad ivd spine/ --segmenter unet --checkpoint ivd.pt --method tpms -o discs-unet/
"""


def _log_to_stderr(enabled=True):
    def log(msg):
        if enabled:
            click.echo(f"porecad: {msg}", err=True)
    return log


def ivd_recipe(image_dir, segmenter, methods, out_dir, checkpoint=None, channels=None, discs=None,
               smooth_iterations=10, recipe_out=None, reports=False) -> dict:
    """The recipe of a ``porecad ivd`` command line."""
    inp = {"path": str(image_dir), "segmenter": segmenter}
    if checkpoint:
        inp["checkpoint"] = str(checkpoint)
    if channels:
        inp["channels"] = [c.strip() for c in channels.split(",") if c.strip()]
    recipe = {"job": "ivd", "input": inp, "methods": list(methods), "smooth_iterations": smooth_iterations,
              "output": {k: v for k, v in (("dir", out_dir), ("recipe", recipe_out)) if v}}
    if reports:
        recipe["reports"] = True
    if discs:
        try:
            recipe["discs"] = [int(x) for x in discs.split(",")]
        except ValueError:
            raise InputError(f"--discs takes comma-separated integers, got {discs!r}") from None
    return recipe


@click.command(epilog=EXAMPLES)
@click.argument("image_dir", type=click.Path())
@option("input.segmenter", "--segmenter", help="classical: threshold + morphology + components (no training); unet: the two-stage 3D U-Net "
            "of 000 §6.2.4 from --checkpoint (needs porecad[seg]).")
@option("methods", "--method", "methods", multiple=True, type=click.Choice(["tpms", "tbss", "tis", "arbf", "all"]),
       help="Porous design method(s), repeatable; all: every installed one.")
@option("output.dir", "-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False),
       help="Output directory.")
@option("input.checkpoint", "--checkpoint", type=click.Path(dir_okay=False),
       help="U-Net checkpoint (porecad seg train).")
@option("input.channels", "--channels", help="Comma-separated channels to read (default: all found; e.g. opp,wat,fat).")
@option("discs", "--discs", help="Comma-separated disc numbers to build (1 = most superior; default all).")
@option("smooth_iterations", "--smooth-iterations", type=int,
       help="Taubin smoothing of each disc's marching-cubes surface.")
@option("reports", "--reports", is_flag=True,
       help="Also write a report directory per scaffold (HTML, plots; measured inside that disc).")
@option("output.recipe", "--recipe", "recipe_out", type=click.Path(dir_okay=False),
       help="Also write the recipe (TOML) that regenerates these outputs with `porecad build`.")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@max_memory_option
def ivd(image_dir, segmenter, methods, out_dir, checkpoint, channels, discs, smooth_iterations, reports, recipe_out,
        force, as_json):
    """Segment the discs of IMAGE_DIR and build one closed porous scaffold per disc and method.

    IMAGE_DIR: a subject folder in the IVD challenge layout (<id>_opp/_wat/_fat/_inn
    NIfTI/MHA/NRRD, optional <id>_Labels), channel subfolders holding DICOM series,
    or one image. Writes segmentation.nii.gz, disc_NN_body.stl, disc_NN_METHOD.stl,
    ivd_report.json and ivd_report.html to --out.
    """
    recipe = ivd_recipe(image_dir, segmenter, methods, out_dir, checkpoint, channels, discs, smooth_iterations,
                        recipe_out, reports)
    report = run_job(recipe, force, as_json)
    if as_json:
        return
    if report.get("skipped_methods"):
        click.echo(f"{'skipped':>18}: {', '.join(report['skipped_methods'])} (not installed)")
    if "metrics" in report:
        a = report["metrics"]["all"]
        click.echo(f"{'segmentation':>18}: Dice {a['dice']:.3f}, HD {a['hd']:.2f} mm, HD95 {a['hd95']:.2f} mm, "
                   f"MSD {a['msd']:.2f} mm")
    for d in report["discs"]:
        for m, s in d["scaffolds"].items():
            click.echo(f"{'disc ' + str(d['disc']) + ' ' + m:>18}: porosity {s['porosity']:.3f}, "
                       f"{s['triangles']} triangles, closed {s['closed']}, manifold {s['manifold']} "
                       f"-> {s['mesh_file']}")
    click.echo(f"{'report_file':>18}: {report['report_file']}")


@click.group()
def phantom():
    """Generated test images (000 ch.6 phantoms)."""


@phantom.command("spine")
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False), help="Output directory.")
@click.option("--discs", type=click.IntRange(1, 64), default=3, show_default=True, help="Number of discs.")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True, help="Random seed.")
@click.option("--subject", default="01", show_default=True, help="Subject id in the file names.")
@click.option("--spacing", nargs=3, type=FiniteRange(0.01, 100.0), default=(2.0, 1.25, 1.25), show_default=True,
              help="Voxel size in mm (x y z).")
@click.option("--noise", type=FiniteRange(0.0, 10.0), default=0.04, show_default=True, help="Rician noise (relative).")
@click.option("--bias", type=FiniteRange(0.0, 10.0), default=0.15, show_default=True,
              help="Bias field amplitude (relative).")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as one JSON object.")
def phantom_spine(out_dir, discs, seed, subject, spacing, noise, bias, force, as_json):
    """A multi-modal (Dixon inn/opp/fat/wat) spine phantom with its disc labels, as NIfTI in the
    IVD challenge layout: OUT/<subject>_{inn,opp,fat,wat}.nii.gz and OUT/<subject>_Labels.nii.gz."""
    from pathlib import Path

    from ..errors import OutputError
    from ..imaging.phantom import spine_phantom, weber_contrast, write_phantom
    d = Path(out_dir)
    if d.exists() and not d.is_dir():
        raise OutputError(f"{d}: is a file, not a directory")
    # check before creating anything
    from ..io import check_output_path
    from ..io.atomic import check_output_dir
    check_output_dir(d)
    if d.exists():
        for name in ("inn", "opp", "fat", "wat", "Labels"):
            check_output_path(d / f"{subject}_{name}.nii.gz", force=force)
    ph = spine_phantom(discs, seed=seed, spacing=spacing, noise=noise, bias=bias)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {d}: {exc.strerror}") from None
    files = write_phantom(d, ph, subject=subject, force=force)
    mask = ph["labels"] > 0
    summary = {"files": files, "shape": ph["shape"], "geometry": ph["geometry"], "discs": ph["discs"],
               "seed": ph["seed"],
               "weber_contrast": {n: weber_contrast(c, mask) for n, c in ph["channels"].items()}}
    if as_json:
        click.echo(dumps(summary))
    else:
        click.echo(f"{'shape':>18}: {'x'.join(map(str, ph['shape']))} voxels of "
                   f"{' x '.join(f'{s:g}' for s in ph['geometry']['spacing'])} mm")
        click.echo(f"{'discs':>18}: {len(ph['discs'])}")
        for k, v in files.items():
            click.echo(f"{k:>18}: {v}")


@click.group()
def seg():
    """Disc segmentation (000 §6.2): U-Nets (train, predict: need porecad[seg]), classical, evaluate."""


@seg.command("train")
@click.argument("data_dir", required=False, type=click.Path())
@click.option("-o", "--out", "out", required=True, type=click.Path(dir_okay=False),
              help="Checkpoint file to write (.pt; weights only, plus OUT.json with the settings).")
@click.option("--model", type=click.Choice(["3d", "2d"]), default="3d", show_default=True,
              help="3d: two-stage localiser + per-disc U-Net (000 §6.2.4); 2d: slice U-Nets along x, y, z (§6.2.3).")
@click.option("--phantoms", type=click.IntRange(1, 1000), help="Train on N generated phantoms instead of DATA_DIR.")
@click.option("--iterations", type=click.IntRange(1, 1_000_000), default=300, show_default=True,
              help="Optimiser steps per network.")
@click.option("--channels", default="opp,wat,fat", show_default=True,
              help="Input channels (000 Table 6.3: opp, wat, fat is best).")
@click.option("--features", default="16,32,64", show_default=True,
              help="Channels per U-Net level (000 Table 6.2: 32,64,128).")
@click.option("--lr", type=FiniteRange(0.0, 10.0, open_lo=True), default=1e-3, show_default=True,
       help="Adam learning rate (000: 1e-5 on a GPU).")
@click.option("--augment/--no-augment", default=True, show_default=True, help="Affine + elastic augmentation.")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True)
@click.option("--threads", type=click.IntRange(1, 1024), default=2, show_default=True, help="Torch threads.")
@click.option("--force", is_flag=True, help="Overwrite an existing checkpoint.")
@click.option("--json", "as_json", is_flag=True, help="Print the training summary as one JSON object.")
def seg_train(data_dir, out, model, phantoms, iterations, channels, features, lr, augment, seed, threads, force,
              as_json):
    """Train a disc segmenter on DATA_DIR (challenge layout, labels required) or on --phantoms N."""
    from .. import seg as segpkg
    segpkg.require_torch()
    from ..seg.train import parse_ints, train_from_cli
    summary = train_from_cli(data_dir, out, model=model, phantoms=phantoms, iterations=iterations,
                             channels=[c.strip() for c in channels.split(",") if c.strip()],
                             features=parse_ints(features, "--features"), lr=lr, augment=augment, seed=seed,
                             threads=threads, force=force, log=_log_to_stderr(True))
    if as_json:
        click.echo(dumps(summary))
    else:
        click.echo(f"{'checkpoint':>18}: {summary['checkpoint']}")
        click.echo(f"{'final loss':>18}: {summary['final_loss']:.4f}")
        click.echo(f"{'time':>18}: {summary['time_s']:.1f} s")


@seg.command("predict")
@click.argument("image_dir", type=click.Path())
@click.option("--checkpoint", required=True, type=click.Path(dir_okay=False), help="Checkpoint from seg train.")
@click.option("-o", "--out", "out", required=True, type=click.Path(dir_okay=False),
              help="Label map to write (.nii.gz, .mha, .nrrd): 0 background, 1..n discs.")
@click.option("--threads", type=click.IntRange(1, 1024), default=2, show_default=True, help="Torch threads.")
@click.option("--force", is_flag=True, help="Overwrite an existing output.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary (and metrics with labels) as JSON.")
def seg_predict(image_dir, checkpoint, out, threads, force, as_json):
    """Segment the discs of IMAGE_DIR with a trained checkpoint; score against its labels if present."""
    from .. import seg as segpkg
    torch = segpkg.require_torch()
    from ..imaging.challenge import find_subjects, load_subject
    from ..imaging.io import write_volume
    from ..imaging.metrics import evaluate_labels
    from ..io import check_output_path
    from ..seg.predict import predict_stack
    check_output_path(out, force=force)
    torch.set_num_threads(max(1, int(threads)))
    subjects = find_subjects(image_dir)
    if len(subjects) > 1:
        raise InputError(f"{image_dir}: holds {len(subjects)} subjects; give one subject folder")
    stack, subject = load_subject(subjects[0])
    labels, info = predict_stack(stack, checkpoint, log=_log_to_stderr(sys.stderr.isatty()))
    write_volume(out, labels.astype("uint8"), stack.geometry, force=force)
    summary = {"subject": subject, "output": str(out), "discs": int(labels.max()), **info}
    if stack.labels is not None:
        summary["metrics"] = evaluate_labels(stack.labels, labels, stack.geometry["spacing"])
    if as_json:
        click.echo(dumps(summary))
    else:
        click.echo(f"{'discs':>18}: {summary['discs']}")
        if "metrics" in summary:
            a = summary["metrics"]["all"]
            click.echo(f"{'Dice':>18}: {a['dice']:.4f}")
            click.echo(f"{'HD / HD95 / MSD':>18}: {a['hd']:.2f} / {a['hd95']:.2f} / {a['msd']:.2f} mm")
        click.echo(f"{'output':>18}: {out}")


@seg.command("evaluate")
@click.argument("truth", type=click.Path())
@click.argument("prediction", type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print the metrics as one JSON object.")
def seg_evaluate(truth, prediction, as_json):
    """Dice/DOC, Hausdorff (max, 95th percentile) and mean surface distance of two label maps
    (000 §6.2.6; distances in mm from the images' spacing). Needs no extra."""
    from ..imaging.io import geometry_mismatch, read_volume
    from ..imaging.metrics import evaluate_labels
    t, gt = read_volume(truth)
    p, gp = read_volume(prediction)
    why = geometry_mismatch(gt, gp, t.shape, p.shape)
    if why:
        raise InputError(f"{prediction} does not match {truth}: {why}")
    res = evaluate_labels(t.astype(int), p.astype(int), gt["spacing"])
    if as_json:
        click.echo(dumps(res))
    else:
        a = res["all"]
        click.echo(f"{'Dice (DOC)':>18}: {a['dice']:.4f}")
        click.echo(f"{'Hausdorff':>18}: {a['hd']:.3f} mm")
        click.echo(f"{'Hausdorff 95%':>18}: {a['hd95']:.3f} mm")
        click.echo(f"{'mean surface dist':>18}: {a['msd']:.3f} mm")


@seg.command("classical")
@click.argument("image_dir", type=click.Path())
@click.option("-o", "--out", "out", required=True, type=click.Path(dir_okay=False),
              help="Label map to write (.nii.gz, .mha, .nrrd).")
@click.option("--ct-bone", is_flag=True, help="Bone in CT (HU threshold) instead of discs in MR.")
@click.option("--threshold", type=FiniteRange(-1e7, 1e7), default=250.0, show_default=True,
              help="--ct-bone: HU threshold.")
@click.option("--min-volume", type=FiniteRange(0.0, 1e12), default=500.0, show_default=True,
              help="--ct-bone: smallest kept component (mm³).")
@click.option("--force", is_flag=True, help="Overwrite an existing output.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary (and metrics with labels) as JSON.")
def seg_classical(image_dir, out, ct_bone, threshold, min_volume, force, as_json):
    """Classical segmentation (threshold, morphology, connected components; needs no extra):
    discs in Dixon/T2 MR, or with --ct-bone bone in CT. IMAGE_DIR: a subject folder or one image."""
    from ..imaging.challenge import find_subjects, load_subject
    from ..imaging.classical import segment_ct_bone, segment_discs
    from ..imaging.io import write_volume
    from ..imaging.metrics import evaluate_labels
    from ..io import check_output_path
    check_output_path(out, force=force)
    subjects = find_subjects(image_dir)
    if len(subjects) > 1:
        raise InputError(f"{image_dir}: holds {len(subjects)} subjects; give one subject folder")
    stack, subject = load_subject(subjects[0])
    spacing = stack.geometry["spacing"]
    if ct_bone:
        if len(stack.channels) != 1:
            raise InputError("--ct-bone segments one CT image; this input has channels " + ", ".join(stack.names))
        labels, info = segment_ct_bone(next(iter(stack.channels.values())), spacing, threshold=threshold,
                                       min_volume_mm3=min_volume)
    else:
        labels, info = segment_discs(stack.channels, spacing)
    if labels.max() > 255:
        raise InputError(f"{int(labels.max())} components; too many for a label map (raise --min-volume)")
    write_volume(out, labels.astype("uint8"), stack.geometry, force=force)
    summary = {"subject": subject, "output": str(out), **{k: v for k, v in info.items()}}
    if stack.labels is not None and not ct_bone:
        summary["metrics"] = evaluate_labels(stack.labels, labels, spacing)
    if as_json:
        click.echo(dumps(summary))
    else:
        n = info.get("discs", info.get("components"))
        click.echo(f"{'components':>18}: {n}")
        if "metrics" in summary:
            click.echo(f"{'Dice':>18}: {summary['metrics']['all']['dice']:.4f}")
        click.echo(f"{'output':>18}: {out}")
