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
* the sign of every pixel in it: the winding number of its z-column (the body's own column
  crossings of the whole grid, computed once), counted for the nodes and the pixels near the surface;
  the others lie farther from the surface than from their nearest node, whose sign they have;
* the exact signed distance (clamped) and closest surface point on coarse nodes, every
  :data:`NODE_STRIDE`-th pixel in x and y;
* a pixel whose nodes bound its distance (1-Lipschitz: ``|d| >= |d_node| - |p - node|``) to at least
  ``W`` = :data:`EXACT_PIXELS` pixels from the surface (and from a skin's inner surface), with the
  nodes' sign: the bilinear interpolation of the nodes' signed distances (the signed distance is
  smooth across the surface, so this is close to it); whole node cells at once where the cell's
  nearest node is far enough;
* any other pixel: the exact distance, searched only as far as the nearest of its nodes' closest
  surface points (an upper bound: a far shorter search than the band's).

The sign is exact everywhere (the layer's section is unchanged) and the distance exact within ``W``
of the surface (and of a skin's inner surface); farther pixels' values are interpolated (the grey
of a pixel depends on its value only within about a pixel of the outline). Measured on the femur
(bench/slice.md): the same layer areas as the exact route, every pixel within 3 pixels of the
surface bit-identical.
"""

from __future__ import annotations

import math

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

    @property
    def bounds(self):
        return self.body.bounds

    @property
    def band(self) -> float:
        return self.body.band

    def evaluate(self, points):
        return self.body.evaluate(points)

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_tmin", "_tmax")}

    def __setstate__(self, state):
        self.__init__(state["body"], state["skin"], state["stride"], state["exact_pixels"])

    def sample_grid(self, xs, ys, zs):
        xs, ys, zs = (np.ascontiguousarray(a, dtype=np.float64) for a in (xs, ys, zs))
        s = self.stride
        if not (_regular(xs) and _regular(ys)) or min(len(xs), len(ys)) < 2 * s + 1:
            return self.body.sample_grid(xs, ys, zs)
        b = self.body
        band = b.band
        out = np.full((len(zs), len(ys), len(xs)), band, np.float32)
        px, py = xs[1] - xs[0], ys[1] - ys[0]
        wc = self.exact_pixels * max(px, py)
        start, zc, sg = b._column_crossings(xs, ys)
        start3, items3, near = b._distance_bins()
        for k, z in enumerate(zs):
            rect = self._rect(xs, ys, float(z))
            if rect is None:
                continue
            i0, i1, j0, j1 = rect
            w = (start, zc, sg, len(xs), i0, j0)
            sub = np.empty((j1 - j0, i1 - i0), np.float32)
            _layer_distance(b.vertices, b.faces, xs[i0:i1], ys[j0:j1], float(z), w, b._lo3, b._cell3, b._nb3,
                            start3, items3, near, band, s, wc, self.skin, sub)
            out[k, j0:j1, i0:i1] = sub
        return out

    def _rect(self, xs, ys, z):
        """``(i0, i1, j0, j1)``: the pixels within ``band`` (in x and y) of the triangles within ``band`` of
        ``z``; None when there are none."""
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
        return int(i0), int(max(i1, i0 + 2)), int(j0), int(max(j1, j0 + 2))


def _regular(a) -> bool:
    if len(a) < 2:
        return False
    d = np.diff(a)
    return bool(d[0] > 0 and np.allclose(d, d[0], rtol=1e-9, atol=1e-12 * max(1.0, abs(a).max())))


@njit(cache=True, nogil=True)
def _winding(w, i, j, z):
    """The winding number at height ``z`` of pixel ``(i, j)`` of the layer's rectangle: ``w`` = (the whole grid's
    column crossings ``start, zc, sg``, its width, the rectangle's first column and row)."""
    start, zc, sg, nx, i0, j0 = w
    q = (j0 + j) * nx + i0 + i
    n = 0
    for t in range(start[q], start[q + 1]):
        if zc[t] > z:
            n += sg[t]
    return n


@njit(cache=True, nogil=True)
def _nearest(vertices, faces, x, y, z, lo, cell, nb, bin_start, bin_items, near, clamp):
    """``(d, qx, qy, qz)``: the distance (clamped) and closest surface point of a point (NaN beyond ``clamp``,
    or where its bin is farther than the body's band from the surface)."""
    bi = int(math.floor((x - lo[0]) / cell))
    bj = int(math.floor((y - lo[1]) / cell))
    bk = int(math.floor((z - lo[2]) / cell))
    if 0 <= bi < nb[0] and 0 <= bj < nb[1] and 0 <= bk < nb[2] and not near[(bk * nb[1] + bj) * nb[0] + bi]:
        return clamp, np.nan, np.nan, np.nan
    d2, qx, qy, qz = K.nearest_point(vertices, faces, x, y, z, lo, cell, nb, bin_start, bin_items, clamp)
    return math.sqrt(d2), qx, qy, qz


@njit(cache=True, parallel=True, nogil=True)
def _layer_distance(vertices, faces, xs, ys, z, w, lo, cell, nb, bin_start, bin_items, near, band, s, wc, skin, out):
    """``out[j, i]``: the signed distance of the pixels ``(xs[i], ys[j], z)`` (module doc): nodes every ``s``
    pixels exact; a pixel whose nodes bound its distance (1-Lipschitz) to at least ``wc`` from the surface and
    the skin's inner surface interpolated, the rest exact, searched only as far as the nearest of the nodes'
    closest surface points."""
    nx, ny = xs.shape[0], ys.shape[0]
    px, py = xs[1] - xs[0], ys[1] - ys[0]
    mx, my = (nx - 1) // s + 2, (ny - 1) // s + 2  # node columns 0, s, 2s, ... and the last pixel
    ix = np.empty(mx, np.int64)
    iy = np.empty(my, np.int64)
    for a in range(mx):
        ix[a] = min(a * s, nx - 1)
    for a in range(my):
        iy[a] = min(a * s, ny - 1)
    node = np.empty((my, mx), np.float64)
    foot = np.empty((my, mx, 3), np.float64)
    for b in prange(my):
        j = iy[b]
        for a in range(mx):
            i = ix[a]
            d, qx, qy, qz = _nearest(vertices, faces, xs[i], ys[j], z, lo, cell, nb, bin_start, bin_items, near, band)
            node[b, a] = -d if _winding(w, i, j, z) > 0 else d
            foot[b, a, 0], foot[b, a, 1], foot[b, a, 2] = qx, qy, qz
    rcell = 0.5 * s * math.hypot(px, py)
    for bp in prange(my - 1):
        b = int(bp)
        j1 = (b + 1) * s if b < my - 2 else ny
        for a in range(mx - 1):
            i1 = (a + 1) * s if a < mx - 2 else nx
            c00, c01, c10, c11 = node[b, a], node[b, a + 1], node[b + 1, a], node[b + 1, a + 1]
            neg = c00 < 0
            same = (c01 < 0) == neg and (c10 < 0) == neg and (c11 < 0) == neg
            lo_c = min(abs(c00), abs(c01), abs(c10), abs(c11)) - rcell
            hi_c = max(abs(c00), abs(c01), abs(c10), abs(c11)) + rcell
            if same and lo_c >= wc and (skin <= 0 or lo_c >= skin + wc or hi_c <= skin - wc):
                for j in range(b * s, j1):  # the whole cell lies away from the surface (and the skin's)
                    ty = (j - iy[b]) / max(iy[b + 1] - iy[b], 1)
                    for i in range(a * s, i1):
                        tx = (i - ix[a]) / max(ix[a + 1] - ix[a], 1)
                        out[j, i] = (1 - ty) * ((1 - tx) * c00 + tx * c01) + ty * ((1 - tx) * c10 + tx * c11)
            else:
                for j in range(b * s, j1):
                    for i in range(a * s, i1):
                        out[j, i] = _pixel(vertices, faces, xs, ys, z, w, lo, cell, nb, bin_start, bin_items, near,
                                           band, wc, skin, node, foot, ix, iy, int(a), int(b), int(i), int(j))


@njit(cache=True, nogil=True)
def _pixel(vertices, faces, xs, ys, z, w, lo, cell, nb, bin_start, bin_items, near, band, wc, skin, node, foot, ix,
           iy, a, b, i, j):
    """The signed distance of pixel ``(i, j)`` of node cell ``(a, b)`` near the surface: interpolated where its own
    bounds allow, else exact (searched as far as the nearest of the nodes' closest surface points)."""
    px, py = xs[1] - xs[0], ys[1] - ys[0]
    x, y = xs[i], ys[j]
    inside = _winding(w, i, j, z) > 0
    lower, upper, same = 0.0, band, True
    for db in range(2):
        bb = b + db
        for da in range(2):
            aa = a + da
            c = node[bb, aa]
            same = same and (c < 0) == inside
            lower = max(lower, abs(c) - math.hypot((i - ix[aa]) * px, (j - iy[bb]) * py))
            if not math.isnan(foot[bb, aa, 0]):  # a surface point: the pixel is no farther from the surface
                upper = min(upper, math.sqrt((x - foot[bb, aa, 0]) ** 2 + (y - foot[bb, aa, 1]) ** 2
                                             + (z - foot[bb, aa, 2]) ** 2))
    if same and lower >= wc and (skin <= 0 or lower >= skin + wc or upper <= skin - wc):
        ty = (j - iy[b]) / max(iy[b + 1] - iy[b], 1)
        tx = (i - ix[a]) / max(ix[a + 1] - ix[a], 1)
        return (1 - ty) * ((1 - tx) * node[b, a] + tx * node[b, a + 1]) + ty * (
            (1 - tx) * node[b + 1, a] + tx * node[b + 1, a + 1])
    clamp = upper * (1.0 + 1e-9) + 1e-12 if upper < band else band
    d = min(_nearest(vertices, faces, x, y, z, lo, cell, nb, bin_start, bin_items, near, clamp)[0], upper)
    return -d if inside else d
