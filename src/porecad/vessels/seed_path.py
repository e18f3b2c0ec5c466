"""A centreline from seed points: minimal paths through the bright lumen (issue 39, item 2).

With ``seeds`` (points in the image's physical frame, mm) instead of a
centreline, the vessel is found between them: the image's foreground (above
its own threshold, :func:`porecad.vessels.ct_segment.foreground_threshold`)
gets a cost ``1 / min(D, r_s)²`` per mm, ``D`` the distance to the
background and ``r_s`` the largest ``D`` within 2 ``D``\\ s of the seeds (the
vessel's own radius), so paths keep to the middle of the lumen but gain
nothing in thicker bright structures (bone touching the vessel); the
path from the first seed to the second, then from every further seed to the
paths found so far (scikit-image's minimal cost path, Dijkstra on the
26-neighbourhood with the voxel spacing). As with VMTK's seeds, every end of
the vessel wanted is a seed: two seeds give one vessel between them, a
third seed in a branch adds that branch. The paths become a centreline graph
(smoothed), which is then segmented segment by segment like a given
centreline (:func:`porecad.vessels.ct_segment.guide_by_image`).

Errors (one line): a seed outside the image, a seed in the background, seeds
that no bright path joins.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import InputError
from .graph import from_polylines

MAX_SEEDS = 16


def check_seeds(seeds, vol) -> np.ndarray:
    """Seeds as ``(k, 3)`` mm, each inside the image and on the bright foreground."""
    S = np.asarray(seeds, float).reshape(-1, 3)
    if not 2 <= len(S) <= MAX_SEEDS:
        raise InputError(f"seeds: give 2 to {MAX_SEEDS} seed points, got {len(S)}")
    inside = vol.inside(S, margin=0.0)
    for k in np.flatnonzero(~inside):
        lo, hi = vol.bounds()
        raise InputError(f"seed {k + 1} at {np.round(S[k], 2).tolist()} mm is outside the image "
                         f"({np.round(lo, 1).tolist()} to {np.round(hi, 1).tolist()} mm)")
    v = vol.sample(S)
    for k in np.flatnonzero(v <= vol.threshold):
        raise InputError(f"seed {k + 1} at {np.round(S[k], 2).tolist()} mm lies in the background (image value "
                         f"{v[k]:.4g}, the foreground starts at {vol.threshold:.4g})")
    return S


def seed_centreline(seeds, vol):
    """The centreline graph joining the seeds through the lumen (module docstring)."""
    from skimage.graph import MCP_Geometric
    from .skeleton import smooth_chains
    S = check_seeds(seeds, vol)
    mask = vol.s > vol.threshold
    D = ndimage.distance_transform_edt(mask, sampling=vol.h)
    idx = np.rint(vol.index(S)).astype(int)
    idx = np.clip(idx, 0, vol.shape - 1)
    lab, _ = ndimage.label(mask, structure=np.ones((3, 3, 3)))
    r_s = 0.0
    for i in idx:
        d0 = float(D[tuple(i)])
        lo, hi = np.maximum(i - int(np.ceil(2 * d0 / vol.h.min())) - 1, 0), i + int(np.ceil(2 * d0 / vol.h.min())) + 2
        r_s = max(r_s, float(D[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].max()))
    cost = np.where(mask, 1.0 / np.maximum(np.minimum(D, r_s), 0.25 * vol.h.min()) ** 2, np.inf)
    lines = []
    tree = [tuple(idx[0])]
    for k in range(1, len(idx)):
        if lab[tuple(idx[k])] != lab[tuple(idx[0])]:
            raise InputError(f"seed {k + 1} is not joined to seed 1 by a bright path")
        mcp = MCP_Geometric(cost, sampling=tuple(vol.h), fully_connected=True)
        mcp.find_costs(tree if k > 1 else [tree[0]], [tuple(idx[k])])
        path = np.asarray(mcp.traceback(tuple(idx[k])))
        lines.append(path)
        tree.extend(tuple(p) for p in path)
    polys = [(p * vol.h) @ vol.D.T + vol.origin for p in lines]
    radii = [np.maximum(D[tuple(p.T)], vol.h.min()) for p in lines]
    g = from_polylines(polys, radii, source="seeds")
    smooth_chains(g, iterations=6)
    return g, {"seeds": S.tolist(), "path_nodes": int(g.n_nodes)}
