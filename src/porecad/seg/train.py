"""Training of the disc U-Nets (000 §6.2.2, §6.2.4, §6.2.5).

* Loss: the Dice loss of eq. 6.2.2, ``1 − (2 I + S) / (ΣT + ΣP + S)`` with
  ``S = 1`` on sigmoid probabilities (MONAI ``DiceLoss``; :func:`dice_loss`
  is the same formula written out).
* Augmentation (§6.2.2): random affine (rotation, scaling, shear,
  translation) and elastic deformation (a random displacement grid smoothed
  by a Gaussian of σ and scaled by α) — MONAI ``RandAffined`` and
  ``Rand3DElasticd`` applied to image and label together (labels nearest).
  000 augments whole volumes offline (6 → 24); here each training crop is
  augmented on the fly, which is cheaper on a CPU.
* Optimiser: Adam. 000 uses 1e-5 for 10,000 GPU epochs; the CPU default is
  1e-3 for a few hundred steps (a deliberate deviation).
* 3D two-stage pipeline (§6.2.4): a localiser (MONAI U-Net on the volume
  average-pooled by ``pool``) learns the coarse disc mask whose connected
  components give the centres; the segmentation network
  (:class:`~porecad.seg.nets.SegUNet3D`) learns each disc from a fixed crop
  around its centre (jittered by a few voxels to mimic localisation error),
  predicting only the disc at the centre.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from . import data as D
from .optimise import apply_augment, fit, make_augment

DEFAULT_CROP = (36, 36, 28)  # 000 §6.2.4.1: 35×35×25 boxes zero-padded to 36×36×28
DEFAULT_POOL = (1, 2, 2)


def parse_ints(text, name):
    try:
        vals = tuple(int(x) for x in str(text).split(",") if x.strip())
    except ValueError:
        raise InputError(f"{name} takes comma-separated integers, got {text!r}") from None
    if len(vals) < 2 or min(vals) < 1:
        raise InputError(f"{name} needs at least two positive channel counts, got {text!r}")
    return vals


def train_3d(subjects, channels, iterations: int = 300, loc_iterations: int | None = None,
             features=(16, 32, 64), loc_features=(8, 16, 32), crop=DEFAULT_CROP, pool=DEFAULT_POOL,
             lr: float = 1e-3, augment: bool = True, seed: int = 0, batch: int = 2, jitter: int = 3,
             dropout: float = 0.2, log=None):
    """Train the two-stage 3D pipeline.

    Parameters
    ----------
    subjects : list of (image, instance labels)
        Normalised ``(C, nx, ny, nz)`` arrays (:func:`porecad.seg.data.subject_arrays`).
    channels : list of str
        Channel names (stored in the checkpoint meta).
    iterations, loc_iterations : int
        Optimiser steps of the segmentation network and the localiser
        (default: the same).

    Returns
    -------
    nets : dict
        ``{"localiser": ..., "segmenter": ...}`` (eval mode).
    meta : dict
        Everything prediction needs, plus the loss histories' summary.
    history : dict
        ``{"localiser": [...], "segmenter": [...]}`` per-step losses.
    """
    import torch

    _check_subjects(subjects, channels)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    loc_iterations = iterations if loc_iterations is None else loc_iterations
    t0 = time.perf_counter()
    localiser, hist_loc = _fit_localiser(subjects, channels, loc_iterations, loc_features, pool, lr,
                                         augment, seed, rng, log, t0)
    segmenter, hist_seg, n_discs = _fit_segmenter(subjects, channels, iterations, features, crop, lr, augment,
                                                  seed, rng, batch, jitter, dropout, log, t0)
    meta = {"model": "3d", "channels": list(channels), "features": list(features),
            "loc_features": list(loc_features), "crop": list(crop), "pool": list(pool), "dropout": dropout,
            "normalisation": "per-channel 1st-99th percentile to [0, 1], clipped at 2",
            "training": {"subjects": len(subjects), "discs": n_discs, "iterations": iterations,
                         "loc_iterations": loc_iterations, "lr": lr, "augment": augment, "seed": seed,
                         "batch": batch, "final_loss": float(np.mean(hist_seg[-10:])),
                         "final_loc_loss": float(np.mean(hist_loc[-10:])),
                         "time_s": time.perf_counter() - t0}}
    return {"localiser": localiser, "segmenter": segmenter}, meta, {"localiser": hist_loc, "segmenter": hist_seg}


def _check_subjects(subjects, channels):
    """Check the training ``subjects`` (list of (image, labels)) against ``channels``; returns nothing,
    raises :class:`InputError` when there are none, one lacks a disc or the channel count differs."""
    if not subjects:
        raise InputError("no training subjects")
    for img, lab in subjects:
        if lab is None or lab.max() == 0:
            raise InputError("every training subject needs a label map with at least one disc")
        if img.shape[0] != len(channels):
            raise InputError("channel count mismatch in the training data")


def _fit_localiser(subjects, channels, loc_iterations, loc_features, pool, lr, augment, seed, rng, log, t0):
    """Stage 1: train the localiser on the subjects' coarse (``pool``-averaged) images and disc masks,
    drawing subjects from ``rng``; returns ``(localiser, per-step losses)``."""
    from .nets import localiser_3d
    m = 2 ** (len(loc_features) - 1)
    coarse = []
    for img, lab in subjects:
        ci = D.pad_to_multiple(D.coarse(img, pool), m)
        cl = D.pad_to_multiple((D.coarse((lab > 0)[None].astype(np.float32), pool) > 0.5).astype(np.float32), m)
        coarse.append((ci, cl))
    aug_loc = make_augment(seed + 1, elastic=False) if augment else None

    def sample_loc():
        ci, cl = coarse[int(rng.integers(len(coarse)))]
        return apply_augment(aug_loc, ci, cl)

    # sizes differ between subjects only if the images do; batch 1 for the localiser
    localiser = localiser_3d(len(channels), loc_features)
    return localiser, fit(localiser, sample_loc, loc_iterations, lr, log, "localiser", batch=1, t0=t0)


def _fit_segmenter(subjects, channels, iterations, features, crop, lr, augment, seed, rng, batch, jitter,
                   dropout, log, t0):
    """Stage 2: train the segmentation network on ``crop``-sized boxes around (``jitter``-ed, from ``rng``)
    disc centres; returns ``(segmenter, per-step losses, number of training discs)``."""
    from .nets import SegUNet3D
    discs = []
    for si, (img, lab) in enumerate(subjects):
        for d, c in enumerate(D.centres(lab), start=1):
            discs.append((si, d, c))
    aug_seg = make_augment(seed + 2) if augment else None

    def sample_seg():
        si, d, c = discs[int(rng.integers(len(discs)))]
        img, lab = subjects[si]
        centre = c + rng.integers(-jitter, jitter + 1, 3)
        x, start = D.crop(img, centre, crop)
        y, _ = D.crop((lab == d)[None].astype(np.float32), centre, crop)
        return apply_augment(aug_seg, x, y)

    segmenter = SegUNet3D(len(channels), features, dropout=dropout)
    hist_seg = fit(segmenter, sample_seg, iterations, lr, log, "segmenter", batch=batch, t0=t0)
    return segmenter, hist_seg, len(discs)


def phantom_subjects(n: int, channels, seed: int = 0, n_discs=(3, 4)):
    """``n`` generated phantoms as training subjects (seeds ``seed``, ``seed + 1``, …)."""
    from ..imaging.phantom import spine_phantom
    out = []
    for i in range(n):
        ph = spine_phantom(n_discs[i % len(n_discs)], seed=seed + i)
        missing = [c for c in channels if c not in ph["channels"]]
        if missing:
            raise InputError(f"the phantom has channels inn, opp, fat, wat; not {', '.join(missing)}")
        img = D.normalise(np.stack([ph["channels"][c] for c in channels]))
        out.append((img, ph["labels"].astype(np.int32)))
    return out


def train_from_cli(data_dir, out, model="3d", phantoms=None, iterations=300, channels=("opp", "wat", "fat"),
                   features=(16, 32, 64), lr=1e-3, augment=True, seed=0, threads=2, force=False, log=None) -> dict:
    """``porecad seg train``: load data, train, save the checkpoint; returns a summary."""
    import torch

    from ..io import check_output_path
    from .checkpoint import save_checkpoint
    check_output_path(out, force=force)
    if iterations < 1:
        raise InputError("`iterations` must be ≥ 1")
    if lr <= 0:
        raise InputError("`lr` must be > 0")
    torch.set_num_threads(max(1, int(threads)))
    if (data_dir is None) == (phantoms is None):
        raise InputError("give a data folder (labelled subjects) or a number of `phantoms`")
    if phantoms is not None:
        if phantoms < 1:
            raise InputError("`phantoms` must be ≥ 1")
        subjects = phantom_subjects(phantoms, channels, seed=10_000 + seed)
    else:
        from ..imaging.challenge import load_dataset
        subjects = []
        for stack, sid in load_dataset(data_dir, channels):
            if stack.labels is None:
                raise InputError(f"subject {sid} has no label map (<id>_Labels.nii); training needs labels")
            subjects.append(D.subject_arrays(stack, channels))
    if log:
        log(f"training the {model} model on {len(subjects)} subjects, channels {', '.join(channels)}")
    if model == "3d":
        nets, meta, hist = train_3d(subjects, list(channels), iterations=iterations, features=features, lr=lr,
                                    augment=augment, seed=seed, log=log)
        fmt = "porecad-ivd-unet3d"
    else:
        from .slices import train_2d
        nets, meta, hist = train_2d(subjects, list(channels), iterations=iterations, features=features, lr=lr,
                                    augment=augment, seed=seed, log=log)
        fmt = "porecad-ivd-unet2d"
    path = save_checkpoint(out, fmt, meta, nets, force=force)
    return {"checkpoint": str(path), "model": model, "subjects": len(subjects),
            "final_loss": meta["training"]["final_loss"], "time_s": meta["training"]["time_s"],
            "first_loss": float(np.mean(next(iter(hist.values()))[:10])), "meta": meta}
