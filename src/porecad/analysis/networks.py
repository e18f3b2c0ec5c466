"""Pore networks on sample grids: percolation and the openness of pores inside a domain.

Used by the ARBF job (000 ch.5) to say whether its pores form one network
open on every outer face of the domain.
"""

from __future__ import annotations

import numpy as np

from .pores import percolates


def pore_network(phi, dom, iso, grid_axes, spacing, outer):
    """Connectivity and openness of the pores ``{Φ < iso}`` inside the domain, on the sample grid.

    6-connected components of the pore samples (``scipy.ndimage.label``);
    the *main* network is the largest. A component is *open* when it reaches
    the boundary layer (samples inside the domain within 1.5 samples of its
    surface). An outer face of the domain (a boundary triangle of a tet mesh,
    a boundary quad of a hex mesh, a face of a point cloud's box) is *opened*
    when a boundary-layer sample of the main network lies nearer to it
    (nearest face centroid, k-d tree; for a box, the nearest box plane) than
    to any other outer face. Percolation per axis (one pore component touching
    both opposite faces of the domain's bounding box) as in
    :func:`percolates`.
    """
    from scipy import ndimage
    from scipy.spatial import cKDTree

    inside = dom < 0
    pore = inside & (phi < iso)
    solid = inside & ~pore
    n_pore = int(pore.sum())
    out = {"pore_samples": n_pore}
    lab, n = ndimage.label(pore)
    slab, ns = ndimage.label(solid)
    ssz = np.bincount(slab.ravel(), minlength=ns + 1)[1:]
    out["solid_components"] = int(ns)
    out["solid_largest_fraction"] = float(ssz.max() / ssz.sum()) if ns else None
    if n == 0:
        out.update(pore_components=0, connected=False, open_pore_fraction=None, closed_pores=0,
                   opens_on_every_outer_face=False, outer_faces=int(len(outer[0]) if outer[1] == "faces" else 6),
                   open_outer_faces=0)
        return out
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    sizes[0] = 0
    main = int(np.argmax(sizes))
    layer = inside & (dom > -1.5 * spacing)
    touching = np.zeros(n + 1, bool)
    touching[np.unique(lab[layer & pore])] = True
    touching[0] = False
    out["pore_components"] = int(n)
    out["largest_fraction"] = float(sizes[main] / n_pore)
    out["connected"] = bool(n == 1)
    out["closed_pores"] = int(n - touching[1:].sum())
    out["open_pore_fraction"] = float(sizes[touching].sum() / n_pore)
    k, j, i = np.nonzero(layer & (lab == main))
    xs, ys, zs = grid_axes
    pts = np.column_stack([xs[i], ys[j], zs[k]])
    centroids, kind = outer
    if kind == "box":
        lo, hi = centroids
        d = np.concatenate([pts - lo, hi - pts], axis=1)  # distances to x0 y0 z0 x1 y1 z1
        n_faces = 6
        hit = np.unique(np.argmin(d, axis=1)) if len(pts) else np.zeros(0, np.int64)
    else:
        n_faces = len(centroids)
        hit = np.unique(cKDTree(centroids).query(pts)[1]) if len(pts) else np.zeros(0, np.int64)
    out["outer_faces"] = int(n_faces)
    out["open_outer_faces"] = int(len(hit))
    out["opens_on_every_outer_face"] = bool(len(hit) == n_faces)
    box = tuple(slice(int(ix.min()), int(ix.max()) + 1) for ix in np.nonzero(inside))
    out["percolation"] = percolates(pore[box])
    return out
