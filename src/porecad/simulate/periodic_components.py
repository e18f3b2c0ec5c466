"""Connected components of a phase in a periodic cell, and the directions each one spans.

Voxels are connected through shared faces (6-connectivity): for a solid,
voxels that only share an edge or a corner form a hinge, which carries no
load; for a pore space, flow needs an open face. A component *spans* (wraps
around) axis ``a`` when it is connected to its own periodic image shifted by
one cell along ``a``: only such a component carries load or flow across the
cell in that direction.

Algorithm: label the cell without wrap-around (scipy), join labels that touch
across the periodic faces, and walk the resulting graph recording each
label's cell offset; an edge that closes a loop with a non-zero total offset
proves the wrap (the standard test for percolation in periodic systems,
e.g. Livraghi et al., *J. Chem. Theory Comput.* 17 (2021) 6759).
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["periodic_components"]


def periodic_components(mask):
    """Label the face-connected components of ``mask`` in a periodic cell.

    Parameters
    ----------
    mask : (nz, ny, nx) bool array
        The phase (solid or pore), axes ordered z, y, x.

    Returns
    -------
    labels : (nz, ny, nx) int32
        0 outside the phase, else the component number 1..n (merged across
        the periodic faces).
    spans : (n + 1, 3) bool
        ``spans[c, a]``: component ``c`` wraps around axis ``a`` (x, y, z
        order; row 0 is unused).
    sizes : (n + 1,) int64
        Voxels per component.

    Examples
    --------
    >>> m = np.zeros((4, 4, 4), bool); m[:, 1, 1] = True    # a rod along z
    >>> lab, spans, sizes = periodic_components(m)
    >>> spans[1].tolist(), int(sizes[1])
    ([False, False, True], 4)
    """
    from scipy import ndimage

    mask = np.asarray(mask, dtype=bool)
    lab, n = ndimage.label(mask)
    # periodic contacts: (label on the last plane, label on the first plane, shift)
    edges = []
    for ax_arr, ax_xyz in ((2, 0), (1, 1), (0, 2)):
        last = np.take(lab, -1, axis=ax_arr).ravel()
        first = np.take(lab, 0, axis=ax_arr).ravel()
        ok = (last > 0) & (first > 0)
        if ok.any():
            pairs = np.unique(np.stack([last[ok], first[ok]], axis=1), axis=0)
            for u, v in pairs:
                edges.append((int(u), int(v), ax_xyz))
    adj: dict[int, list] = {}
    for u, v, a in edges:
        s = np.zeros(3, dtype=np.int64)
        s[a] = 1
        adj.setdefault(u, []).append((v, s))
        adj.setdefault(v, []).append((u, -s))
    root = np.arange(n + 1, dtype=np.int64)
    offset = np.zeros((n + 1, 3), dtype=np.int64)
    seen = np.zeros(n + 1, dtype=bool)
    span_root = np.zeros((n + 1, 3), dtype=bool)
    for start in adj:
        if seen[start]:
            continue
        seen[start] = True
        queue = deque([start])
        while queue:
            u = queue.popleft()
            for v, s in adj[u]:
                want = offset[u] + s
                if not seen[v]:
                    seen[v] = True
                    root[v] = start
                    offset[v] = want
                    queue.append(v)
                else:
                    span_root[start] |= (want - offset[v]) != 0
    # compact numbering of the merged components
    roots, merged = np.unique(root[1:], return_inverse=True)
    relabel = np.zeros(n + 1, dtype=np.int32)
    relabel[1:] = merged.astype(np.int32) + 1
    labels = relabel[lab]
    spans = np.zeros((len(roots) + 1, 3), dtype=bool)
    spans[1:] = span_root[roots]
    sizes = np.bincount(labels.ravel(), minlength=len(roots) + 1).astype(np.int64)
    sizes[0] = 0
    return labels, spans, sizes
