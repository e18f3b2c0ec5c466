"""Numba kernels for mesh bodies: winding numbers along z-rays and clamped distances.

Inside/outside is the winding number of the closed, oriented body mesh,
counted along a ray from each query point in the +z direction: every triangle
whose xy-projection contains the point's (x, y) and lies above it contributes
``+1`` if its normal points up (the ray leaves the body) and ``-1`` if it
points down (the ray enters). A point is inside when the sum is positive, so
a self-intersecting or overlapping closed mesh is treated as the union of its
parts, and nested shells (a cavity) come out right. Points on shared edges or
vertices of the projection are assigned to exactly one triangle by a
half-open "top-left" rule on exact float64 orientation tests, so no crossing
is counted twice or missed.

Unsigned distances are exact point-triangle distances (Ericson, *Real-Time
Collision Detection*, 5.1.5) to the triangles in the cells of a uniform 3D bin
grid within the clamp distance ``band``, nearest cells first; farther points
get ``band``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..mesh.box_bins import bin_boxes


# ---------------------------------------------------------------- binning
def bin_triangles_xy(vertices, faces, x0, y0, cell, nbx, nby):
    """CSR of triangles per xy bin (by the xy bounding box of each triangle).

    :func:`bin_triangles_xyz` with one bin in z (bin ``j * nbx + i``): one
    compiled kernel for both binnings (a first run compiles one, issue 22).
    """
    z0 = float(np.min(vertices[:, 2])) if len(vertices) else 0.0
    return bin_triangles_xyz(vertices, faces, np.array([x0, y0, z0], np.float64), float(cell),
                             np.array([nbx, nby, 1], np.int64))


def bin_triangles_xyz(vertices, faces, lo, cell, nb):
    """CSR of triangles per 3D bin (by bounding box), bins of edge ``cell`` from ``lo`` (:func:`bin_boxes`)."""
    a, b, c = (np.asarray(vertices[faces[:, i]], np.float64) for i in range(3))
    return bin_boxes(np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c),
                     np.asarray(lo, np.float64), float(cell), np.asarray(nb, np.int64))


# ---------------------------------------------------------------- ray crossings
@njit(cache=True, inline="always")
def _orient(ax, ay, bx, by, px, py):
    """Twice the signed area of (a, b, p), exactly antisymmetric in a and b.

    Evaluated with the edge's endpoints in a fixed (lexicographic) order, so the
    two triangles sharing an edge get exactly opposite values and a point
    rounding-close to the edge falls in exactly one of them.
    """
    if ax < bx or (ax == bx and ay < by):
        return (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    return -((ax - bx) * (py - by) - (ay - by) * (px - bx))


@njit(cache=True, inline="always")
def _top_left(ax, ay, bx, by):
    """Edge a->b of a counter-clockwise triangle owns the points on it (half-open rule)."""
    return (ay == by and bx < ax) or (by < ay)


@njit(cache=True)
def _crossing(vertices, faces, f, px, py):
    """(hit, z, sign) of the vertical line through (px, py) with triangle f."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    ax, ay = vertices[a, 0], vertices[a, 1]
    bx, by = vertices[b, 0], vertices[b, 1]
    cx, cy = vertices[c, 0], vertices[c, 1]
    area = _orient(ax, ay, bx, by, cx, cy)
    if area == 0.0:
        return False, 0.0, 0
    sign = 1
    if area < 0.0:  # clockwise in xy: the normal points down; test with swapped b, c
        sign = -1
        bx, by, cx, cy = cx, cy, bx, by
        b, c = c, b
        area = -area
    w0 = _orient(bx, by, cx, cy, px, py)
    w1 = _orient(cx, cy, ax, ay, px, py)
    w2 = _orient(ax, ay, bx, by, px, py)
    if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
        return False, 0.0, 0
    if w0 == 0.0 and not _top_left(bx, by, cx, cy):
        return False, 0.0, 0
    if w1 == 0.0 and not _top_left(cx, cy, ax, ay):
        return False, 0.0, 0
    if w2 == 0.0 and not _top_left(ax, ay, bx, by):
        return False, 0.0, 0
    z = (w0 * vertices[a, 2] + w1 * vertices[b, 2] + w2 * vertices[c, 2]) / area
    return True, z, sign


