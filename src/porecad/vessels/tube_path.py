"""Paths that stay in one tube, and the check that they did (issue 55).

Between seeds on a contrast CT the bright foreground holds the vessel *and*
the heart, bone and other vessels of the same brightness; a path that only
keeps to the middle of the bright voxels cuts through them (the aortic
root → heart → spine → descending aorta, never climbing the arch). Here:

* :func:`tube_map`: the image resampled to an isotropic grid of a third of the
  seeds' vessel radius (never finer than the image), its intensities clipped
  to the background–lumen range (bone brighter than the lumen counts as
  lumen, no more), scikit-image's Frangi vesselness for bright tubes at
  σ = 0.5–0.8 of the seeds' radii, normalised by its largest value next to
  the seeds (1 = as tube-like as the vessel at the seeds); the distance
  ``D`` to the background on the same grid.
* :func:`tube_cost`: per mm ``max(1, D / (1.5 r_s))² / (min(D, r_s)² (V + ε))``
  (``ε`` = :data:`EPS`): the middle of a tube of the seeds' radius is cheap,
  a blob (heart), a slab or the inside of a thicker column (spine) costs
  up to ``1/ε`` times more, and so does a radius far above the seeds'.
* :func:`not_tube_findings`: along the centreline found, nodes whose
  vesselness is below :data:`MIN_TUBENESS` or whose radius exceeds
  :data:`RADIUS_JUMP` × the path's median radius form stretches; one longer than
  that radius is a ``path-not-tube`` finding with its place (mm, in the
  output's frame), its length, the local radius and what would fix it.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..findings import Finding

#: the cost floor of vesselness: a non-tube voxel costs up to 1/EPS times a tube voxel
EPS = 0.03
#: below this (normalised) vesselness a path node is not in a tube
MIN_TUBENESS = 0.2
#: a local radius above this multiple of the seeds' vessel radius is not the vessel
RADIUS_JUMP = 2.0
#: the coarse grid holds at most this many voxels (its spacing grows to fit)
MAX_VOXELS = 8_000_000


def seed_radii(vol, S) -> np.ndarray:
    """The vessel radius at each seed (mm): the largest distance to the background within the seed's own."""
    h = vol.h
    out = []
    for X in S:
        i = np.rint(vol.index(X)[0]).astype(int)
        half = np.ceil(40.0 / h).astype(int)                    # a 80 mm box is enough for an aorta
        lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, vol.shape)
        box = vol.s[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] > vol.threshold
        D = ndimage.distance_transform_edt(box, sampling=h)
        c = i - lo
        d0 = float(D[tuple(c)])
        w = np.ceil((d0 + h.min()) / h).astype(int)
        a, b = np.maximum(c - w, 0), c + w + 1
        out.append(max(float(D[a[0]:b[0], a[1]:b[1], a[2]:b[2]].max()), float(h.min())))
    return np.asarray(out)


class TubeMap:
    """The coarse isotropic grid of :func:`tube_map`: vesselness ``V`` and background distance ``D``."""

    def __init__(self, vol, spacing, V, D):
        self.vol, self.h, self.V, self.D = vol, float(spacing), V, D

    def physical(self, idx):
        """Grid indices ``(k, 3)`` → physical points (the image's frame)."""
        return (np.asarray(idx, float) * self.h) @ self.vol.D.T + self.vol.origin

    def index(self, X):
        return self.vol.index(X) * self.vol.h / self.h

    def tubeness(self, X):
        return ndimage.map_coordinates(self.V, self.index(X).T, order=1, mode="nearest")


