"""The 2-D U-Net of 000 §6.2.3: one network per slicing direction (x, y, z), merged.

Training slices are cut along each index axis of the (normalised) volumes,
zero-padded to a common size per direction (000 pads 256×36 slices to
256×256) and fed to a separate MONAI 2-D U-Net per direction with the Dice
loss of eq. 6.2.2. Augmentation here is 2-D affine + elastic on the slices
(000 slices 3-D-augmented volumes instead; cheaper on a CPU). Prediction runs
every slice of each direction, averages the three probability volumes and
thresholds at 0.5 — 000's "half of the maximum, 127.5" on a 0–255 scale —
then numbers the connected components (≥ ``min_voxels``) from the superior end.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from .optimise import apply_augment, fit

AXES = ("x", "y", "z")


def _slices(vol: np.ndarray, axis: int) -> np.ndarray:
    """``(C, nx, ny, nz)`` → ``(n_axis, C, h, w)``."""
    return np.moveaxis(vol, axis + 1, 0)


def _pad2(a: np.ndarray, size) -> np.ndarray:
    h, w = a.shape[-2:]
    if h > size[0] or w > size[1]:
        raise InputError(f"slice {h}x{w} is larger than the network's {size[0]}x{size[1]}")
    return np.pad(a, [(0, 0)] * (a.ndim - 2) + [(0, size[0] - h), (0, size[1] - w)])


def _size_for(shapes, m):
    hs = max(s[0] for s in shapes)
    ws = max(s[1] for s in shapes)
    return [hs + (-hs) % m, ws + (-ws) % m]


def make_augment_2d(seed: int):
    from monai.transforms import Compose, Rand2DElasticd, RandAffined
    t = Compose([RandAffined(keys=["image", "label"], prob=0.7, rotate_range=(0.15,), scale_range=(0.1, 0.1),
                             translate_range=(3, 3), mode=("bilinear", "nearest"), padding_mode="zeros"),
                 Rand2DElasticd(keys=["image", "label"], prob=0.3, spacing=(12, 12), magnitude_range=(1.0, 3.0),
                                mode=("bilinear", "nearest"), padding_mode="zeros")])
    t.set_random_state(seed=seed)
    return t


def train_2d(subjects, channels, iterations: int = 300, features=(16, 32, 64, 128), lr: float = 1e-3,
             augment: bool = True, seed: int = 0, batch: int = 8, log=None):
    """Train the three direction networks; returns ``(nets, meta, history)`` like :func:`train_3d`."""
    import torch

    from .nets import unet_2d
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    m = 2 ** (len(features) - 1)
    t0 = time.perf_counter()
    nets, hist, sizes = {}, {}, {}
    for axis, name in enumerate(AXES):
        imgs = [_slices(img, axis) for img, _ in subjects]
        labs = [_slices((lab > 0)[None].astype(np.float32), axis) for _, lab in subjects]
        size = _size_for([s.shape[-2:] for s in imgs], m)
        sizes[name] = size
        fg = [np.nonzero(lb.reshape(lb.shape[0], -1).any(axis=1))[0] for lb in labs]
        aug = make_augment_2d(seed + axis) if augment else None

        def sample(imgs=imgs, labs=labs, fg=fg, size=size, aug=aug):
            s = int(rng.integers(len(imgs)))
            if len(fg[s]) and rng.random() < 0.75:
                k = int(rng.choice(fg[s]))
            else:
                k = int(rng.integers(imgs[s].shape[0]))
            x, y = apply_augment(aug, _pad2(imgs[s][k], size), _pad2(labs[s][k], size))
            return x, y

        model = unet_2d(len(channels), features)
        hist[name] = fit(model, sample, iterations, lr, log, f"2d-{name}", batch=batch, t0=t0)
        nets[name] = model
    meta = {"model": "2d", "channels": list(channels), "features": list(features), "slice_size": sizes,
            "normalisation": "per-channel 1st-99th percentile to [0, 1], clipped at 2",
            "training": {"subjects": len(subjects), "iterations": iterations, "lr": lr, "augment": augment,
                         "seed": seed, "batch": batch,
                         "final_loss": float(np.mean([np.mean(h[-10:]) for h in hist.values()])),
                         "time_s": time.perf_counter() - t0}}
    return nets, meta, hist


def build_2d(meta: dict, nets: dict, path):
    from .checkpoint import load_into
    from .nets import unet_2d
    models = {}
    for name in AXES:
        if name not in nets:
            raise InputError(f"{path}: checkpoint has no 2-D {name} weights")
        model = unet_2d(len(meta["channels"]), meta["features"])
        load_into(model, nets[name], f"2-D {name}", path)
        model.eval()
        models[name] = model
    return models


def predict_probabilities(image: np.ndarray, meta: dict, models: dict, batch: int = 16) -> dict:
    """Per-direction IVD probability volumes of a normalised image."""
    import torch
    out = {}
    shape = image.shape[1:]
    for axis, name in enumerate(AXES):
        sl = _slices(image, axis)
        h, w = sl.shape[-2:]
        size = meta["slice_size"][name]
        size = [max(size[0], h + (-h) % 8), max(size[1], w + (-w) % 8)]
        probs = []
        with torch.no_grad():
            for i in range(0, sl.shape[0], batch):
                x = torch.from_numpy(np.ascontiguousarray(_pad2(sl[i:i + batch], size)))
                probs.append(torch.sigmoid(models[name](x)).numpy()[:, 0, :h, :w])
        p = np.concatenate(probs)  # (n_axis, h, w)
        out[name] = np.moveaxis(p, 0, axis).reshape(shape)
    return out


def predict_2d(image: np.ndarray, meta: dict, models: dict, min_voxels: int = 50):
    """Merged 2-D prediction: mean of the three directions > 0.5, components numbered from the top."""
    from scipy import ndimage
    probs = predict_probabilities(image, meta, models)
    merged = np.mean([probs[a] for a in AXES], axis=0) > 0.5
    lab, n = ndimage.label(merged)
    keep = []
    for i in range(1, n + 1):
        size = int(np.count_nonzero(lab == i))
        if size >= min_voxels:
            keep.append((ndimage.center_of_mass(lab == i)[2], i))
    keep.sort(key=lambda t: -t[0])
    out = np.zeros(lab.shape, dtype=np.int16)
    for new, (_, old) in enumerate(keep, start=1):
        out[lab == old] = new
    return out, {"directions": {a: {"voxels": int(np.count_nonzero(probs[a] > 0.5))} for a in AXES}}