def column_crossings(vertices, faces, px, py, bin_start, bin_items, x0, y0, cell, nbx, nby):
    """Crossings of the vertical lines through points ``(px[q], py[q])``.

    Returns CSR ``(start, z, sign)``: for query ``q`` the crossings
    ``start[q] .. start[q+1]`` sorted by z, with the sign of the normal's z.
    Counted, then filled, by serial kernels on threads
    (:func:`porecad.kernel_threads.run_interleaved`).
    """
    from ..kernel_threads import run_interleaved

    nq = px.shape[0]
    counts = np.zeros(nq + 1, np.int64)
    args = (vertices, faces, px, py, bin_start, bin_items, float(x0), float(y0), float(cell), int(nbx), int(nby))
    run_interleaved(_column_counts, nq, *args, counts, min_per_thread=256)
    np.cumsum(counts, out=counts)
    zs = np.empty(counts[-1], np.float64)
    sg = np.empty(counts[-1], np.int8)
    run_interleaved(_column_fill, nq, *args, counts, zs, sg, min_per_thread=256)
    return counts, zs, sg


@njit(cache=True, nogil=True)
def _column_counts(vertices, faces, px, py, bin_start, bin_items, x0, y0, cell, nbx, nby, counts, first, step):
    """``counts[q + 1]`` = crossings of column ``q`` (columns ``first, first + step, ...``)."""
    for q in range(first, px.shape[0], step):
        b = _bin_of(px[q], py[q], x0, y0, cell, nbx, nby)
        if b < 0:
            continue
        n = 0
        for t in range(bin_start[b], bin_start[b + 1]):
            hit, z, s = _crossing(vertices, faces, bin_items[t], px[q], py[q])
            if hit:
                n += 1
        counts[q + 1] = n


@njit(cache=True, nogil=True)
def _column_fill(vertices, faces, px, py, bin_start, bin_items, x0, y0, cell, nbx, nby, counts, zs, sg, first, step):
    """The crossings of columns ``first, first + step, ...`` at ``counts[q]..``, sorted by z."""
    for q in range(first, px.shape[0], step):
        b = _bin_of(px[q], py[q], x0, y0, cell, nbx, nby)
        if b < 0:
            continue
        o = counts[q]
        for t in range(bin_start[b], bin_start[b + 1]):
            hit, z, s = _crossing(vertices, faces, bin_items[t], px[q], py[q])
            if hit:
                zs[o] = z
                sg[o] = s
                o += 1
        # insertion sort by z (columns hold a handful of crossings)
        for i in range(counts[q] + 1, counts[q + 1]):
            zk, sk = zs[i], sg[i]
            j = i - 1
            while j >= counts[q] and zs[j] > zk:
                zs[j + 1] = zs[j]
                sg[j + 1] = sg[j]
                j -= 1
            zs[j + 1] = zk
            sg[j + 1] = sk


@njit(cache=True, inline="always")
def _bin_of(x, y, x0, y0, cell, nbx, nby):
    i = int(math.floor((x - x0) / cell))
    j = int(math.floor((y - y0) / cell))
    if i < 0 or j < 0 or i >= nbx or j >= nby:
        return -1
    return j * nbx + i


def winding_on_columns(start, zs, sg, zq, out):
    """``out[k, q]`` = winding number at height ``zq[k]`` on column ``q`` (crossings above it)."""
    from ..kernel_threads import run_interleaved
    run_interleaved(_winding_on_columns, start.shape[0] - 1, start, zs, sg, zq, out, min_per_thread=256)


@njit(cache=True, nogil=True)
def _winding_on_columns(start, zs, sg, zq, out, first, step):
    nq = start.shape[0] - 1
    nk = zq.shape[0]
    for q in range(first, nq, step):
        s0, s1 = start[q], start[q + 1]
        # walk the sorted heights and crossings together from the top down
        w = 0
        t = s1 - 1
        for k in range(nk - 1, -1, -1):
            while t >= s0 and zs[t] > zq[k]:
                w += sg[t]
                t -= 1
            out[k, q] = w


