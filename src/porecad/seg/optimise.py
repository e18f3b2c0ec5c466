"""Training steps shared by the 3D and 2D segmenters: Dice loss, augmentation, the Adam loop (000 §6.2)."""

from __future__ import annotations

import time

import numpy as np


def dice_loss(logits, target, smooth: float = 1.0):
    """000 eq. 6.2.2 as a loss: ``1 − (2 I + S) / (ΣT + ΣP + S)`` over the whole batch."""
    import torch
    p = torch.sigmoid(logits)
    inter = (p * target).sum()
    return 1.0 - (2.0 * inter + smooth) / (target.sum() + p.sum() + smooth)


def make_loss():
    """MONAI's Dice loss configured as eq. 6.2.2 (sigmoid, S = 1 in numerator and denominator, batch-pooled)."""
    from monai.losses import DiceLoss
    return DiceLoss(sigmoid=True, smooth_nr=1.0, smooth_dr=1.0, batch=True)


def make_augment(seed: int, elastic: bool = True):
    """Affine + elastic augmentation of ``{"image", "label"}`` (channel-first 3-D arrays)."""
    from monai.transforms import Compose, Rand3DElasticd, RandAffined
    ts = [RandAffined(keys=["image", "label"], prob=0.7, rotate_range=(0.15, 0.15, 0.15),
                      scale_range=(0.1, 0.1, 0.1), shear_range=(0.05, 0.05, 0.05), translate_range=(2, 2, 2),
                      mode=("bilinear", "nearest"), padding_mode="zeros")]
    if elastic:
        ts.append(Rand3DElasticd(keys=["image", "label"], prob=0.3, sigma_range=(5.0, 7.0),
                                 magnitude_range=(20.0, 60.0), mode=("bilinear", "nearest"),
                                 padding_mode="zeros"))
    t = Compose(ts)
    t.set_random_state(seed=seed)
    return t


def apply_augment(aug, img, lab):
    """``(image, label)`` after the augmentation ``aug`` (None: unchanged); labels binarised."""
    if aug is None:
        return img, lab
    out = aug({"image": img, "label": lab})
    im, lb = out["image"], out["label"]
    im = im.numpy() if hasattr(im, "numpy") else np.asarray(im)
    lb = lb.numpy() if hasattr(lb, "numpy") else np.asarray(lb)
    return np.asarray(im, dtype=np.float32), (np.asarray(lb) > 0.5).astype(np.float32)


def fit(model, sample, iterations, lr, log, name, batch=1, every=None, t0=None):
    """Adam + Dice loss for ``iterations`` steps of ``sample() -> (x, y)`` arrays; returns the loss history."""
    import torch
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    loss_fn = make_loss()
    model.train()
    history = []
    every = every or max(1, iterations // 10)
    t0 = time.perf_counter() if t0 is None else t0
    for it in range(1, iterations + 1):
        xs, ys = zip(*(sample() for _ in range(batch)))
        x = torch.from_numpy(np.stack(xs))
        y = torch.from_numpy(np.stack(ys))
        opt.zero_grad()
        loss = loss_fn(model(x), y)
        loss.backward()
        opt.step()
        history.append(float(loss.item()))
        if log and (it % every == 0 or it == iterations):
            recent = float(np.mean(history[-every:]))
            log(f"{name} {it}/{iterations} loss {recent:.4f} ({time.perf_counter() - t0:.0f} s)")
    model.eval()
    return history
