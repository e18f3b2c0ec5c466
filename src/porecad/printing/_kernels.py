"""Numba kernels of the slicer (:mod:`porecad.printing.raster`, :mod:`porecad.printing.printability`).

* :func:`layer_grey` — one layer's field samples to anti-aliased grey in one
  pass: the in-plane gradient per pixel step by central differences (one-sided
  at the edges, as ``numpy.gradient``), coverage ``clip(1/2 - f / |g|, 0, 1)``,
  the 8-bit grey with row 0 at the largest y, and the layer's solid area.
* :func:`new_islands` — 8-connected pieces of a layer's solid (coverage at
  least 1/2) that touch no solid of the layer below (union-find over the
  pixels); returns their pixel counts and centroids.

No kernel raises, formats strings or runs threads (the slicer's bands do).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def layer_grey(v, px, py, weights, use_weights, grey, solid, empty=1e300):
    """Grey (ny, nx) uint8 and solid (ny, nx) bool of field samples ``v`` (ny, nx) on ``px`` x ``py`` mm pixels;
    returns the area (mm²). The coverage needs only the gradient per pixel step (any pixel aspect).

    Pixels of a value at least ``empty`` (> 0) are empty without their gradient: the caller knows that the
    field changes by less than twice that over a pixel (a body's band, :class:`porecad.printing.part.LayerWindows`).
    """
    ny, nx = v.shape
    total = 0.0
    tiny = 1e-12 * min(px, py)
    for j in range(ny):
        j0 = j - 1 if j > 0 else j
        j1 = j + 1 if j < ny - 1 else j
        for i in range(nx):
            if v[j, i] >= empty:
                solid[j, i] = False
                grey[ny - 1 - j, i] = 0
                continue
            i0 = i - 1 if i > 0 else i
            i1 = i + 1 if i < nx - 1 else i
            gx = (v[j, i1] - v[j, i0]) / np.float32(max(i1 - i0, 1))
            gy = (v[j1, i] - v[j0, i]) / np.float32(max(j1 - j0, 1))
            g = math.sqrt(gx * gx + gy * gy)  # per pixel
            f = v[j, i]
            if g > tiny:
                c = 0.5 - f / g
                c = 0.0 if c < 0.0 else (1.0 if c > 1.0 else c)
            else:
                c = 1.0 if f < 0 else 0.0
            solid[j, i] = c >= 0.5
            if use_weights:
                c *= weights[j, i]
            total += c
            grey[ny - 1 - j, i] = np.uint8(c * 255.0 + 0.5)
    return total * px * py


@njit(cache=True, nogil=True)
def _find(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, nogil=True)
def new_islands(solid, below, j0=0, i0=0):
    """``(counts, mean row, mean column)`` of the pieces of ``solid`` (ny, nx) that rest on nothing in ``below``.

    ``solid`` and ``below`` may be a window of the layers from row ``j0`` and column ``i0`` (no solid
    beyond it): the rows and columns are the layer's.

    Runs of solid pixels along the rows are joined when they touch in neighbouring rows (8-connected),
    so the union-find works on runs, not pixels.
    """
    ny, nx = solid.shape
    cap = ny * (nx // 2 + 1)
    rs = np.empty(cap, dtype=np.int32)
    re = np.empty(cap, dtype=np.int32)
    rr = np.empty(cap, dtype=np.int32)
    first = np.zeros(ny + 1, dtype=np.int32)
    n = 0
    for j in range(ny):
        first[j] = n
        i = 0
        while i < nx:
            if solid[j, i]:
                s0 = i
                while i < nx and solid[j, i]:
                    i += 1
                rs[n], re[n], rr[n] = s0, i, j
                n += 1
            else:
                i += 1
    first[ny] = n
    parent = np.arange(n).astype(np.int32)
    for j in range(1, ny):
        a, b = first[j - 1], first[j]
        while a < first[j] and b < first[j + 1]:
            if rs[a] <= re[b] and rs[b] <= re[a]:  # touching, diagonals included (ends are exclusive)
                ra, rb = _find(parent, a), _find(parent, b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
            if re[a] < re[b]:
                a += 1
            else:
                b += 1
    supported = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        for i in range(rs[r], re[r]):
            if below[rr[r], i]:
                supported[_find(parent, r)] = True
                break
    count = np.zeros(n, dtype=np.int64)
    sj = np.zeros(n)
    si = np.zeros(n)
    for r in range(n):
        root = _find(parent, r)
        if not supported[root]:
            length = re[r] - rs[r]
            count[root] += length
            sj[root] += length * (rr[r] + j0)
            si[root] += length * (rs[r] + i0 + re[r] + i0 - 1) / 2.0
    roots = np.nonzero(count)[0]
    return count[roots], sj[roots] / count[roots], si[roots] / count[roots]
