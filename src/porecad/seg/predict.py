"""Prediction with a trained checkpoint (000 §6.2.4.3 post-processing).

3D (two-stage): the localiser's sigmoid output on the pooled volume is
thresholded at 0.5; each connected component's centroid is a disc centre; the
fixed-size crop around it goes through the segmentation network; its
sigmoid is thresholded at 0.5, the component nearest the crop centre is
kept, and the patch is pasted back at its centre with its own instance
label (discs numbered from the superior, high-``k`` end).

2D: see :mod:`porecad.seg.slices` (slices along x, y and z, merged).
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from . import data as D


def build_3d(meta: dict, nets: dict, path):
    """The two networks of a 3D checkpoint with their weights loaded (eval mode)."""
    from .checkpoint import load_into
    from .nets import SegUNet3D, localiser_3d
    try:
        loc = localiser_3d(len(meta["channels"]), meta["loc_features"])
        segm = SegUNet3D(len(meta["channels"]), meta["features"], dropout=float(meta.get("dropout", 0.2)))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: checkpoint meta data incomplete ({exc})") from None
    for name, model in (("localiser", loc), ("segmenter", segm)):
        if name not in nets:
            raise InputError(f"{path}: checkpoint has no {name} weights")
        load_into(model, nets[name], name, path)
        model.eval()
    return loc, segm


def _keep_central(mask: np.ndarray) -> np.ndarray:
    """The connected component of ``mask`` nearest the patch centre."""
    from scipy import ndimage
    lab, n = ndimage.label(mask)
    if n <= 1:
        return mask
    centre = (np.asarray(mask.shape) - 1) / 2.0
    best, best_d = 1, np.inf
    for i, c in enumerate(ndimage.center_of_mass(mask, lab, range(1, n + 1)), start=1):
        size = np.count_nonzero(lab == i)
        d = np.linalg.norm(np.asarray(c) - centre) / np.sqrt(size)
        if d < best_d:
            best, best_d = i, d
    return lab == best


def predict_3d(image: np.ndarray, meta: dict, loc, segm, min_coarse_voxels: int = 8):
    """Instance labels of a normalised ``(C, nx, ny, nz)`` image; and the centres found."""
    import torch
    from scipy import ndimage
    pool = meta["pool"]
    m = 2 ** (len(meta["loc_features"]) - 1)
    ci = D.pad_to_multiple(D.coarse(image, pool), m)
    with torch.no_grad():
        prob = torch.sigmoid(loc(torch.from_numpy(ci[None]))).numpy()[0, 0]
    lab, n = ndimage.label(prob > 0.5)
    centres = []
    for i, sl in enumerate(ndimage.find_objects(lab), start=1):
        if sl is None or np.count_nonzero(lab[sl] == i) < min_coarse_voxels:
            continue
        c = np.asarray(ndimage.center_of_mass(lab == i))
        centres.append(c * np.asarray(pool) + (np.asarray(pool) - 1) / 2.0)
    shape = image.shape[1:]
    centres = [c for c in centres if np.all(c >= 0) and np.all(c < np.asarray(shape))]
    centres.sort(key=lambda c: -c[2])
    out = np.zeros(shape, dtype=np.int16)
    crop = meta["crop"]
    patches = []
    for c in centres:
        x, start = D.crop(image, c, crop)
        with torch.no_grad():
            p = torch.sigmoid(segm(torch.from_numpy(x[None]))).numpy()[0, 0]
        mask = p > 0.5
        if mask.any():
            patches.append((_keep_central(mask), start))
    for n_, (mask, start) in enumerate(patches, start=1):
        D.paste(out, mask, start, n_)
    # renumber (a patch may have been fully covered by an earlier one)
    present = [v for v in np.unique(out) if v > 0]
    remap = np.zeros(max(present, default=0) + 1, dtype=np.int16)
    for new, old in enumerate(present, start=1):
        remap[old] = new
    return remap[out], [c.tolist() for c in centres]


def predict_stack(stack, checkpoint, log=None):
    """Segment a :class:`~porecad.imaging.io.Stack` with a checkpoint: ``(labels, info)``."""
    from .checkpoint import load_checkpoint
    t0 = time.perf_counter()
    fmt, meta, nets = load_checkpoint(checkpoint)
    channels = meta.get("channels")
    if not channels:
        raise InputError(f"{checkpoint}: checkpoint meta data has no channels")
    missing = [c for c in channels if c not in stack.channels]
    if missing:
        raise InputError(f"the checkpoint needs channel(s) {', '.join(channels)}; the image has "
                         f"{', '.join(stack.names)}")
    image = D.normalise(stack.array(channels))
    if fmt == "porecad-ivd-unet3d":
        loc, segm = build_3d(meta, nets, checkpoint)
        labels, centres = predict_3d(image, meta, loc, segm)
        info = {"segmenter": "unet3d", "centres_voxel": centres}
    else:
        from .slices import build_2d, predict_2d
        models = build_2d(meta, nets, checkpoint)
        labels, extra = predict_2d(image, meta, models)
        info = {"segmenter": "unet2d", **extra}
    info.update(checkpoint=str(checkpoint), discs=int(labels.max()), time_s=time.perf_counter() - t0)
    if log:
        log(f"{info['segmenter']}: {info['discs']} discs in {info['time_s']:.1f} s")
    return labels, info
