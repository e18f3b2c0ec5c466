"""A mesh body's signed distance on a print layer's pixels, exact only where the slices need it.

:meth:`MeshBody.sample_grid <porecad.bodies.mesh.MeshBody.sample_grid>` computes the exact distance
(clamped to ``band``) for every sample in the 3D bins near the surface: for a body sliced at 50 µm
that is a shell a few bins thick and most of the slicing time (issue 54). A layer's grey depends on
the body's distance only near the body's outline in the layer (its anti-aliased edge, a skin's inner
edge); elsewhere the body only clamps the lattice by its sign. :class:`SlicedBody` samples a layer
``z`` (any tensor grid with regular x and y axes) so:

* the layer's rectangle: the xy box of the triangles within ``band`` of ``z`` (in z), widened by
  ``band``. Outside it every pixel is outside the body and ``band`` or farther from it: ``+band``,
  as :class:`MeshBody` gives;
* the sign of every pixel in it: the winding number of its z-column (the body's column crossings,
  computed once for a rectangle of the grid that holds the layers' rectangles so far), counted for the nodes and the pixels near the surface;
  the others lie farther from the surface than from their nearest node, whose sign they have;
* the exact signed distance (clamped) and closest surface point on coarse nodes, every
  :data:`NODE_STRIDE`-th pixel in x and y;
* a pixel whose nodes bound its distance (1-Lipschitz: ``|d| >= |d_node| - |p - node|``) to at least
  ``W`` = :data:`EXACT_PIXELS` pixels from the surface (and from a skin's inner surface), with the
  nodes' sign: the bilinear interpolation of the nodes' signed distances (the signed distance is
  smooth across the surface, so this is close to it); whole node cells at once where the cell's
  nearest node is far enough;
* any other pixel: the exact distance, searched only as far as the nearest of its nodes' closest
  surface points (an upper bound: a far shorter search than the band's), over its node cell's
  candidates: the triangles whose boxes lie within the largest such bound of the cell's pixels (found
  once per cell; the triangles a pixel's search would not skip, met in the same order).

A node in a 3D bin of the body that lies farther than ``band`` from the surface is ``±band`` (a pixel
there that needs the exact value: the bound), with the sign of the previous node of its row where that
lies in the same bin (no surface between them); a pixel whose nodes bound it ``W`` or more from the
surface has its nodes' sign: only the others count their column's crossings.

The sign is exact everywhere (the layer's section is unchanged) and the distance exact within ``W``
of the surface (and of a skin's inner surface); farther pixels' values are interpolated (the grey
of a pixel depends on its value only within about a pixel of the outline). Measured on the femur
(bench/slice.md): the same layer areas as the exact route, every pixel within 3 pixels of the
surface bit-identical.
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit, prange

from ..fields.base import Field
from . import distance_kernels as K

#: coarse nodes every this many pixels in x and y
NODE_STRIDE = 4
#: pixels nearer than this to the outline (beyond the nodes' reach) get the exact distance
EXACT_PIXELS = 3.0


class SlicedBody(Field):
    """A :class:`~porecad.bodies.mesh.MeshBody` sampled on layers for the slicer (see the module doc).

    ``skin``: the thickness of a skin whose inner surface (distance ``-skin``) the slices show: the
    pixels near it get the exact distance too. Points (:meth:`evaluate`) and irregular grids are the
    body's own.
    """

    def __init__(self, body, skin: float = 0.0, stride: int = NODE_STRIDE, exact_pixels: float = EXACT_PIXELS):
        self.body, self.skin, self.stride, self.exact_pixels = body, float(skin), int(stride), float(exact_pixels)
        v, f = body.vertices, body.faces
        tri = v[f]  # (F, 3, 3)
        self._tmin, self._tmax = tri.min(axis=1), tri.max(axis=1)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        size = np.linalg.norm(n, axis=1)
        n = np.where(size[:, None] > 0, n / np.where(size > 0, size, 1.0)[:, None], 0.0)
        self._planes = np.ascontiguousarray(np.column_stack([n, np.einsum("ij,ij->i", n, tri[:, 0])]))
        self._lock, self._cols = threading.Lock(), None

    @property
    def bounds(self):
        return self.body.bounds

    @property
    def band(self) -> float:
        return self.body.band

    def evaluate(self, points):
        return self.body.evaluate(points)

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_tmin", "_tmax", "_planes", "_lock", "_cols")}

    def __setstate__(self, state):
        self.__init__(state["body"], state["skin"], state["stride"], state["exact_pixels"])

    def sample_grid(self, xs, ys, zs):
        xs, ys, zs = (np.ascontiguousarray(a, dtype=np.float64) for a in (xs, ys, zs))
        if not self.layered(xs, ys):
            return self.body.sample_grid(xs, ys, zs)
        out = np.full((len(zs), len(ys), len(xs)), self.band, np.float32)
        for k, z in enumerate(zs):
            got = self.sample_layer(xs, ys, float(z))
            if got is not None:
                i0, i1, j0, j1, sub = got
                out[k, j0:j1, i0:i1] = sub
        return out

    def layered(self, xs, ys) -> bool:
        """Whether a layer of the axes ``xs``, ``ys`` is sampled so (regular axes, at least a node cell):
        else :meth:`sample_grid` is the body's own."""
        return _regular(xs) and _regular(ys) and min(len(xs), len(ys)) >= 2 * self.stride + 1

    def sample_layer(self, xs, ys, z: float):
        """``(i0, i1, j0, j1, values)``: the distances (float32 ``(j1 - j0, i1 - i0)``) of the layer ``z``'s
        pixels ``xs[i0:i1]`` x ``ys[j0:j1]``; every other pixel's is ``+band``. None: all are ``+band``.
        The axes must be :meth:`layered` (float64, contiguous)."""
        rect = self._rect(xs, ys, z)
        if rect is None:
            return None
        b = self.body
        px, py = xs[1] - xs[0], ys[1] - ys[0]
        near = b._distance_bins()[2]
        i0, i1, j0, j1, hit = rect
        start, zc, sg, width, c0, r0 = self._columns(xs, ys, (i0, i1, j0, j1))
        w = (start, zc, sg, width, i0 - c0, j0 - r0)
        q = (b._lo3, float(b._cell3), b._nb3, near, np.nonzero(hit)[0].astype(np.int64), self._tmin, self._tmax,
             self._planes)
        sub = np.empty((j1 - j0, i1 - i0), np.float32)
        _layer_distance(b.vertices, b.faces, xs[i0:i1], ys[j0:j1], z, w, q, b.band, self.stride,
                        self.exact_pixels * max(px, py), self.skin, sub)
        return i0, i1, j0, j1, sub

    def _columns(self, xs, ys, rect):
        """``(start, zc, sg, width, i0, j0)``: the body's z crossings (CSR) of the pixel columns of a rectangle
        of the grid (``width`` columns wide, from column ``i0`` and row ``j0``) that holds ``rect``; computed
        for the first rectangle asked, widened by a sixteenth of the grid, and again for the union widened
        by an eighth where a later one lies beyond it; for the whole grid once that is more than half of it
        (a band of layers pays for its own columns only, the whole part about once)."""
        nx, ny = len(xs), len(ys)
        key = (nx, float(xs[0]), float(xs[-1]), ny, float(ys[0]), float(ys[-1]))
        i0, i1, j0, j1 = rect
        with self._lock:
            c = self._cols
            if c is not None and c[0] == key and c[1] <= i0 and i1 <= c[2] and c[3] <= j0 and j1 <= c[4]:
                return c[5]
            mx, my = (max(1, nx // 16), max(1, ny // 16)) if c is None or c[0] != key else (nx // 8, ny // 8)
            if c is not None and c[0] == key:
                i0, i1, j0, j1 = min(i0, c[1]), max(i1, c[2]), min(j0, c[3]), max(j1, c[4])
            i0, i1, j0, j1 = max(0, i0 - mx), min(nx, i1 + mx), max(0, j0 - my), min(ny, j1 + my)
            if 2 * (i1 - i0) * (j1 - j0) > nx * ny:
                i0, i1, j0, j1 = 0, nx, 0, ny
            b = self.body
            px = np.tile(xs[i0:i1], j1 - j0)
            py = np.repeat(ys[j0:j1], i1 - i0)
            start, zc, sg = K.column_crossings(b.vertices, b.faces, px, py, b._xy_start, b._xy_items, b._x0, b._y0,
                                               b._cell_xy, b._nbx, b._nby)
            self._cols = (key, i0, i1, j0, j1, (start, zc, sg, i1 - i0, i0, j0))
            return self._cols[5]

    def _rect(self, xs, ys, z):
        """``(i0, i1, j0, j1, hit)``: the pixels within ``band`` (in x and y) of the triangles within ``band`` of
        ``z`` (``hit``: those triangles' flags); None when there are none."""
        band = self.body.band
        hit = (self._tmin[:, 2] <= z + band) & (self._tmax[:, 2] >= z - band)
        if not hit.any():
            return None
        lo = self._tmin[hit, :2].min(axis=0) - band
        hi = self._tmax[hit, :2].max(axis=0) + band
        i0, i1 = np.searchsorted(xs, lo[0], "left"), np.searchsorted(xs, hi[0], "right")
        j0, j1 = np.searchsorted(ys, lo[1], "left"), np.searchsorted(ys, hi[1], "right")
        if i1 <= i0 or j1 <= j0:
            return None
        i0, j0 = min(i0, len(xs) - 2), min(j0, len(ys) - 2)  # at least 2 x 2 pixels (the kernel's pitch)
        return int(i0), int(max(i1, i0 + 2)), int(j0), int(max(j1, j0 + 2)), hit


def _regular(a) -> bool:
    if len(a) < 2:
        return False
    d = np.diff(a)
    return bool(d[0] > 0 and np.allclose(d, d[0], rtol=1e-9, atol=1e-12 * max(1.0, abs(a).max())))


@njit(cache=True, nogil=True, inline="always")
def _winding(w, i, j, z):
    """The winding number at height ``z`` of pixel ``(i, j)`` of the layer's rectangle: ``w`` = (the column
    crossings ``start, zc, sg`` of a rectangle of the grid that holds it, that one's width, the layer rectangle's
    first column and row in it)."""
    start, zc, sg, nx, i0, j0 = w
    q = (j0 + j) * nx + i0 + i
    n = 0
    for t in range(start[q], start[q + 1]):
        if zc[t] > z:
            n += sg[t]
    return n


@njit(cache=True, nogil=True)
def _bins(xs, ys, z, lo, cell, nb, near):
    """``(bx, by, k, nb, near)``: the body's 3D bin of each pixel column ``bx`` and row ``by`` and of the layer ``k``
    (-1 beyond the bins), their counts and near flags, for :func:`_far`."""
    bx = np.empty(xs.shape[0], np.int64)
    by = np.empty(ys.shape[0], np.int64)
    for i in range(xs.shape[0]):
        bi = int(math.floor((xs[i] - lo[0]) / cell))
        bx[i] = bi if 0 <= bi < nb[0] else -1
    for j in range(ys.shape[0]):
        bj = int(math.floor((ys[j] - lo[1]) / cell))
        by[j] = bj if 0 <= bj < nb[1] else -1
    bk = int(math.floor((z - lo[2]) / cell))
    return bx, by, bk if 0 <= bk < nb[2] else -1, nb, near


@njit(cache=True, nogil=True, inline="always")
def _far(bins, i, j):
    """The bin of pixel ``(i, j)`` (:func:`_bins`) where that lies farther than the body's band from the surface,
    else -1."""
    bx, by, bk, nb, near = bins
    if bx[i] < 0 or by[j] < 0 or bk < 0:
        return -1
    bn = (bk * nb[1] + by[j]) * nb[0] + bx[i]
    return -1 if near[bn] else bn


@njit(cache=True, nogil=True)
def _rows(ys, iy, cand, tmin, tmax, band):
    """CSR ``(start, items)`` of the candidate triangles ``cand`` per node row ``b``: those whose y range lies
    within ``band`` of the rows from node row ``b`` to the next (every triangle within ``band`` of a point
    there: the layer's triangles within ``band`` in z are ``cand``)."""
    my = iy.shape[0]
    lo_b = np.empty(my, np.float64)
    hi_b = np.empty(my, np.float64)
    for b in range(my):
        lo_b[b] = ys[iy[b]] - band
        hi_b[b] = ys[iy[min(b + 1, my - 1)]] + band
    start = np.zeros(my + 1, np.int64)
    for t in range(cand.shape[0]):
        f = cand[t]
        for b in range(my):
            if tmin[f, 1] <= hi_b[b] and tmax[f, 1] >= lo_b[b]:
                start[b + 1] += 1
    for b in range(my):
        start[b + 1] += start[b]
    items = np.empty(start[my], np.int64)
    fill = start[:-1].copy()
    for t in range(cand.shape[0]):
        f = cand[t]
        for b in range(my):
            if tmin[f, 1] <= hi_b[b] and tmax[f, 1] >= lo_b[b]:
                items[fill[b]] = f
                fill[b] += 1
    return start, items


@njit(cache=True, nogil=True, inline="always")
def _nearest(vertices, faces, x, y, z, q, items, t0, t1, clamp, far):
    """``(d, qx, qy, qz)``: the distance (clamped) and closest surface point of a point (NaN beyond ``clamp``;
    ``far`` where that is not negative: its bin is farther than the body's band from the surface, :func:`_far`):
    the least over the candidate triangles ``items[t0:t1]`` (every triangle within ``clamp`` of the point;
    ``q``: the body's 3D bins' origin, edge, counts and near flags, the rows' candidates, the triangles' boxes
    and planes), as :func:`porecad.bodies.distance_kernels.nearest_point` finds it."""
    lo, cell, nb, near, start, _, tmin, tmax, planes = q
    if far >= 0.0:
        return far, np.nan, np.nan, np.nan
    best = clamp * clamp
    bx, by, bz = np.nan, np.nan, np.nan
    for t in range(t0, t1):
        f = items[t]
        dx = max(tmin[f, 0] - x, 0.0, x - tmax[f, 0])
        dy = max(tmin[f, 1] - y, 0.0, y - tmax[f, 1])
        dz = max(tmin[f, 2] - z, 0.0, z - tmax[f, 2])
        if dx * dx + dy * dy + dz * dz > best * (1.0 + 1e-9):  # (a rounding's slack: the box holds the point)
            continue
        h = abs(planes[f, 0] * x + planes[f, 1] * y + planes[f, 2] * z - planes[f, 3]) - 1e-9  # its plane's distance
        if h > 0.0 and h * h > best:
            continue
        a, bb, c = faces[f, 0], faces[f, 1], faces[f, 2]
        qx, qy, qz = K.point_triangle_closest(x, y, z, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                                              vertices[bb, 0], vertices[bb, 1], vertices[bb, 2],
                                              vertices[c, 0], vertices[c, 1], vertices[c, 2])
        d2 = (qx - x) ** 2 + (qy - y) ** 2 + (qz - z) ** 2
        if d2 < best:
            best = d2
            bx, by, bz = qx, qy, qz
    return math.sqrt(best), bx, by, bz


@njit(cache=True, parallel=True, nogil=True)
def _layer_distance(vertices, faces, xs, ys, z, w, q0, band, s, wc, skin, out):
    """``out[j, i]``: the signed distance of the pixels ``(xs[i], ys[j], z)`` (module doc): nodes every ``s``
    pixels exact; a pixel whose nodes bound its distance (1-Lipschitz) to at least ``wc`` from the surface and
    the skin's inner surface interpolated, the rest exact, searched only as far as the nearest of the nodes'
    closest surface points. ``q0``: the body's 3D bins (origin, edge, counts, near flags), the layer's
    triangles within ``band`` in z and every triangle's box."""
    nx, ny = xs.shape[0], ys.shape[0]
    px, py = xs[1] - xs[0], ys[1] - ys[0]
    mx, my = (nx - 1) // s + 2, (ny - 1) // s + 2  # node columns 0, s, 2s, ... and the last pixel
    ix = np.empty(mx, np.int64)
    iy = np.empty(my, np.int64)
    for a in range(mx):
        ix[a] = min(a * s, nx - 1)
    for a in range(my):
        iy[a] = min(a * s, ny - 1)
    lo, cell, nb, near, cand, tmin, tmax, planes = q0
    start, items = _rows(ys, iy, cand, tmin, tmax, band)
    q = (lo, cell, nb, near, start, items, tmin, tmax, planes)
    node = np.empty((my, mx), np.float64)
    foot = np.empty((my, mx, 3), np.float64)
    bins = _bins(xs, ys, z, lo, cell, nb, near)
    for b in prange(my):
        j = iy[b]
        prev, val = -1, band  # the previous node's bin (and value) where that is farther than the band from the surface
        for a in range(mx):
            i = ix[a]
            bn = _far(bins, i, j)
            if bn >= 0:
                if bn != prev:  # the same bin as the previous node's: no surface between them, the same sign
                    prev, val = bn, -band if _winding(w, i, j, z) > 0 else band
                node[b, a] = val
                foot[b, a, 0], foot[b, a, 1], foot[b, a, 2] = np.nan, np.nan, np.nan
                continue
            prev = -1
            clamp = band  # searched only as far as the previous node's closest surface point (the same result)
            if a > 0 and not math.isnan(foot[b, a - 1, 0]):
                u = math.sqrt((xs[i] - foot[b, a - 1, 0]) ** 2 + (ys[j] - foot[b, a - 1, 1]) ** 2
                              + (z - foot[b, a - 1, 2]) ** 2)
                clamp = min(band, u * (1.0 + 1e-9) + 1e-12)
            d, qx, qy, qz = _nearest(vertices, faces, xs[i], ys[j], z, q, items, start[b], start[b + 1], clamp,
                                    -1.0)
            node[b, a] = -d if _winding(w, i, j, z) > 0 else d
            foot[b, a, 0], foot[b, a, 1], foot[b, a, 2] = qx, qy, qz
    rcell = 0.5 * s * math.hypot(px, py)
    hyp = np.empty((2 * s + 1, 2 * s + 1), np.float64)  # the pixels' distances to their nodes (:func:`_bounds`)
    for dj in range(-s, s + 1):
        for di in range(-s, s + 1):
            hyp[s + dj, s + di] = math.hypot(di * px, dj * py)
    for bp in prange(my - 1):
        b = int(bp)
        j1 = (b + 1) * s if b < my - 2 else ny
        buf = np.empty(start[b + 1] - start[b], np.int64)  # a cell's candidates (:func:`_cell_candidates`)
        for a in range(mx - 1):
            i1 = (a + 1) * s if a < mx - 2 else nx
            c00, c01, c10, c11 = node[b, a], node[b, a + 1], node[b + 1, a], node[b + 1, a + 1]
            neg = c00 < 0
            same = (c01 < 0) == neg and (c10 < 0) == neg and (c11 < 0) == neg
            lo_c = min(abs(c00), abs(c01), abs(c10), abs(c11)) - rcell
            hi_c = max(abs(c00), abs(c01), abs(c10), abs(c11)) + rcell
            if same and lo_c >= wc and (skin <= 0 or lo_c >= skin + wc or hi_c <= skin - wc) and (
                    c00 == c01 and c00 == c10 and c00 == c11):
                out[b * s:j1, a * s:i1] = c00  # all four nodes at the band (outside or inside): its value
            elif same and lo_c >= wc and (skin <= 0 or lo_c >= skin + wc or hi_c <= skin - wc):
                for j in range(b * s, j1):  # the whole cell lies away from the surface (and the skin's)
                    ty = (j - iy[b]) / max(iy[b + 1] - iy[b], 1)
                    for i in range(a * s, i1):
                        tx = (i - ix[a]) / max(ix[a + 1] - ix[a], 1)
                        out[j, i] = (1 - ty) * ((1 - tx) * c00 + tx * c01) + ty * ((1 - tx) * c10 + tx * c11)
            else:
                _cell_pixels(vertices, faces, xs, ys, z, w, q, band, wc, skin, node, foot, ix, iy, int(a), int(b),
                             (int(a) * s, int(i1), b * s, int(j1)), buf, out, hyp, bins)


@njit(cache=True, nogil=True)
def _cell_pixels(vertices, faces, xs, ys, z, w, q, band, wc, skin, node, foot, ix, iy, a, b, box, buf, out,
                 hyp, bins):
    """``out`` on the pixels ``box`` = ``(i0, i1, j0, j1)`` of node cell ``(a, b)`` near the surface: interpolated
    where a pixel's own bounds allow (:func:`_bounds`), else exact, over the cell's candidates
    (:func:`_cell_candidates`, found once for the cell at its first exact pixel)."""
    i0, i1, j0, j1 = box
    n = -1
    for j in range(j0, j1):
        for i in range(i0, i1):
            inside, upper, v = _bounds(xs, ys, z, w, band, wc, skin, node, foot, ix, iy, a, b, i, j, hyp)
            if not math.isnan(v):
                out[j, i] = v
                continue
            if n < 0:
                n = _cell_candidates(xs, ys, z, q, band, foot, a, b, box, buf)
            clamp = upper * (1.0 + 1e-9) + 1e-12 if upper < band else band
            far = clamp if _far(bins, i, j) >= 0 else -1.0
            d = min(_nearest(vertices, faces, xs[i], ys[j], z, q, buf, 0, n, clamp, far)[0], upper)
            out[j, i] = -d if inside else d


@njit(cache=True, nogil=True)
def _cell_candidates(xs, ys, z, q, band, foot, a, b, box, buf):
    """The number ``n`` of node row ``b``'s candidates written to ``buf[:n]``, in the row's order, whose box lies
    within ``r`` of the pixels ``box`` of node cell ``(a, b)`` (in x and y their rectangle, in z ``z``): ``r``
    (with a rounding's slack) bounds every pixel's search radius there (at most ``band``, at most the farthest
    corner from any of the cell's nodes' closest surface points). Every other triangle's box lies farther from
    each pixel than its search radius: :func:`_nearest` would skip it, so the search meets the same triangles
    in the same order, with the same result."""
    i0, i1, j0, j1 = box
    lo, cell, nb, near, start, items, tmin, tmax, planes = q
    x0, x1, y0, y1 = xs[i0], xs[i1 - 1], ys[j0], ys[j1 - 1]
    r = band
    for bb in range(b, b + 2):
        for aa in range(a, a + 2):
            fx, fy, fz = foot[bb, aa, 0], foot[bb, aa, 1], foot[bb, aa, 2]
            if not math.isnan(fx):
                ex = max(abs(x0 - fx), abs(x1 - fx))
                ey = max(abs(y0 - fy), abs(y1 - fy))
                r = min(r, math.sqrt(ex * ex + ey * ey + (z - fz) ** 2))
    r = r * (1.0 + 1e-6) + 1e-9
    r2 = r * r
    n = 0
    for t in range(start[b], start[b + 1]):
        f = items[t]
        dx = max(tmin[f, 0] - x1, 0.0, x0 - tmax[f, 0])
        dy = max(tmin[f, 1] - y1, 0.0, y0 - tmax[f, 1])
        dz = max(tmin[f, 2] - z, 0.0, z - tmax[f, 2])
        if dx * dx + dy * dy + dz * dz <= r2:
            buf[n] = f
            n += 1
    return n


@njit(cache=True, nogil=True, inline="always")
def _bounds(xs, ys, z, w, band, wc, skin, node, foot, ix, iy, a, b, i, j, hyp):
    """``(inside, upper, v)`` of pixel ``(i, j)`` of node cell ``(a, b)``: its sign, an upper bound of its distance
    (the nearest of the nodes' closest surface points, at most ``band``; -1 where not needed: ``v`` is set) and
    its interpolated value where its nodes bound its distance far enough from the surface and the skin's
    (1-Lipschitz), else NaN. ``hyp[s + dj, s + di]``: the distance of pixels ``di``, ``dj`` apart."""
    s = (hyp.shape[0] - 1) // 2
    neg = node[b, a] < 0
    lower, same = 0.0, True
    for db in range(2):
        bb = b + db
        for da in range(2):
            aa = a + da
            c = node[bb, aa]
            same = same and (c < 0) == neg
            lower = max(lower, abs(c) - hyp[s + j - iy[bb], s + i - ix[aa]])
    upper = -1.0
    if same and lower >= wc and (skin <= 0 or lower >= skin + wc):
        inside = neg  # farther than ``wc`` from the surface: the nodes' sign (their winding number)
    else:
        inside = _winding(w, i, j, z) > 0
        same = same and inside == neg
        upper = _upper(xs[i], ys[j], z, band, foot, a, b)
    if same and lower >= wc and (skin <= 0 or lower >= skin + wc or upper <= skin - wc):
        ty = (j - iy[b]) / max(iy[b + 1] - iy[b], 1)
        tx = (i - ix[a]) / max(ix[a + 1] - ix[a], 1)
        return inside, upper, (1 - ty) * ((1 - tx) * node[b, a] + tx * node[b, a + 1]) + ty * (
            (1 - tx) * node[b + 1, a] + tx * node[b + 1, a + 1])
    return inside, upper, np.nan


@njit(cache=True, nogil=True, inline="always")
def _upper(x, y, z, band, foot, a, b):
    """The distance of ``(x, y, z)`` to the nearest of node cell ``(a, b)``'s nodes' closest surface points (a surface
    point: the point is no farther from the surface), at most ``band``."""
    upper = band
    for bb in range(b, b + 2):
        for aa in range(a, a + 2):
            if not math.isnan(foot[bb, aa, 0]):
                upper = min(upper, math.sqrt((x - foot[bb, aa, 0]) ** 2 + (y - foot[bb, aa, 1]) ** 2
                                             + (z - foot[bb, aa, 2]) ** 2))
    return upper
