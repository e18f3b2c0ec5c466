"""Training data for the disc U-Nets: normalised channels, instance targets, crops (000 §6.2.1, §6.2.4).

Torch-free helpers shared by training and prediction (they import numpy and
scipy only, so the extra is needed only for the networks themselves).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def normalise(volume: np.ndarray) -> np.ndarray:
    """Per-channel scaling by the 99th percentile (robust to noise and bias), clipped to [0, 2].

    ``volume`` is ``(C, nx, ny, nz)``; returns float32 of the same shape.
    """
    v = np.asarray(volume, dtype=np.float32)
    out = np.empty_like(v)
    for c in range(v.shape[0]):
        hi = float(np.percentile(v[c], 99.0))
        lo = float(np.percentile(v[c], 1.0))
        scale = hi - lo if hi > lo else 1.0
        out[c] = np.clip((v[c] - lo) / scale, 0.0, 2.0)
    return out


def instances(labels: np.ndarray) -> np.ndarray:
    """Instance labels: as given when they already number the discs, else the connected components."""
    from scipy import ndimage
    lab = np.asarray(labels)
    if int(lab.max()) > 1:
        return lab.astype(np.int32)
    comp, _ = ndimage.label(lab > 0)
    return comp.astype(np.int32)


def centres(inst: np.ndarray) -> list[np.ndarray]:
    """Centroids (fractional voxel indices) of instances 1..n."""
    from scipy import ndimage
    n = int(inst.max())
    if n == 0:
        return []
    return [np.asarray(c) for c in ndimage.center_of_mass(inst > 0, inst, range(1, n + 1))]


def crop(volume: np.ndarray, centre, size) -> tuple[np.ndarray, tuple]:
    """A ``size`` box of the last three axes around ``centre``, zero-padded outside; and its start index."""
    size = np.asarray(size, dtype=int)
    start = np.round(np.asarray(centre, dtype=float) - size / 2.0).astype(int)
    shape = np.asarray(volume.shape[-3:])
    out = np.zeros(volume.shape[:-3] + tuple(size), dtype=volume.dtype)
    lo = np.maximum(start, 0)
    hi = np.minimum(start + size, shape)
    if np.any(hi <= lo):
        return out, tuple(start)
    src = (Ellipsis,) + tuple(slice(a, b) for a, b in zip(lo, hi))
    dst = (Ellipsis,) + tuple(slice(a - s, b - s) for a, b, s in zip(lo, hi, start))
    out[dst] = volume[src]
    return out, tuple(int(s) for s in start)


def paste(target: np.ndarray, patch: np.ndarray, start, value) -> None:
    """Write ``value`` into ``target`` where ``patch`` is true and ``target`` is still 0."""
    start = np.asarray(start, dtype=int)
    size = np.asarray(patch.shape)
    lo = np.maximum(start, 0)
    hi = np.minimum(start + size, np.asarray(target.shape))
    if np.any(hi <= lo):
        return
    t = target[tuple(slice(a, b) for a, b in zip(lo, hi))]
    p = patch[tuple(slice(a - s, b - s) for a, b, s in zip(lo, hi, start))]
    t[(t == 0) & p] = value


def coarse(volume: np.ndarray, pool) -> np.ndarray:
    """Average-pool the last three axes by integer factors ``pool`` (trailing voxels dropped)."""
    f = [int(p) for p in pool]
    v = np.asarray(volume, dtype=np.float32)
    shape = v.shape[-3:]
    n = [s // p for s, p in zip(shape, f)]
    if min(n) < 1:
        raise InputError(f"image {shape} is smaller than the pooling {tuple(f)}")
    v = v[(Ellipsis,) + tuple(slice(0, a * p) for a, p in zip(n, f))]
    v = v.reshape(v.shape[:-3] + (n[0], f[0], n[1], f[1], n[2], f[2]))
    return v.mean(axis=(-5, -3, -1))


def pad_to_multiple(volume: np.ndarray, m: int) -> np.ndarray:
    """Zero-pad the last three axes up to multiples of ``m``."""
    shape = volume.shape[-3:]
    pad = [(0, (-s) % m) for s in shape]
    return np.pad(volume, [(0, 0)] * (volume.ndim - 3) + pad)


def subject_arrays(stack, channels) -> tuple[np.ndarray, np.ndarray | None]:
    """``(normalised (C, ...) image, instance labels or None)`` of a stack for the given channels."""
    img = normalise(stack.array(channels))
    lab = instances(stack.labels) if stack.labels is not None else None
    return img, lab