@njit(cache=True, parallel=True)
def winding_at_points(start, zs, sg, pz):
    """Winding number of each query point from its own column of crossings."""
    nq = pz.shape[0]
    out = np.zeros(nq, np.int32)
    for q in prange(nq):
        w = 0
        for t in range(start[q], start[q + 1]):
            if zs[t] > pz[q]:
                w += sg[t]
        out[q] = w
    return out


# ---------------------------------------------------------------- distances
@njit(cache=True, inline="always")
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@njit(cache=True)
def point_triangle_closest(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Closest point of a triangle to a point (Ericson 5.1.5, by Voronoi regions)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = _dot(abx, aby, abz, apx, apy, apz)
    d2 = _dot(acx, acy, acz, apx, apy, apz)
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = _dot(abx, aby, abz, bpx, bpy, bpz)
    d4 = _dot(acx, acy, acz, bpx, bpy, bpz)
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = _dot(abx, aby, abz, cpx, cpy, cpz)
    d6 = _dot(acx, acy, acz, cpx, cpy, cpz)
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w


@njit(cache=True)
def _nearest_point(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band):
    """Squared distance and closest point among the triangles binned near the point, up to ``band``.

    The bins within ``band`` of the point (``ceil(band / cell)`` bins each
    way) are searched ring by ring outwards, skipping a bin whose box lies
    farther than the closest triangle found so far and stopping at the first
    ring that lies farther: every triangle within ``band`` meets the bin of
    its closest point, so the result is exact.

    Returns ``(d2, qx, qy, qz)``; ``d2 = band²`` and NaN coordinates when no
    triangle is closer than ``band``.
    """
    i = int(math.floor((px - lo[0]) / cell))
    j = int(math.floor((py - lo[1]) / cell))
    k = int(math.floor((pz - lo[2]) / cell))
    r = int(math.ceil(band / cell * (1.0 - 1e-12)))
    best = band * band
    bx, by, bz = np.nan, np.nan, np.nan
    for ring in range(r + 1):
        if ring >= 2 and ((ring - 1) * cell) ** 2 >= best:
            break
        for kk in range(max(k - ring, 0), min(k + ring + 1, nb[2])):
            dz = max(lo[2] + kk * cell - pz, 0.0, pz - lo[2] - (kk + 1) * cell)
            for jj in range(max(j - ring, 0), min(j + ring + 1, nb[1])):
                dy = max(lo[1] + jj * cell - py, 0.0, py - lo[1] - (jj + 1) * cell)
                on_shell = abs(kk - k) == ring or abs(jj - j) == ring
                for ii in range(max(i - ring, 0), min(i + ring + 1, nb[0])):
                    if not on_shell and abs(ii - i) != ring:
                        continue  # an inner ring's bin, searched already
                    dx = max(lo[0] + ii * cell - px, 0.0, px - lo[0] - (ii + 1) * cell)
                    if dx * dx + dy * dy + dz * dz >= best:
                        continue
                    b = (kk * nb[1] + jj) * nb[0] + ii
                    for t in range(bin_start[b], bin_start[b + 1]):
                        f = bin_items[t]
                        a, bb, c = faces[f, 0], faces[f, 1], faces[f, 2]
                        qx, qy, qz = point_triangle_closest(
                            px, py, pz,
                            vertices[a, 0], vertices[a, 1], vertices[a, 2],
                            vertices[bb, 0], vertices[bb, 1], vertices[bb, 2],
                            vertices[c, 0], vertices[c, 1], vertices[c, 2])
                        d2 = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
                        if d2 < best:
                            best = d2
                            bx, by, bz = qx, qy, qz
    return best, bx, by, bz


@njit(cache=True)
def _bins_met(vertices, faces, f, lo, cell, nb, keep, count_only, start, pos, items):
    """Visit the bins of triangle ``f``'s bounding box that the triangle may meet (see :func:`bin_triangles_near`)."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    rng = np.empty(6, np.int64)
    for ax in range(3):
        t0 = min(vertices[a, ax], vertices[b, ax], vertices[c, ax])
        t1 = max(vertices[a, ax], vertices[b, ax], vertices[c, ax])
        rng[2 * ax] = min(max(int(math.floor((t0 - lo[ax]) / cell)), 0), nb[ax] - 1)
        rng[2 * ax + 1] = min(max(int(math.floor((t1 - lo[ax]) / cell)), 0), nb[ax] - 1)
    for k in range(rng[4], rng[5] + 1):
        for j in range(rng[2], rng[3] + 1):
            for i in range(rng[0], rng[1] + 1):
                px = lo[0] + (i + 0.5) * cell
                py = lo[1] + (j + 0.5) * cell
                pz = lo[2] + (k + 0.5) * cell
                qx, qy, qz = point_triangle_closest(
                    px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2], vertices[b, 0], vertices[b, 1],
                    vertices[b, 2], vertices[c, 0], vertices[c, 1], vertices[c, 2])
                if (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2 > keep:
                    continue
                bn = (k * nb[1] + j) * nb[0] + i
                if count_only:
                    start[bn + 1] += 1
                else:
                    items[pos[bn]] = f
                    pos[bn] += 1


@njit(cache=True)
def bin_triangles_near(vertices, faces, lo, cell, nb):
    """CSR of triangles per 3D bin, each triangle in the bins it may meet, not its whole bounding box.

    A bin is kept when the triangle comes within the bin's half diagonal of its centre (every bin the
    triangle crosses, and a few next to them). :func:`bin_triangles_xyz` puts a long slanted triangle (a
    facet of a thin branching tube) in every bin of its box: tens of thousands of bins, each then searched.
    """
    keep = (0.8660254037844387 * cell) ** 2 * (1.0 + 1e-9)
    total = nb[0] * nb[1] * nb[2]
    start = np.zeros(total + 1, np.int64)
    pos = np.zeros(1, np.int64)
    items = np.zeros(1, np.int32)
    for f in range(faces.shape[0]):
        _bins_met(vertices, faces, f, lo, cell, nb, keep, True, start, pos, items)
    for b in range(total):
        start[b + 1] += start[b]
    pos = start[:-1].copy()
    items = np.empty(start[-1], np.int32)
    for f in range(faces.shape[0]):
        _bins_met(vertices, faces, f, lo, cell, nb, keep, False, start, pos, items)
    return start, items


@njit(cache=True)
def _clamped_distance(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band):
    d2, _, _, _ = _nearest_point(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band)
    return math.sqrt(d2)


@njit(cache=True, parallel=True, nogil=True)
def signed_distance_grid(vertices, faces, xs, ys, zs, winding, lo, cell, nb, bin_start, bin_items,
                         near, band, out):
    """``out[k, j, i]``: distance to the surface clamped to ``band``, negative inside.

    ``winding[k, j * nx + i]`` is the winding number of the sample; ``near``
    flags the 3D bins within ``band`` of a triangle (only those samples search).
    """
    nx, ny, nk = xs.shape[0], ys.shape[0], zs.shape[0]
    for kj in prange(nk * ny):
        k = kj // ny
        j = kj - k * ny
        z = zs[k]
        y = ys[j]
        bk = int(math.floor((z - lo[2]) / cell))
        bj = int(math.floor((y - lo[1]) / cell))
        row_near = 0 <= bk < nb[2] and 0 <= bj < nb[1]
        for i in range(nx):
            x = xs[i]
            d = band
            if row_near:
                bi = int(math.floor((x - lo[0]) / cell))
                if 0 <= bi < nb[0] and near[(bk * nb[1] + bj) * nb[0] + bi]:
                    d = _clamped_distance(vertices, faces, x, y, z, lo, cell, nb, bin_start, bin_items,
                                          band)
            out[k, j, i] = -d if winding[k, j * nx + i] > 0 else d


@njit(cache=True, parallel=True)
def clamped_distance_points(vertices, faces, points, lo, cell, nb, bin_start, bin_items, near, band):
    """Distances of arbitrary points to the surface, clamped to ``band`` (``near``: the bins within ``band`` of a
    triangle, see :func:`dilate_bins`; a point in another bin is ``band`` away at least)."""
    n = points.shape[0]
    out = np.empty(n)
    for q in prange(n):
        i = int(math.floor((points[q, 0] - lo[0]) / cell))
        j = int(math.floor((points[q, 1] - lo[1]) / cell))
        k = int(math.floor((points[q, 2] - lo[2]) / cell))
        if 0 <= i < nb[0] and 0 <= j < nb[1] and 0 <= k < nb[2] and not near[(k * nb[1] + j) * nb[0] + i]:
            out[q] = band
            continue
        out[q] = _clamped_distance(vertices, faces, points[q, 0], points[q, 1], points[q, 2], lo, cell, nb,
                                   bin_start, bin_items, band)
    return out


@njit(cache=True)
def dilate_bins(counts, nb, r=1):
    """Flags of the bins within ``r`` bins (each axis) of a bin that holds a triangle: the bins whose points may
    lie within ``r`` bin edges of the surface. Three separable passes."""
    nxb, nyb, nzb = nb[0], nb[1], nb[2]
    cur = np.zeros(nxb * nyb * nzb, np.bool_)
    for b in range(nxb * nyb * nzb):
        cur[b] = counts[b + 1] > counts[b]
    for ax in range(3):
        out = np.zeros_like(cur)
        for k in range(nzb):
            for j in range(nyb):
                for i in range(nxb):
                    if not cur[(k * nyb + j) * nxb + i]:
                        continue
                    idx = (i, j, k)
                    n = (nxb, nyb, nzb)[ax]
                    for m in range(max(idx[ax] - r, 0), min(idx[ax] + r + 1, n)):
                        if ax == 0:
                            out[(k * nyb + j) * nxb + m] = True
                        elif ax == 1:
                            out[(k * nyb + m) * nxb + i] = True
                        else:
                            out[(m * nyb + j) * nxb + i] = True
        cur = out
    return cur


@njit(cache=True, parallel=True)
def closest_point_sweep(xs, ys, zs, c_in, c_out, best):
    """One Jacobi sweep of closest-point propagation on a grid.

    ``c_in[k, j, i]`` is a surface point believed closest to grid point
    ``(xs[i], ys[j], zs[k])`` and ``best`` its distance; each point also tries
    the closest points of its 26 neighbours and keeps the nearest
    (``c_out``, ``best`` updated). Points with NaN candidates are skipped.
    """
    nz, ny, nx = best.shape
    for k in prange(nz):
        for j in range(ny):
            for i in range(nx):
                px, py, pz = xs[i], ys[j], zs[k]
                b = best[k, j, i]
                bx, by, bz = c_in[k, j, i, 0], c_in[k, j, i, 1], c_in[k, j, i, 2]
                for dk in range(-1, 2):
                    kk = k + dk
                    if kk < 0 or kk >= nz:
                        continue
                    for dj in range(-1, 2):
                        jj = j + dj
                        if jj < 0 or jj >= ny:
                            continue
                        for di in range(-1, 2):
                            ii = i + di
                            if ii < 0 or ii >= nx:
                                continue
                            cx, cy, cz = c_in[kk, jj, ii, 0], c_in[kk, jj, ii, 1], c_in[kk, jj, ii, 2]
                            d = math.sqrt((px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2)
                            if d < b:
                                b, bx, by, bz = d, cx, cy, cz
                best[k, j, i] = b
                c_out[k, j, i, 0], c_out[k, j, i, 1], c_out[k, j, i, 2] = bx, by, bz


@njit(cache=True, parallel=True)
def closest_points(vertices, faces, points, lo, cell, nb, bin_start, bin_items, band, out):
    """Closest surface point of each point among triangles within ``band`` (NaN where none)."""
    for q in prange(points.shape[0]):
        _, bx, by, bz = _nearest_point(vertices, faces, points[q, 0], points[q, 1], points[q, 2], lo, cell, nb,
                                       bin_start, bin_items, band)
        out[q, 0], out[q, 1], out[q, 2] = bx, by, bz


@njit(cache=True, nogil=True)
def point_distance(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band):
    """The distance of one point to the surface, clamped to ``band`` (the kernel of :func:`signed_distance_grid`,
    for other kernels)."""
    return _clamped_distance(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band)


@njit(cache=True, nogil=True)
def nearest_point(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band):
    """``(d2, qx, qy, qz)``: the squared distance and closest surface point of one point, up to ``band``
    (``band²`` and NaN beyond: :func:`_nearest_point`, for other kernels)."""
    return _nearest_point(vertices, faces, px, py, pz, lo, cell, nb, bin_start, bin_items, band)
