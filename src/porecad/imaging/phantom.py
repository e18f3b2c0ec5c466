"""A seeded multi-modal spine phantom: vertebral bodies, discs and Dixon channels.

Stands in for the multi-modality MR data of 000 §6.2.1 (which cannot be
downloaded here) in tests and demos. The field of view is sagittal like the
challenge data: ``i`` (x) runs left–right with 2 mm slices, ``j`` (y)
posterior → anterior and ``k`` (z) inferior → superior, both 1.25 mm — the
challenge's 2 × 1.25 × 1.25 mm voxels.

Anatomy (all sizes in mm, jittered per seed): ``n_discs`` kidney-shaped
discs (:class:`porecad.fields.sdf.LumbarDisc`, tilted in the sagittal plane
like a lordotic lumbar spine) between vertebral bodies of the same outline
(fatty marrow inside a dark cortical shell), the spinal canal (CSF) behind
them, paraspinal muscle, subcutaneous fat and air.

Channels follow the two-point Dixon model: per tissue a water signal ``W``
and a fat signal ``F``, then ``wat = W``, ``fat = F``, ``inn = W + F``,
``opp = |W − F|``. With the tissue values below the disc is bright on water,
in-phase and opposed-phase and dark on fat, and marrow bright on fat and
in-phase — the contrasts of 000 Table 6.1 (fat has the lowest Weber contrast,
eq. 6.2.1). A smooth multiplicative bias field and Rician noise follow; tissue
boundaries carry partial-volume mixing.

Labels: 0 background, 1..n discs numbered from the top (superior) down.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

#: Dixon (water, fat) signal per tissue (arbitrary units, ~ the scale of 000 Table 6.1)
TISSUES = {
    "air": (0.0, 0.0),
    "muscle": (70.0, 12.0),
    "subcutaneous_fat": (18.0, 190.0),
    "marrow": (55.0, 95.0),
    "cortex": (10.0, 6.0),
    "disc_annulus": (120.0, 10.0),
    "disc_nucleus": (185.0, 14.0),
    "csf": (230.0, 4.0),
}
CHANNELS = ("inn", "opp", "fat", "wat")


def _rot_x(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _smoothstep_inside(d, width):
    """Partial-volume occupancy from a signed distance (negative inside)."""
    return 1.0 / (1.0 + np.exp(np.clip(d / max(width, 1e-6), -40, 40)))


def spine_phantom(n_discs: int = 3, seed: int = 0, spacing=(2.0, 1.25, 1.25), noise: float = 0.04,
                  bias: float = 0.15, disc_size=(20.0, 15.0, 9.0), vertebra_height: float = 22.0,
                  shape=None) -> dict:
    """Generate a spine phantom.

    Parameters
    ----------
    n_discs : int
        Number of discs (≥ 1; 000 ch.6's images hold ≥ 7, tests use 3).
    seed : int
        Random seed: the same seed gives the same phantom, bit for bit.
    spacing : 3 floats
        Voxel size in mm (x, y, z); default the challenge's 2 × 1.25 × 1.25.
    noise : float
        Rician noise sigma relative to the disc's water signal.
    bias : float
        Amplitude of the smooth multiplicative bias field (0: none).
    disc_size : 3 floats
        Mean disc semi-axes left–right, semi-axis anterior–posterior and
        height (mm); each disc is jittered by ±10 %.
    vertebra_height : float
        Mean vertebral body height (mm).
    shape : 3 ints, optional
        Grid size; default fits the discs with ~half a vertebra above and below.

    Returns
    -------
    dict
        ``channels`` (name → float32 array), ``labels`` (int16, 0 / 1..n),
        ``geometry``, ``discs`` (per disc: label, centre in mm, semi-axes,
        height, tilt), ``seed``.
    """
    n_discs, spacing = _check_args(n_discs, spacing, noise, bias)
    rng = np.random.default_rng(int(seed))
    shape, ext, P, pv = _voxel_grid(shape, spacing, n_discs, disc_size, vertebra_height)
    line = _spine_line(rng, ext, disc_size, vertebra_height)
    occupancy = _body_occupancy(P, pv)
    discs, disc_occ, nucleus_occ, labels, centres = _discs(rng, P, pv, line, n_discs, disc_size, vertebra_height)
    vert_occ, cortex_occ = _vertebrae(rng, P, pv, line, centres, disc_size, vertebra_height)
    canal = _canal(P, pv, line, disc_size)
    W, F = _compose(rng, occupancy, canal, cortex_occ, vert_occ, disc_occ, nucleus_occ)
    channels = _channels(rng, W, F, P, ext, shape, noise, bias)
    geometry = {"spacing": spacing.tolist(), "origin": [0.0, 0.0, 0.0], "direction": np.eye(3).tolist()}
    return {"channels": channels, "labels": labels.reshape(shape), "geometry": geometry, "discs": discs,
            "seed": int(seed), "shape": list(shape)}


def _check_args(n_discs, spacing, noise, bias):
    """Validate the phantom's arguments; returns ``(n_discs as int, spacing as a float array)``."""
    if int(n_discs) != n_discs or n_discs < 1 or n_discs > 12:
        raise InputError(f"`discs` must be an integer from 1 to 12, got {n_discs!r}")
    n_discs = int(n_discs)
    spacing = np.asarray(spacing, dtype=float)
    if spacing.shape != (3,) or np.any(~np.isfinite(spacing)) or np.any(spacing <= 0):
        raise InputError(f"spacing must be three positive numbers, got {spacing.tolist()}")
    if not (0 <= noise < 1) or not (0 <= bias < 1):
        raise InputError("noise and bias must lie in [0, 1)")
    return n_discs, spacing


def _voxel_grid(shape, spacing, n_discs, disc_size, vertebra_height):
    """The grid: ``shape`` (default: fits the discs), its extent (mm), voxel centres ``P`` (N × 3, mm,
    origin 0) and the partial-volume width; returns ``(shape, ext, P, pv)``."""
    a0, b0, h0 = (float(x) for x in disc_size)
    pitch = vertebra_height + h0
    if shape is None:
        ext = np.array([2 * a0 + 24.0, 2 * b0 + 50.0, n_discs * pitch + 0.8 * vertebra_height])
        shape = tuple(int(np.ceil(e / s / 4.0) * 4) for e, s in zip(ext, spacing))
    shape = tuple(int(s) for s in shape)
    if len(shape) != 3 or min(shape) < 8:
        raise InputError(f"phantom shape must be three sizes ≥ 8, got {shape}")
    ext = np.array(shape) * spacing
    # voxel centres in mm (origin 0, identity direction)
    xs, ys, zs = (np.arange(n) * s for n, s in zip(shape, spacing))
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    P = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    pv = 0.35 * float(np.min(spacing))  # partial-volume width
    return shape, ext, P, pv


def _spine_line(rng, ext, disc_size, vertebra_height):
    """The spine's centre line, drawn from ``rng``: x mid, y a little anterior of mid with a gentle curve,
    z from the top down; returns ``(cx, z_top, spine_y)`` with ``spine_y(z)`` the line's y (mm)."""
    h0 = float(disc_size[2])
    cx = 0.5 * ext[0] + rng.uniform(-1.5, 1.5)
    cy0 = 0.5 * ext[1] + 6.0 + rng.uniform(-2.0, 2.0)
    curve = rng.uniform(-3.0, 3.0)
    z_top = ext[2] - 0.4 * vertebra_height - 0.5 * h0 + rng.uniform(-1.5, 1.5)

    def spine_y(z):
        t = (z - 0.5 * ext[2]) / max(ext[2], 1.0)
        return cy0 + curve * 4.0 * t * t

    return cx, z_top, spine_y


def _body_occupancy(P, pv):
    """Background body at the voxel centres ``P``: muscle inside a soft-tissue outline, subcutaneous fat
    behind, air beyond; returns tissue name → occupancy (N,) (zero but for muscle and fat)."""
    occupancy = {name: np.zeros(P.shape[0]) for name in TISSUES}
    d_back = P[:, 1] - 6.0  # posterior skin at y = 6 mm
    body_in = _smoothstep_inside(-d_back, pv)
    fat_layer = body_in * (1 - _smoothstep_inside(-(P[:, 1] - 14.0), pv))
    muscle = body_in - fat_layer
    occupancy["subcutaneous_fat"] += fat_layer
    occupancy["muscle"] += muscle
    return occupancy


def _discs(rng, P, pv, line, n_discs, disc_size, vertebra_height):
    """The discs along the spine ``line`` (sizes, spacing and tilts drawn from ``rng``); returns
    ``(disc records, disc occupancies, nucleus occupancies, labels (N,) int16, disc centres z)``."""
    from ..fields.sdf import LumbarDisc

    cx, z_top, spine_y = line
    a0, b0, h0 = (float(x) for x in disc_size)
    pitch = vertebra_height + h0
    discs, disc_occ, nucleus_occ = [], [], []
    centres = []
    for n in range(n_discs):
        zc = z_top - n * (pitch + rng.uniform(-1.5, 1.5))
        centres.append(zc)
    tilts = np.deg2rad(rng.uniform(-8.0, 8.0, n_discs))
    labels = np.zeros(P.shape[0], dtype=np.int16)
    for n, zc in enumerate(centres):
        a = a0 * rng.uniform(0.9, 1.1)
        b = b0 * rng.uniform(0.9, 1.1)
        h = h0 * rng.uniform(0.9, 1.1)
        c = np.array([cx, spine_y(zc), zc])
        R = _rot_x(tilts[n])
        q = (P - c) @ R  # into the disc frame (x lateral, y anterior, z up)
        d = LumbarDisc(a=a, b=b, height=h, notch=0.45 * b, notch_depth=0.2 * b, rim=0.3 * h).evaluate(q)
        occ = _smoothstep_inside(d, pv)
        labels[d <= 0] = n + 1
        nuc = LumbarDisc(a=0.6 * a, b=0.55 * b, height=0.6 * h, notch=0.3 * b, notch_depth=0.1 * b,
                         rim=0.25 * h).evaluate(q - np.array([0, 0.1 * b, 0]))
        disc_occ.append(occ)
        nucleus_occ.append(_smoothstep_inside(nuc, pv) * occ)
        discs.append({"label": n + 1, "centre_mm": c.tolist(), "a_mm": a, "b_mm": b, "height_mm": h,
                      "tilt_deg": float(np.rad2deg(tilts[n]))})
    return discs, disc_occ, nucleus_occ, labels, centres


def _vertebrae(rng, P, pv, line, centres, disc_size, vertebra_height):
    """Vertebral bodies between and around the discs at z ``centres`` (same outline, taller, slightly
    larger; tilt and height from ``rng``); returns ``(marrow occupancies, cortical shell occupancies)``."""
    from ..fields.sdf import LumbarDisc

    cx, z_top, spine_y = line
    a0, b0, h0 = (float(x) for x in disc_size)
    pitch = vertebra_height + h0
    n_discs = len(centres)
    vert_occ, cortex_occ = [], []
    gaps = [z_top + 0.5 * pitch] + [0.5 * (centres[i] + centres[i + 1]) for i in range(n_discs - 1)] \
        + [centres[-1] - 0.5 * pitch]
    for zc in gaps:
        c = np.array([cx, spine_y(zc), zc])
        q = (P - c) @ _rot_x(rng.uniform(-0.05, 0.05))
        hv = vertebra_height * rng.uniform(0.95, 1.05) - 1.0
        shape_v = LumbarDisc(a=a0 * 1.05, b=b0 * 1.02, height=hv, notch=0.45 * b0, notch_depth=0.2 * b0, rim=2.0)
        d = shape_v.evaluate(q)
        outer = _smoothstep_inside(d, pv)
        inner = _smoothstep_inside(d + 1.2, pv)  # 1.2 mm cortical shell
        vert_occ.append(inner)
        cortex_occ.append(outer - inner)
    return vert_occ, cortex_occ


def _canal(P, pv, line, disc_size):
    """The spinal canal, an elliptic tube behind the bodies; returns its occupancy (N,)."""
    cx, _, spine_y = line
    b0 = float(disc_size[1])
    canal_y = P[:, 1] - (spine_y(P[:, 2]) - b0 - 8.0)
    d_canal = np.hypot((P[:, 0] - cx) / 8.0, canal_y / 6.5) - 1.0
    return _smoothstep_inside(d_canal * 6.5, pv)


def _paint(w, f, frac, wat, fat):
    """Replace the (water, fat) signals ``wat``, ``fat`` in place by ``(w, f)`` by the occupancy ``frac``."""
    wat *= (1 - frac)
    fat *= (1 - frac)
    wat += frac * w
    fat += frac * f


def _compose(rng, occupancy, canal, cortex_occ, vert_occ, disc_occ, nucleus_occ):
    """Compose the tissues (later structures replace earlier ones by their occupancy; marrow signal
    jittered from ``rng``); returns the water and fat signals ``(W, F)``, (N,) each."""
    n = canal.shape[0]
    W = np.zeros(n)
    F = np.zeros(n)
    for name in ("muscle", "subcutaneous_fat"):
        w, f = TISSUES[name]
        W += occupancy[name] * w
        F += occupancy[name] * f
    _paint(*TISSUES["csf"], canal, W, F)
    for occ in cortex_occ:
        _paint(*TISSUES["cortex"], occ, W, F)
    for occ in vert_occ:
        jitter = rng.uniform(0.85, 1.15)
        w, f = TISSUES["marrow"]
        _paint(w * jitter, f / jitter, occ, W, F)
    for occ, nuc in zip(disc_occ, nucleus_occ):
        _paint(*TISSUES["disc_annulus"], occ, W, F)
        _paint(*TISSUES["disc_nucleus"], nuc, W, F)
    return W, F


def _channels(rng, W, F, P, ext, shape, noise, bias):
    """The Dixon channels from the water and fat signals ``W``, ``F`` with a smooth multiplicative bias
    field, a gain and Rician noise (all from ``rng``); returns name → float32 array of ``shape``."""
    # smooth multiplicative bias field (low-order, random per seed)
    if bias > 0:
        u = (P / ext) * 2 - 1
        coef = rng.normal(0, 1, 6)
        field_ = coef[0] * u[:, 0] + coef[1] * u[:, 1] + coef[2] * u[:, 2] + coef[3] * u[:, 1] * u[:, 2] \
            + coef[4] * u[:, 2] ** 2 + coef[5] * u[:, 1] ** 2
        field_ = 1.0 + bias * field_ / max(np.max(np.abs(field_)), 1e-9)
    else:
        field_ = np.ones(P.shape[0])
    sigma = noise * TISSUES["disc_nucleus"][0]
    gain = rng.uniform(0.9, 1.1)
    clean = {"wat": W, "fat": F, "inn": W + F, "opp": np.abs(W - F)}
    channels = {}
    for name in CHANNELS:
        s = clean[name] * field_ * gain
        if sigma > 0:  # Rician magnitude noise
            s = np.hypot(s + rng.normal(0, sigma, s.shape), rng.normal(0, sigma, s.shape))
        channels[name] = s.reshape(shape).astype(np.float32)
    return channels


def weber_contrast(image, mask) -> float:
    """Absolute Weber contrast ``|I − I_b| / I_b`` (000 eq. 6.2.1) of a mask against the rest."""
    fg = float(np.mean(image[mask]))
    bg = float(np.mean(image[~mask]))
    return abs(fg - bg) / bg if bg else float("inf")


def write_phantom(out_dir, phantom: dict, subject: str = "01", force: bool = False) -> dict:
    """Write a phantom in the challenge layout: ``DIR/<subject>_{inn,opp,fat,wat}.nii.gz`` and
    ``DIR/<subject>_Labels.nii.gz``; returns name → path.

    Every output path is checked before anything is written.
    """
    from pathlib import Path

    from ..io import check_output_path
    from .io import write_volume
    d = Path(out_dir)
    paths = {name: d / f"{subject}_{name}.nii.gz" for name in CHANNELS}
    paths["labels"] = d / f"{subject}_Labels.nii.gz"
    for p in paths.values():
        check_output_path(p, force=force)
    for name in CHANNELS:
        write_volume(paths[name], phantom["channels"][name], phantom["geometry"], force=force)
    write_volume(paths["labels"], phantom["labels"].astype(np.uint8), phantom["geometry"], force=force)
    return {k: str(v) for k, v in paths.items()}
