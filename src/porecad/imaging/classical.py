"""Classical segmentation: threshold, morphology and connected components (000 §6.1.1).

Quick-start segmenters that need no training:

* :func:`segment_discs` — intervertebral discs in Dixon MR: discs are bright
  on the water (and opposed-phase) image and dark on fat, so the score
  ``wat − fat`` (or the brightest available water-like channel) separates them
  from marrow, fat and most muscle. An Otsu threshold gives seeds; an opening
  cuts thin bridges; bright runs along the spine axis longer than a disc
  is high (the CSF-filled canal) are removed first; connected components are kept when they are disc-shaped
  (flat along the spine axis, within a volume range), which rejects the
  spinal canal (a long tube); each kept disc is then grown to the half level
  between its own median intensity and the upper quartile of its
  surroundings (so partial-volume voxels count once and the disc does not
  leak into the muscle beside it) and holes are filled. Discs are numbered from the superior end.
* :func:`segment_ct_bone` — bone in CT by a Hounsfield threshold, closing,
  hole filling and a component size filter.

Both return an instance label map (0 background, 1..n).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def _otsu(values: np.ndarray) -> float:
    hist, edges = np.histogram(values, bins=256)
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist).astype(float)
    w1 = w0[-1] - w0
    m = np.cumsum(hist * centres)
    mu0 = m / np.maximum(w0, 1)
    mu1 = (m[-1] - m) / np.maximum(w1, 1)
    between = w0 * w1 * (mu0 - mu1) ** 2
    return float(centres[int(np.argmax(between[:-1]))])


def _multi_otsu_low(values: np.ndarray) -> float:
    """The middle of three four-class Otsu thresholds on the positive scores.

    The classes are roughly: partial volume / fat-water mixtures, soft tissue
    (muscle), disc annulus, and disc nucleus with CSF; discs lie above the
    middle threshold.
    """
    try:
        from skimage.filters import threshold_multiotsu
        return float(threshold_multiotsu(values, classes=4, nbins=128)[1])
    except (ImportError, ValueError):
        return _otsu(values)


def disc_score(channels: dict) -> tuple[np.ndarray, str]:
    """The scalar image the disc segmenter thresholds and a description of it."""
    names = {n.lower(): n for n in channels}
    water = next((names[n] for n in ("wat", "water", "opp", "t2", "inn") if n in names), None)
    if water is None:
        if len(channels) != 1:
            raise InputError("classical disc segmentation needs a water-like channel (wat, opp, inn or t2) "
                             f"or a single image; got {', '.join(channels)}")
        water = next(iter(channels))
    score = np.asarray(channels[water], dtype=np.float32)
    what = water
    if "fat" in names and water != names["fat"]:
        score = score - np.asarray(channels[names["fat"]], dtype=np.float32)
        what = f"{water} - fat"
    return score, what


def segment_discs(channels: dict, spacing, axis: int = 2, min_volume_mm3: float = 400.0,
                  max_volume_mm3: float = 60000.0, max_height_mm: float = 22.0, smooth_sigma: float = 0.6,
                  superior_high: bool = True):
    """Segment intervertebral discs classically.

    Parameters
    ----------
    channels : dict
        Channel name → array ``[i, j, k]`` (Dixon ``inn``/``opp``/``fat``/``wat``
        or one T2-like image).
    spacing : 3 floats
        Voxel size in mm.
    axis : int
        Index axis along the spine (the challenge layout: 2, superior–inferior).
    min_volume_mm3, max_volume_mm3 : float
        Accepted disc volumes.
    max_height_mm : float
        Largest extent along the spine axis of a disc (rejects the canal).
    smooth_sigma : float
        Gaussian pre-smoothing in voxels (0: none).
    superior_high : bool
        Number discs from the high-index end of ``axis`` (superior in LPS
        sagittal data).

    Returns
    -------
    labels : int16 ndarray
        0 background, 1..n discs.
    info : dict
        Score image, thresholds and per-disc voxel counts.
    """
    from scipy import ndimage

    spacing = np.asarray(spacing, dtype=float)
    score, what = disc_score(channels)
    if smooth_sigma > 0:
        score = ndimage.gaussian_filter(score, smooth_sigma)
    positive = score[score > 0]
    if positive.size < 100:
        raise InputError("the image has no bright (water-like) tissue to segment")
    t = _multi_otsu_low(positive)
    tube, lab, n = _disc_seeds(score >= t, spacing, axis, max_height_mm)
    kept = _disc_shaped(lab, spacing, axis, min_volume_mm3, max_height_mm)
    voxel = float(np.prod(spacing))
    regions = [r for r in (_grow_disc(score, lab == idx, tube, voxel, axis, max_volume_mm3) for idx in kept)
               if r is not None]
    out, levels = _number_discs(regions, score.shape, superior_high)
    info = {"segmenter": "classical", "score": what, "threshold": t, "components": int(n),
            "tube_voxels": int(np.count_nonzero(tube)),
            "discs": len(regions), "levels": levels,
            "voxels": [int(np.count_nonzero(out == i)) for i in range(1, len(regions) + 1)]}
    return out, info


def _disc_seeds(bright, spacing, axis, max_height_mm):
    """Seeds from the ``bright`` mask: runs along the spine ``axis`` longer than ``max_height_mm`` (the
    CSF-filled canal) are removed (dilated by one voxel) and thin bridges opened; returns
    ``(tube mask, seed component labels, number of components)``."""
    from scipy import ndimage

    ball = ndimage.generate_binary_structure(3, 1)
    line = np.zeros((3, 3, 3), dtype=bool)
    line[tuple(slice(None) if a == axis else 1 for a in range(3))] = True
    runs, _ = ndimage.label(bright, line)
    run_len = np.bincount(runs.ravel()) * spacing[axis]
    run_len[0] = 0
    tube = ndimage.binary_dilation(run_len[runs] > max_height_mm, ball)
    seeds = ndimage.binary_opening(bright & ~tube, ball)
    lab, n = ndimage.label(seeds)
    return tube, lab, n


def _disc_shaped(lab, spacing, axis, min_volume_mm3, max_height_mm):
    """Component ids of ``lab`` that are disc-shaped: at least ``min_volume_mm3``, at most
    ``max_height_mm`` along ``axis`` and flat (height ≤ 0.8 × width); returns the list of ids."""
    from scipy import ndimage

    voxel = float(np.prod(spacing))
    kept = []
    for idx, sl in enumerate(ndimage.find_objects(lab), start=1):
        if sl is None:
            continue
        comp = lab[sl] == idx
        vol = float(comp.sum()) * voxel
        ext = np.array([(s.stop - s.start) * sp for s, sp in zip(sl, spacing)])
        height = ext[axis]
        width = max(ext[a] for a in range(3) if a != axis)
        if vol < min_volume_mm3 or height > max_height_mm or height > 0.8 * width:
            continue
        kept.append(idx)
    return kept


def _grow_disc(score, comp, tube, voxel, axis, max_volume_mm3):
    """Grow the seed ``comp`` to the half level between its median score and the upper quartile of its
    surroundings (within 3 voxels, outside the ``tube``), holes filled; returns ``(centre along axis,
    region mask, level)``, or None when the region exceeds ``max_volume_mm3``."""
    from scipy import ndimage

    ball = ndimage.generate_binary_structure(3, 1)
    grow = ndimage.binary_dilation(comp, ball, iterations=3)
    shell = grow & ~ndimage.binary_dilation(comp, ball, iterations=2)
    inside = float(np.median(score[comp]))
    # the brighter side of the surroundings (muscle beside the disc rather than the dark endplates)
    outside = float(np.percentile(score[shell], 75)) if shell.any() else 0.0
    level = 0.5 * (inside + outside)
    region = (score >= level) & grow & ~tube
    rl, _ = ndimage.label(region)
    ids = np.unique(rl[comp & region])
    region = np.isin(rl, ids[ids > 0]) | comp
    region = ndimage.binary_fill_holes(region)
    vol = float(region.sum()) * voxel
    if vol > max_volume_mm3:
        return None
    centre = ndimage.center_of_mass(region)
    return centre[axis], region, level


def _number_discs(regions, shape, superior_high):
    """Label the grown ``regions`` (centre, mask, level) from the superior end (first come keeps a voxel);
    returns ``(int16 label map of shape, levels in label order)``."""
    out = np.zeros(shape, dtype=np.int16)
    regions.sort(key=lambda r: -r[0] if superior_high else r[0])
    levels = []
    for n_, (_, region, level) in enumerate(regions, start=1):
        out[region & (out == 0)] = n_
        levels.append(level)
    return out, levels


def segment_ct_bone(array, spacing, threshold: float = 250.0, closing_mm: float = 1.5,
                    min_volume_mm3: float = 500.0, max_components: int | None = None):
    """Bone in CT: ``HU ≥ threshold``, closing, hole filling, components by size.

    Returns an instance label map (1 = largest component) and info.
    """
    from scipy import ndimage

    spacing = np.asarray(spacing, dtype=float)
    mask = np.asarray(array) >= threshold
    if not mask.any():
        raise InputError(f"no voxel reaches {threshold:g} HU (values {float(np.min(array)):g} to "
                         f"{float(np.max(array)):g})")
    radius = np.maximum(np.round(closing_mm / spacing).astype(int), 0)
    if np.any(radius > 0):
        zz = [np.arange(-r, r + 1) * s / max(closing_mm, 1e-9) for r, s in zip(radius, spacing)]
        g = np.meshgrid(*zz, indexing="ij")
        struct = sum(x * x for x in g) <= 1.0 + 1e-9
        mask = ndimage.binary_closing(np.pad(mask, radius[:, None]), struct)[
            tuple(slice(r, r + n) for r, n in zip(radius, array.shape))]
    mask = ndimage.binary_fill_holes(mask)
    lab, n = ndimage.label(mask)
    sizes = np.bincount(lab.ravel())[1:] * float(np.prod(spacing))
    order = [i + 1 for i in np.argsort(-sizes) if sizes[i] >= min_volume_mm3]
    if max_components:
        order = order[:int(max_components)]
    out = np.zeros(lab.shape, dtype=np.int16)
    for new, old in enumerate(order, start=1):
        out[lab == old] = new
    return out, {"segmenter": "ct-bone", "threshold": float(threshold), "components": len(order),
                 "volumes_mm3": [float(sizes[o - 1]) for o in order]}
