"""Numba kernel of :func:`porecad.analysis.render.render`: z-buffer rasterisation of triangles.

Each triangle's pixels are found by edge functions over its bounding box
(Pineda 1988) with the pixel centre at ``(x + 0.5, y + 0.5)``; the depth,
the cut-plane distance and the vertex normal are interpolated
barycentrically, and the nearest fragment per pixel is kept (Catmull 1974).
Serial: a few hundred milliseconds of numpy become tens of milliseconds, and
the kernel is compiled by the first run's background helper
(:mod:`porecad.first_run`).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True)
def rasterise(px, py, z, side, faces, nrm, back, light, width, height, cut, z_lo, z_span, zbuf, shade, section):
    """Draw every face into ``zbuf`` (depth), ``shade`` (Lambert x depth cue) and ``section`` (a back face seen).

    ``px``, ``py``: screen coordinates of the vertices (pixels); ``z`` their
    depth along the view; ``side`` their signed distance to the cut plane
    (fragments with a positive interpolated distance are cut away when
    ``cut``); ``nrm`` unit vertex normals; ``back[f]`` whether face ``f``
    faces away from the eye; the buffers are flat, ``width * height`` long.
    """
    for t in range(faces.shape[0]):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        ax, ay, bx, by, ex, ey = px[a], py[a], px[b], py[b], px[c], py[c]
        den = (by - ey) * (ax - ex) + (ex - bx) * (ay - ey)
        if den == 0.0:
            continue
        x0 = min(max(int(math.floor(min(ax, bx, ex))), 0), width - 1)
        x1 = min(max(int(math.ceil(max(ax, bx, ex))), 0), width - 1)
        y0 = min(max(int(math.floor(min(ay, by, ey))), 0), height - 1)
        y1 = min(max(int(math.ceil(max(ay, by, ey))), 0), height - 1)
        for yy in range(y0, y1 + 1):
            qy = yy + 0.5
            for xx in range(x0, x1 + 1):
                qx = xx + 0.5
                l0 = ((by - ey) * (qx - ex) + (ex - bx) * (qy - ey)) / den
                l1 = ((ey - ay) * (qx - ex) + (ax - ex) * (qy - ey)) / den
                l2 = 1.0 - l0 - l1
                if l0 < 0.0 or l1 < 0.0 or l2 < 0.0:
                    continue
                if cut and l0 * side[a] + l1 * side[b] + l2 * side[c] > 0.0:
                    continue
                depth = l0 * z[a] + l1 * z[b] + l2 * z[c]
                pix = yy * width + xx
                if not depth < zbuf[pix]:
                    continue
                zbuf[pix] = depth
                nx = l0 * nrm[a, 0] + l1 * nrm[b, 0] + l2 * nrm[c, 0]
                ny = l0 * nrm[a, 1] + l1 * nrm[b, 1] + l2 * nrm[c, 1]
                nz = l0 * nrm[a, 2] + l1 * nrm[b, 2] + l2 * nrm[c, 2]
                nn = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-30)
                lam = min(max((nx * light[0] + ny * light[1] + nz * light[2]) / nn, 0.0), 1.0)
                cue = 1.0 - 0.45 * (depth - z_lo) / z_span
                shade[pix] = (0.22 + 0.78 * lam) * cue
                section[pix] = back[t]
