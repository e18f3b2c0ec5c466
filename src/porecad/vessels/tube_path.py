"""Paths that stay in one tube, and the check that they did (issue 55).

Between seeds on a contrast CT the bright foreground holds the vessel *and*
the heart, bone and other vessels of the same brightness; a path that only
keeps to the middle of the bright voxels cuts through them (the aortic
root → heart → spine → descending aorta, never climbing the arch). Here:

* :func:`tube_map`: the image resampled to an isotropic grid of a quarter of
  the smallest seed radius (never finer than the image), its intensities clipped
  to the background–lumen range (bone brighter than the lumen counts as
  lumen, no more), scikit-image's Frangi vesselness for bright tubes at
  σ from 0.3 × the narrowest seed radius to 0.8 × the narrower of the
  first two seeds' (:func:`frangi_scales`: a stenosis or a branch stays
  tube-like, a chamber or a bone column much wider than the vessel is no
  tube, whatever a seed in it says), made scale-invariant
  (:data:`GAMMA`), normalised by its largest value next to the seeds (1 = as
  tube-like as the vessel at the seeds); the distance
  ``D`` to the background on the same grid.
* :func:`tube_cost`: per mm ``max(1, D / (1.5 r_s))² / (min(D, r_s)² (V + ε))``
  (``ε`` = :data:`EPS`): the middle of a tube of the seeds' radius is cheap,
  a blob (heart), a slab or the inside of a thicker column (spine) costs
  up to ``1/ε`` times more, and so does a radius far above the seeds'.
* :func:`not_tube_findings`: along the centreline found, nodes whose
  vesselness is below :data:`MIN_TUBENESS`, or that lie in a piece of the
  path wider than :data:`RADIUS_JUMP` × the pieces beside it — pieces cut
  where the radius changes by more than that within :data:`JUMP_SPAN` radii
  along the path, compared with their neighbours, not with the path's median
  (:func:`wide_nodes`: a gradual taper is no jump, a stenosis is no bump) —
  or wider than :data:`RADIUS_JUMP` × the largest seed radius form
  stretches; one longer than the radius beside it is a ``path-not-tube``
  finding with its place (mm, in the output's frame), its length, the local
  radius and what would fix it (the seed to move, or where to add one).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..findings import Finding

#: the cost floor of vesselness: a non-tube voxel costs up to 1/EPS times a tube voxel
EPS = 0.03
#: below this (normalised) vesselness a path node is not in a tube
MIN_TUBENESS = 0.2
#: a radius jump: more than RADIUS_JUMP × within JUMP_SPAN radii along the path
RADIUS_JUMP, JUMP_SPAN = 2.0, 3.0
#: Frangi's structure scale ``γ σ²`` (voxels; the grey values run 0–1 from background to lumen): the same
#: response for a tube of radius ∝ σ at every σ (skimage's γ, taken from the first σ, favours the finest)
GAMMA = 0.15
#: Frangi's scales: from SCALES[0] × the narrowest seed's radius (a stenosis, a branch) to SCALES[1] × the
#: narrower of the first two seeds' (the vessel), geometric steps of at most SCALE_STEP
SCALES = (0.3, 0.8)
SCALE_STEP = 1.4
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


def frangi_scales(radii) -> np.ndarray:
    """Frangi's σ (mm) for seeds of vessel radii ``radii``: a tube of the vessel's radius — the narrower of
    the first two seeds (the vessel's ends), or a narrower branch's — is tube-like, one much wider is not
    (a chamber or a bone column, even with a seed in it)."""
    r = np.asarray(radii, float)
    r_main = float(r[:2].min())
    lo, hi = SCALES[0] * min(r_main, float(r.min())), SCALES[1] * r_main
    n = max(2, int(np.ceil(np.log(hi / lo) / np.log(SCALE_STEP))) + 1)
    return np.geomspace(lo, hi, n)


def tube_map(vol, S, radii) -> TubeMap:
    """The vesselness and distance maps for seeds ``S`` of vessel radii ``radii`` (module docstring)."""
    from skimage.filters import frangi
    hv = max(float(vol.h.min()), float(np.min(radii)) / 4.0)
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
    sig = np.unique(np.clip(np.round(frangi_scales(radii) / hv, 2), 1.0, None))
    V = np.zeros(shape, np.float32)
    for sg in sig:  # scale-invariant: skimage's Hessian is not σ²-normalised, so neither is its structure term
        V = np.maximum(V, frangi(I, sigmas=(float(sg),), black_ridges=False, gamma=GAMMA / float(sg) ** 2))
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


def radius_pieces(r: np.ndarray, s: np.ndarray):
    """A chain's radii ``r`` (arc length ``s``) cut where they jump: ``(bounds, levels)``, piece ``k`` the nodes
    ``bounds[k]:bounds[k + 1]``.

    The change of ``log r`` across ``±JUMP_SPAN/2`` radii (of the smallest radius within ``JUMP_SPAN``
    radii) beyond ``log RADIUS_JUMP`` marks a jump; each run of such nodes of one sign is one cut in the
    middle of its steepest part. A piece's level is the median radius of its nodes away from its cuts.
    """
    n = len(r)
    x = np.log(np.maximum(r, 1e-9))
    lo = np.searchsorted(s, s - JUMP_SPAN * r, "left")
    hi = np.searchsorted(s, s + JUMP_SPAN * r, "right")
    half = 0.5 * JUMP_SPAN * np.array([r[a:b].min() for a, b in zip(lo, hi)])
    d = np.interp(s + half, s, x) - np.interp(s - half, s, x)
    big = np.abs(d) > np.log(RADIUS_JUMP)
    cuts, k = [], 0
    while k < n:
        if not big[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and big[j + 1] and np.sign(d[j + 1]) == np.sign(d[k]):
            j += 1
        top = np.flatnonzero(np.abs(d[k:j + 1]) >= 0.95 * np.abs(d[k:j + 1]).max())
        cuts.append(k + int(round(0.5 * (top[0] + top[-1]))))           # the middle of the steepest part
        k = j + 1
    bounds = [0, *cuts, n]
    levels = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        idx = np.arange(a, b)
        away = np.ones(len(idx), bool)
        if a > 0:
            away &= s[idx] - s[a] > half[a]
        if b < n:
            away &= s[b] - s[idx] > half[b]
        levels.append(float(np.median(r[idx[away] if away.any() else idx])))
    return bounds, np.asarray(levels)


def wide_nodes(r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Nodes of pieces (:func:`radius_pieces`) wider than ``RADIUS_JUMP`` × every neighbouring piece.

    Pieces narrower than both neighbours by that factor (a stenosis) are passed over as neighbours, so the
    vessel on either side of a stenosis is not taken for a bump; a gradual taper has no cut at all.
    """
    bounds, L = radius_pieces(r, s)
    m = len(L)
    dip = [0 < k < m - 1 and L[k] * RADIUS_JUMP < min(L[k - 1], L[k + 1]) for k in range(m)]
    keep = [k for k in range(m) if not dip[k]]
    out = np.zeros(len(r), bool)
    for q, k in enumerate(keep):
        nb = keep[max(q - 1, 0):q] + keep[q + 1:q + 2]
        if nb and all(L[k] > RADIUS_JUMP * L[j] for j in nb):
            out[bounds[k]:bounds[k + 1]] = True
    return out


def _near_seed(X, seeds, reach):
    """1-based number of the seed within ``reach`` of ``X``, else None."""
    if seeds is None or not len(seeds):
        return None
    dist = np.linalg.norm(np.asarray(seeds, float) - X, axis=1)
    k = int(np.argmin(dist))
    return k + 1 if dist[k] <= reach else None


def not_tube_findings(graph, tubeness, to_frame=None, frame: str = "LPS", seeds=None) -> list:
    """``path-not-tube`` findings along ``graph``'s chains (module docstring); ``to_frame`` maps points out.

    ``seeds`` (LPS mm; default the graph's own, :func:`porecad.vessels.seed_path.seed_centreline`): a stretch
    that reaches a chain end at a seed names that seed as the one to move.
    """
    seeds = getattr(graph, "seeds", None) if seeds is None else seeds
    r_seeds = float(getattr(graph, "seed_radius", None) or np.inf)  # wider than any seed's vessel: no tube
    to_frame = to_frame or (lambda P: P)
    out = lambda X: np.round(to_frame(np.asarray(X, float)[None])[0], 1).tolist()  # noqa: E731
    V = np.asarray(tubeness)
    found = []
    for chain in graph.branches():
        P, r = graph.points[chain], graph.radii[chain]
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        bad = (V[chain] < MIN_TUBENESS) | wide_nodes(r, s) | (r > RADIUS_JUMP * r_seeds)
        r_ref = float(np.median(r[~bad])) if (~bad).any() else float(np.median(r))
        for a, b in stretches(bad, s, r_ref):
            r_loc, v_loc = float(r[a:b + 1].max()), float(V[chain[a:b + 1]].min())
            near = np.abs(s - 0.5 * (s[a] + s[b])) <= 0.5 * (s[b] - s[a]) + JUMP_SPAN * r_ref
            beside = near & ~bad
            r_nb = float(np.median(r[beside])) if beside.any() else r_ref
            where = out(P[(a + b) // 2])
            before, after = out(P[max(a - 1, 0)]), out(P[min(b + 1, len(P) - 1)])
            seed = None
            for end in (0, len(P) - 1):
                if a <= end <= b:
                    seed = seed or _near_seed(P[end], seeds, r_loc + 2.0 * r_ref)
            fix = (f"move seed {seed} (at {out(seeds[seed - 1])} mm) into the vessel: it lies in a part "
                   f"{2 * r_loc:.0f} mm wide" if seed else
                   f"add a seed in the vessel where it runs between {before} and {after} mm")
            found.append(Finding(
                "path-not-tube",
                f"the path between the seeds leaves the tube for {s[b] - s[a]:.0f} mm about {where} mm ({frame}; "
                f"local radius {r_loc:.1f} mm against {r_nb:.1f} mm beside it, tubularity {v_loc:.2f}): {fix}",
                {"at": where, "frame": frame, "length": round(float(s[b] - s[a]), 2), "radius": round(r_loc, 2),
                 "neighbour_radius": round(r_nb, 2), "tubularity": round(v_loc, 3),
                 "between": [before, after], "seed": seed}))
    return found
