"""Numba kernel of :class:`porecad.analysis.surface_index.SurfaceIndex`: exact nearest points.

Triangles are binned into a uniform 3D grid of cubic cells by their bounding
boxes (CSR: ``start[b] .. start[b + 1]`` index ``items``;
:func:`porecad.bodies.distance_kernels.bin_triangles_xyz`). A query point with
an upper bound ``ub`` on its distance to the surface scans only the cells
that meet the cube ``[p - ub, p + ub]`` and skips every cell whose box lies
farther than the best distance found so far; the point–triangle distance is
exact (Ericson, *Real-Time Collision Detection* 5.1.5, as in
:func:`porecad.bodies.distance_kernels.point_triangle_closest`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..bodies.distance_kernels import point_triangle_closest


@njit(cache=True, nogil=True)
def nearest(vertices, faces, box_lo, box_hi, points, ub, lo, cell, nb, start, items, dist, closest, tri, first, step):
    """Exact distance, closest surface point and its triangle for points ``first, first + step, ...``.

    Among the triangles within ``ub[q]``: ``dist[q]`` is the distance
    (``ub[q]`` where no triangle is nearer, then ``closest[q]`` is NaN and
    ``tri[q]`` -1). Serial and without the GIL: callers run one interleaved
    run per thread (a ``prange`` kernel costs seconds more to compile on the
    first run). A run stamps the triangles it has tested for the current
    point, so a long triangle binned in many cells is tested once; a triangle
    whose bounding box (``box_lo``, ``box_hi``) lies no nearer than the best
    distance so far is skipped before the exact test. At most 2**31 - 1 points a call.
    """
    n = points.shape[0]
    stamp = np.full(faces.shape[0], -1, np.int32)    # int32: half the memory traffic of its random writes
    for q in range(first, n, step):
        qs = np.int32(q)
        px, py, pz = points[q, 0], points[q, 1], points[q, 2]
        u = ub[q]
        best = u * u
        bx, by, bz = np.nan, np.nan, np.nan
        bf = -1
        i0 = max(int(math.floor((px - u - lo[0]) / cell)), 0)
        i1 = min(int(math.floor((px + u - lo[0]) / cell)), nb[0] - 1)
        j0 = max(int(math.floor((py - u - lo[1]) / cell)), 0)
        j1 = min(int(math.floor((py + u - lo[1]) / cell)), nb[1] - 1)
        k0 = max(int(math.floor((pz - u - lo[2]) / cell)), 0)
        k1 = min(int(math.floor((pz + u - lo[2]) / cell)), nb[2] - 1)
        for k in range(k0, k1 + 1):
            cz0 = lo[2] + k * cell
            dz = max(cz0 - pz, 0.0, pz - cz0 - cell)
            for j in range(j0, j1 + 1):
                cy0 = lo[1] + j * cell
                dy = max(cy0 - py, 0.0, py - cy0 - cell)
                dzy = dz * dz + dy * dy
                if dzy >= best:
                    continue
                for i in range(i0, i1 + 1):
                    cx0 = lo[0] + i * cell
                    dx = max(cx0 - px, 0.0, px - cx0 - cell)
                    if dzy + dx * dx >= best:
                        continue
                    b = (k * nb[1] + j) * nb[0] + i
                    for t in range(start[b], start[b + 1]):
                        f = items[t]
                        if stamp[f] == qs:
                            continue
                        stamp[f] = qs
                        ex = max(box_lo[f, 0] - px, 0.0, px - box_hi[f, 0])
                        ey = max(box_lo[f, 1] - py, 0.0, py - box_hi[f, 1])
                        ez = max(box_lo[f, 2] - pz, 0.0, pz - box_hi[f, 2])
                        if ex * ex + ey * ey + ez * ez >= best:
                            continue
                        a, bb, c = faces[f, 0], faces[f, 1], faces[f, 2]
                        qx, qy, qz = point_triangle_closest(
                            px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                            vertices[bb, 0], vertices[bb, 1], vertices[bb, 2],
                            vertices[c, 0], vertices[c, 1], vertices[c, 2])
                        d2 = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
                        if d2 < best:
                            best = d2
                            bx, by, bz = qx, qy, qz
                            bf = f
        dist[q] = math.sqrt(best)
        closest[q, 0], closest[q, 1], closest[q, 2] = bx, by, bz
        tri[q] = bf
