"""Interconnectivity of a phase inside a design domain: open and closed pores, percolation, the skin.

On a voxel grid with the phase (``void`` or ``solid``) and the domain
(``inside``) as boolean masks ``[z, y, x]``, components are 6-connected
(scipy ``ndimage.label``):

* a component is **open** when one of its voxels touches the domain's
  outside (a 6-neighbour outside the domain, or the grid's edge): it is
  connected to the surroundings of the part; the others are **closed pores**
  (count and volume);
* a phase **percolates** along an axis when one open component reaches the
  domain boundary near both ends along it: within ``tol`` of the domain's
  lowest and highest extent (one voxel for a box — its faces — and 5 % of
  the extent for a body, whose ends are curved);
* with a **skin** (a solid shell of thickness ``t`` closing the part), the
  pores it closes are told apart from pores the lattice itself closes: the
  shell is removed (the domain shrunk to depth ``>= t``, depth from the
  Euclidean distance transform of the domain mask, half a voxel accurate),
  and a closed pore that reaches the shrunk domain's boundary is *closed by
  the skin*; the lattice's own openness is measured in the shrunk domain.
"""

from __future__ import annotations

import numpy as np


def _label(mask):
    from scipy import ndimage
    return ndimage.label(mask)


def _touching(inside):
    """Voxels of ``inside`` with a 6-neighbour outside it (the grid's edge counts as outside)."""
    out = np.zeros(inside.shape, dtype=bool)
    for a in range(inside.ndim):
        n = inside.shape[a]
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[a], hi[a] = slice(0, n - 1), slice(1, n)
        edge = inside[tuple(lo)] != inside[tuple(hi)]
        out[tuple(lo)] |= edge
        out[tuple(hi)] |= edge
        first = [slice(None)] * 3
        first[a] = 0
        out[tuple(first)] = True
        first[a] = n - 1
        out[tuple(first)] = True
    return out & inside


def components(phase, inside, origin, h, box: bool):
    """Open/closed components and percolation of ``phase & inside``.

    Returns a dict: ``open_fraction`` (of the phase's voxels), ``closed``
    (count), ``closed_volume`` (mm³), ``percolation`` {x, y, z}, and the
    arrays ``labels``, ``open`` (per label) for further use.
    """
    ph = phase & inside
    labels, n = _label(ph)
    touch = _touching(inside) & ph
    is_open = np.zeros(n + 1, dtype=bool)
    is_open[np.unique(labels[touch])] = True
    is_open[0] = False
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    total = int(sizes[1:].sum())
    closed = np.flatnonzero(~is_open[1:]) + 1
    out = {"open_fraction": float(sizes[is_open].sum() / total) if total else None,
           "closed": int(len(closed)), "closed_volume": float(sizes[closed].sum() * h ** 3),
           "closed_sizes": sizes[closed], "labels": labels, "open": is_open, "voxels": total}
    # percolation: an open component touching the domain boundary near both ends of an axis
    k, j, i = np.nonzero(touch)
    coords = (origin[0] + i * h, origin[1] + j * h, origin[2] + k * h)
    lab = labels[k, j, i]
    dom_idx = np.nonzero(inside)
    perc = {}
    for name, a, ax_idx in (("x", 0, 2), ("y", 1, 1), ("z", 2, 0)):
        if len(dom_idx[ax_idx]) == 0:
            perc[name] = False
            continue
        lo_c = origin[a] + dom_idx[ax_idx].min() * h
        hi_c = origin[a] + dom_idx[ax_idx].max() * h
        tol = 0.5 * h if box else max(0.5 * h, 0.05 * (hi_c - lo_c))
        at_lo = np.unique(lab[coords[a] <= lo_c + tol])
        at_hi = np.unique(lab[coords[a] >= hi_c - tol])
        perc[name] = bool(np.intersect1d(at_lo, at_hi).size)
    out["percolation"] = perc
    return out


def depth_in(inside, h):
    """Depth (mm) of each domain voxel below the domain boundary: EDT to the nearest outside voxel minus h/2."""
    from scipy import ndimage
    padded = np.pad(inside, 1, constant_values=False)
    d = ndimage.distance_transform_edt(padded, sampling=h)[1:-1, 1:-1, 1:-1].astype(np.float32)
    d -= 0.5 * h
    return d


def skin_split(void, inside, origin, h, skin: float, full: dict):
    """Closed pores split into *closed by the skin* and *closed in the lattice*; the lattice's own openness.

    ``full`` is :func:`components` of the void in the whole domain. Returns a
    dict with ``skin``, ``closed_by_skin`` / ``closed_by_skin_volume``,
    ``closed_in_lattice`` / ``closed_in_lattice_volume``,
    ``lattice_open_pore_fraction`` and ``lattice_percolation`` (the void in
    the domain with the shell removed).
    """
    depth = depth_in(inside, h)
    inner = inside & (depth >= skin)
    del depth
    lat = components(void, inner, origin, h, box=False)
    labels, is_open = full["labels"], full["open"]
    n = len(is_open) - 1
    # a closed pore of the full domain is closed by the skin when part of it is open once the shell is removed
    lat_open_vox = lat["open"][lat["labels"]]
    reach = np.zeros(n + 1, dtype=bool)
    reach[np.unique(labels[lat_open_vox])] = True
    reach[0] = False
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    closed = ~is_open
    closed[0] = False
    by_skin = closed & reach
    own = closed & ~reach
    return {"skin": float(skin),
            "closed_by_skin": int(by_skin.sum()), "closed_by_skin_volume": float(sizes[by_skin].sum() * h ** 3),
            "closed_in_lattice": int(own.sum()), "closed_in_lattice_volume": float(sizes[own].sum() * h ** 3),
            "lattice_open_pore_fraction": lat["open_fraction"], "lattice_percolation": lat["percolation"],
            "lattice_closed_pores": lat["closed"]}