def tube_map(vol, S, radii) -> TubeMap:
    """The vesselness and distance maps for seeds ``S`` of vessel radii ``radii`` (module docstring)."""
    from skimage.filters import frangi
    hv = max(float(vol.h.min()), float(np.min(radii)) / 3.0)
    while np.prod((vol.shape - 1) * vol.h / hv + 1) > MAX_VOXELS:
        hv *= 1.25
    shape = tuple(int(v) for v in np.floor((vol.shape - 1) * vol.h / hv) + 1)
    scale = hv / vol.h
    src = ndimage.gaussian_filter(vol.s, 0.4 * np.maximum(scale - 1.0, 0.0)) if scale.max() > 1.5 else vol.s
    I = ndimage.affine_transform(src, scale, output_shape=shape, order=1, mode="nearest")
    lumen = float(np.median(vol.sample(S)))
    lo = vol.threshold - max(lumen - vol.threshold, 1e-6)
    mask = I > vol.threshold
    I = (np.clip(I, lo, lumen) - lo) / max(lumen - lo, 1e-6)
    sig = np.unique(np.clip(np.round(np.array([0.5, 0.65, 0.8])[:, None] * np.asarray(radii)[None] / hv, 2),
                            1.0, None))
    V = frangi(I, sigmas=tuple(sig), black_ridges=False).astype(np.float32)
    D = ndimage.distance_transform_edt(mask) * hv
    tm = TubeMap(vol, hv, V, D)
    ref = 0.0
    for X, r in zip(S, radii):  # the vessel's own vesselness next to each seed
        c = np.rint(tm.index(X)[0]).astype(int)
        w = int(np.ceil(r / hv)) + 1
        a, b = np.maximum(c - w, 0), np.minimum(c + w + 1, shape)
        ref = max(ref, float(V[a[0]:b[0], a[1]:b[1], a[2]:b[2]].max()))
    tm.V = np.where(mask, np.minimum(V / ref, 1.0) if ref > 0 else 0.0, 0.0).astype(np.float32)
    return tm


def tube_cost(tm: TubeMap, r_s: float) -> np.ndarray:
    """The cost per mm on ``tm``'s grid (module docstring); infinite in the background."""
    D, floor = tm.D, 0.25 * tm.h
    c = np.maximum(1.0, D / (1.5 * r_s)) ** 2 / (np.maximum(np.minimum(D, r_s), floor) ** 2 * (tm.V + EPS))
    return np.where(D > 0, c, np.inf)


def stretches(bad: np.ndarray, s: np.ndarray, min_length: float):
    """Runs of ``bad`` nodes along a chain with arc length ``s``: ``[(first, last)]`` spanning ≥ ``min_length``."""
    out, k, n = [], 0, len(bad)
    while k < n:
        if not bad[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and bad[j + 1]:
            j += 1
        if s[j] - s[k] >= min_length:
            out.append((k, j))
        k = j + 1
    return out


def not_tube_findings(graph, tubeness, to_frame=None, frame: str = "LPS") -> list:
    """``path-not-tube`` findings along ``graph``'s chains (module docstring); ``to_frame`` maps points out."""
    to_frame = to_frame or (lambda P: P)
    r_seed = float(np.median(graph.radii))
    bad_node = (np.asarray(tubeness) < MIN_TUBENESS) | (graph.radii > RADIUS_JUMP * r_seed)
    found = []
    for chain in graph.branches():
        P = graph.points[chain]
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        for a, b in stretches(bad_node[chain], s, r_seed):
            mid = chain[(a + b) // 2]
            where = np.round(to_frame(graph.points[mid][None])[0], 1).tolist()
            before = np.round(to_frame(P[max(a - 1, 0)][None])[0], 1).tolist()
            after = np.round(to_frame(P[min(b + 1, len(P) - 1)][None])[0], 1).tolist()
            r_loc = float(graph.radii[chain[a:b + 1]].max())
            v_loc = float(np.min(np.asarray(tubeness)[chain[a:b + 1]]))
            found.append(Finding(
                "path-not-tube",
                f"the path between the seeds leaves the tube for {s[b] - s[a]:.0f} mm about {where} mm ({frame}; "
                f"local radius {r_loc:.1f} mm against the path's median {r_seed:.1f} mm, tubularity {v_loc:.2f}): "
                f"add a seed in the vessel where it runs between {before} and {after} mm, or move the seed "
                "that lies outside it",
                {"at": where, "frame": frame, "length": round(float(s[b] - s[a]), 2), "radius": round(r_loc, 2),
                 "median_radius": round(float(r_seed), 2), "tubularity": round(v_loc, 3),
                 "between": [before, after]}))
    return found
