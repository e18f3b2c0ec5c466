"""A centreline from seed points: minimal paths through the bright lumen (issue 39, item 2).

With ``seeds`` (points in the image's physical frame, mm) instead of a
centreline, the vessel is found between them: minimal paths that stay in one
tube (:mod:`porecad.vessels.tube_path`: on a grid of a quarter of the smallest
seed radius, a cost per mm that is low in the middle of a tube of the seeds'
radius and up to 33 times higher in a chamber, bone or a much wider lumen of
the same brightness), from the first seed to the second, then from every
further seed to the paths found so far (scikit-image's minimal cost path,
Dijkstra on the 26-neighbourhood). As with VMTK's seeds, every end of the
vessel wanted is a seed: two seeds give one vessel between them, a third seed
in a branch adds that branch. The paths become a centreline graph (smoothed),
which is then segmented segment by segment like a given centreline
(:func:`porecad.vessels.ct_segment.guide_by_image`); the graph keeps its
``tube_map`` for the ``path-not-tube`` check.

Errors (one line): a seed outside the image, a seed in the background or on
the lumen's rim, seeds that no bright path joins.
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
    from .tube_path import seed_radii, tube_cost, tube_map
    S = check_seeds(seeds, vol)
    radii = seed_radii(vol, S)
    tm = tube_map(vol, S, radii)
    r_s = float(radii.max())
    cost = tube_cost(tm, r_s)
    idx = np.clip(np.rint(tm.index(S)).astype(int), 0, np.asarray(cost.shape) - 1)
    for k, i in enumerate(idx):  # a seed on a thin rim may round onto the background of the coarse grid
        if not np.isfinite(cost[tuple(i)]):
            raise InputError(f"seed {k + 1} at {np.round(S[k], 2).tolist()} mm lies on the lumen's rim; move it "
                             "towards the vessel's middle")
    lab, _ = ndimage.label(np.isfinite(cost), structure=np.ones((3, 3, 3)))
    lines = []
    tree = [tuple(idx[0])]
    for k in range(1, len(idx)):
        if lab[tuple(idx[k])] != lab[tuple(idx[0])]:
            raise InputError(f"seed {k + 1} is not joined to seed 1 by a bright path")
        mcp = MCP_Geometric(cost, sampling=(tm.h,) * 3, fully_connected=True)
        mcp.find_costs(tree if k > 1 else [tree[0]], [tuple(idx[k])])
        path = np.asarray(mcp.traceback(tuple(idx[k])))
        lines.append(path)
        tree.extend(tuple(p) for p in path)
    polys = [tm.physical(p) for p in lines]
    rad = [np.clip(tm.D[tuple(p.T)], tm.h, 3.0 * r_s) for p in lines]
    g = from_polylines(polys, rad, source="seeds")
    smooth_chains(g, iterations=6)
    g.tube_map, g.seed_radius, g.seeds = tm, r_s, S
    return g, {"seeds": S.tolist(), "path_nodes": int(g.n_nodes), "seed_radii": np.round(radii, 3).tolist(),
               "path_grid": round(tm.h, 4)}
