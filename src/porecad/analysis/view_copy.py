"""A lighter copy of a surface mesh for the report's pictures and 3D view (for printing: porecad.mesh.decimate).

Quadric edge collapse (Garland & Heckbert 1997, "Surface simplification
using quadric error metrics") by ``fast-simplification`` (MIT; the
Fast-Quadric-Mesh-Simplification library that trimesh and PyVista use);
where it is missing, vertex clustering on a uniform grid (Rossignac &
Borrel 1993) in numpy, whose cell is chosen from the surface area so that
about the wanted number of triangles remain. The copy keeps the shape to
within about one cell or collapsed edge; it need not stay closed or
manifold, and it is only drawn.
"""

from __future__ import annotations

import numpy as np

from ..mesh.arrays import scatter_sum

#: triangles of the report's viewer copy
VIEW_TRIANGLES = 150_000


def view_copy(vertices, faces, max_triangles: int = VIEW_TRIANGLES):
    """At most about ``max_triangles`` triangles of the same shape: ``(vertices float32, faces uint32)``."""
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    max_triangles = max(int(max_triangles), 4)
    if len(f) > max_triangles:
        try:
            import fast_simplification
        except ImportError:
            v, f = cluster(v, f, max_triangles)
        else:
            v, f = fast_simplification.simplify(v, f.astype(np.int32), target_count=max_triangles)
            v, f = np.asarray(v, dtype=np.float32), np.asarray(f, dtype=np.int64)
        if len(f) > 1.2 * max_triangles:  # a library that stopped early: cluster what is left
            v, f = cluster(v, f, max_triangles)
    used = np.zeros(len(v), bool)
    used[f.ravel()] = True
    remap = np.cumsum(used) - 1
    return np.ascontiguousarray(v[used]), np.ascontiguousarray(remap[f], dtype=np.uint32)


def cluster(vertices, faces, max_triangles: int):
    """Vertex clustering: weld the vertices of each grid cell at their mean; drop collapsed and repeated faces."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    p = v[f]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    # a surface of area A on a grid of cell h has about 2 A / h² triangles (two per crossed cell face)
    h = float(np.sqrt(2.0 * area / max(max_triangles, 1))) or 1.0
    for _ in range(8):
        key = np.floor((v - v.min(axis=0)) / h).astype(np.int64)
        _, cell = np.unique(key, axis=0, return_inverse=True)
        cell = cell.reshape(-1)
        g = cell[f]
        keep = (g[:, 0] != g[:, 1]) & (g[:, 1] != g[:, 2]) & (g[:, 0] != g[:, 2])
        g = g[keep]
        g = g[np.unique(np.sort(g, axis=1), axis=0, return_index=True)[1]]
        if len(g) <= 1.2 * max_triangles:
            break
        h *= 1.3
    n = int(cell.max()) + 1
    centre = scatter_sum(cell, v, n)
    centre /= np.bincount(cell, minlength=n)[:, None]
    return centre.astype(np.float32), g
