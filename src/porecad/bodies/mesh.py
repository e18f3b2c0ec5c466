"""A closed triangle mesh as a body field: signed distance, negative inside.

:class:`MeshBody` answers inside/outside by the winding number along rays
(z-rays for grids; for scattered points, rays along the body's shortest
extent, which cross the fewest sheets) — robust to self-intersections and
nested shells, see
:mod:`porecad.bodies.distance_kernels`) and the distance to the surface exactly up to
a clamp distance ``band`` (farther samples get ``±band``). Grid sampling works
slab by slab like every field: the ray crossings of the grid's (x, y) columns
are computed once per grid (a few per column), so a slab costs one pass over
its samples plus exact distances for the samples near the surface.
"""

from __future__ import annotations

import threading

import numpy as np

from ..errors import InputError
from ..fields.base import Field
from ..mesh.validate import signed_volume
from . import distance_kernels as K

#: every how many lattice lines :meth:`MeshBody.evaluate_lattice` evaluates first, and how much wider its band is there
LATTICE_STRIDE = 4
LATTICE_WIDEN = 3.0
#: most 3D distance bins of a body (their CSR starts: 32 MB)
DISTANCE_BINS = 1 << 22

#: axis orders that make axis 0 or 1 the last (rays along it): cyclic, so the mesh keeps its orientation
RAY_ORDER = {0: [1, 2, 0], 1: [2, 0, 1]}


def _column_bins(v, f):
    """``(vertices, start, items, x0, y0, cell, nx, ny)``: the triangles of ``(v, f)`` binned by their xy
    footprint (CSR), about 4 triangles' footprint per square bin of edge ``cell``, for rays along z."""
    v = np.ascontiguousarray(v)
    lo, ext = v.min(axis=0), np.ptp(v, axis=0)
    area_xy = max(ext[0] * ext[1], 1e-300)
    cell = float(max(np.sqrt(4.0 * area_xy / len(f)), 1e-9 * max(ext.max(), 1.0)))
    x0, y0 = lo[0] - cell, lo[1] - cell
    nx = int(np.ceil((ext[0] + 2 * cell) / cell)) + 1
    ny = int(np.ceil((ext[1] + 2 * cell) / cell)) + 1
    start, items = K.bin_triangles_xy(v, f, x0, y0, cell, nx, ny)
    return v, start, items, x0, y0, cell, nx, ny


class MeshBody(Field):
    """Signed distance to a closed, outward-oriented triangle mesh, clamped to ``±band``.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        A closed, consistently oriented mesh (see :func:`porecad.bodies.load_body`).
    band : float
        Distances are exact up to ``band`` (mm) and clamped beyond it. Use at
        least two sample spacings, plus any skin thickness.
    """

    def __init__(self, vertices, faces, band: float):
        v = np.ascontiguousarray(vertices, dtype=np.float64)
        f = np.ascontiguousarray(faces, dtype=np.int64)
        if len(f) == 0:
            raise InputError("the body mesh has no faces")
        if not np.isfinite(band) or band <= 0:
            raise InputError(f"distance band must be positive, got {band}")
        self.vertices, self.faces, self.band = v, f, float(band)
        self.lo = v.min(axis=0)
        self.hi = v.max(axis=0)
        ext = self.hi - self.lo
        self._rays = {}          # column bins of rays along each axis (z: grids, column by column), built on first use
        self._rays_lock = threading.Lock()
        # 3D bins around the mesh with a band of margin on every side, of edge down to band / 4 where that makes
        # at most DISTANCE_BINS bins (a query then searches the small bins near it, nearest first, not 27 of edge
        # band)
        self._lo3 = self.lo - self.band
        if np.prod(np.ceil((ext + 2 * self.band) / self.band) + 1) > 5e8:
            raise InputError(f"distance band {band:g} mm is too small for a body of extent "
                             f"{ext.max():g} mm")
        # (no smaller than the triangles' edges: a triangle across many bins is tested from each of them)
        edge = float(np.linalg.norm(v[f[:100_000, 0]] - v[f[:100_000, 1]], axis=1).mean())
        self._cell3 = next(c for c in (self.band / s for s in (4, 3, 2, 1)) if c == self.band or (
            c >= edge and np.prod(np.ceil((ext + 2 * self.band) / c) + 1) <= DISTANCE_BINS))
        self._nb3 = (np.ceil((ext + 2 * self.band) / self._cell3).astype(np.int64) + 1)
        self._bins3 = None       # built on the first distance query (inside/outside needs only the xy bins)
        self._bins3_lock = threading.Lock()
        self._columns = None
        self._lock = threading.Lock()

    _LOCKS = ("_rays_lock", "_bins3_lock", "_lock")

    def __getstate__(self):
        """Pickled for a dask worker (a streamed infill on ``local:N``): the mesh and the bins built so far,
        without the locks, which the worker makes anew."""
        return {k: v for k, v in self.__dict__.items() if k not in self._LOCKS}

    def __setstate__(self, state):
        self.__dict__.update(state)
        for k in self._LOCKS:
            setattr(self, k, threading.Lock())

    def _distance_bins(self):
        """``(start, items, near)``: the 3D bins of edge ``_cell3`` (CSR) and the bins within ``band`` of a
        triangle, built once."""
        with self._bins3_lock:
            if self._bins3 is None:
                start, items = K.bin_triangles_near(self.vertices, self.faces, self._lo3, self._cell3, self._nb3)
                r = int(np.ceil(self.band / self._cell3 * (1.0 - 1e-12)))
                self._bins3 = (start, items, K.dilate_bins(start, self._nb3, r))
            return self._bins3

    @property
    def _xyz_start(self):
        return self._distance_bins()[0]

    @property
    def _xyz_items(self):
        return self._distance_bins()[1]

    @property
    def _near(self):
        return self._distance_bins()[2]

    # ------------------------------------------------------------------ info
    @property
    def bounds(self):
        return self.lo.copy(), self.hi.copy()

    @property
    def volume(self) -> float:
        return float(signed_volume(self.vertices, self.faces))

    # ------------------------------------------------------------------ queries
    def winding(self, points) -> np.ndarray:
        """Winding number of each point (1 inside, 0 outside a simple closed mesh).

        Counted along rays parallel to the body's shortest extent (z unless
        another is shorter by a fifth): a ray through a long bone's lattice
        along its length crosses hundreds of walls, across it a few dozen.
        """
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        ext = self.hi - self.lo
        axis = int(np.argmin(ext))
        if ext[axis] > 0.8 * ext[2]:
            axis = 2
        bins = self._ray_bins(axis)
        if axis != 2:
            p = p[:, RAY_ORDER[axis]]
        start, zs, sg = K.column_crossings(bins[0], self.faces, p[:, 0].copy(), p[:, 1].copy(), *bins[1:])
        return K.winding_at_points(start, zs, sg, p[:, 2].copy())

    def _ray_bins(self, axis: int):
        """:func:`_column_bins` of rays along ``axis`` (the vertices in :data:`RAY_ORDER` for x and y)."""
        with self._rays_lock:
            if axis not in self._rays:
                v = self.vertices if axis == 2 else self.vertices[:, RAY_ORDER[axis]]
                self._rays[axis] = _column_bins(v, self.faces)
            return self._rays[axis]

    # the z-ray bins by name, for the grid fills here and in porecad.volmesh
    _xy_start = property(lambda self: self._ray_bins(2)[1])
    _xy_items = property(lambda self: self._ray_bins(2)[2])
    _x0 = property(lambda self: self._ray_bins(2)[3])
    _y0 = property(lambda self: self._ray_bins(2)[4])
    _cell_xy = property(lambda self: self._ray_bins(2)[5])
    _nbx = property(lambda self: self._ray_bins(2)[6])
    _nby = property(lambda self: self._ray_bins(2)[7])

    def contains(self, points) -> np.ndarray:
        return self.winding(points) > 0

    def distance(self, points) -> np.ndarray:
        """Unsigned distance of each point to the surface, clamped at :attr:`band`."""
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        return K.clamped_distance_points(self.vertices, self.faces, p, self._lo3, self._cell3, self._nb3,
                                         self._xyz_start, self._xyz_items, self._near, self.band)

    def evaluate(self, points):
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        d = self.distance(p)
        return np.where(self.winding(p) > 0, -d, d)

    def _wide(self):
        """This body with a band :data:`LATTICE_WIDEN` times as wide (the coarse nodes of :meth:`evaluate_lattice`)."""
        with self._lock:
            if getattr(self, "_wide_body", None) is None:
                self._wide_body = MeshBody(self.vertices, self.faces, band=LATTICE_WIDEN * self.band)
            return self._wide_body

    def evaluate_lattice(self, points, stride: int = LATTICE_STRIDE):
        """:meth:`evaluate` at a curvilinear lattice of points ``(n1, n2, n3, 3)`` (a mapped grid), the same values.

        Most samples of a mapped grid lie farther than ``band`` from the
        surface, where the value is ``±band`` and only its sign is needed,
        and the winding number of a scattered point (its own ray) is the
        dear part of :meth:`evaluate` (5 µs a point against 1.7 µs for the
        distance). So the nodes of every ``stride``-th lattice line are
        evaluated first with a band :data:`LATTICE_WIDEN` times as wide;
        the signed distance is 1-Lipschitz, so a sample ``r`` from its
        nearest node ``d_c`` has ``|d| >= |d_c| - r``: where that is at least
        ``band`` the sample is ``±band`` with the node's sign, where it is
        positive the sign is the node's and only the distance is computed,
        and only the rest (within ``r`` of the surface) is evaluated in full.
        Exact, not an approximation: the values equal :meth:`evaluate`'s.
        """
        P = np.ascontiguousarray(points, dtype=np.float64)
        if P.ndim != 4 or P.shape[3] != 3:
            raise InputError(f"evaluate_lattice needs an (n1, n2, n3, 3) array, got shape {P.shape}")
        m = int(stride)
        shape = P.shape[:3]
        if m < 2 or min(shape) < 2 * m:
            return self.evaluate(P.reshape(-1, 3)).reshape(shape)
        # the nearest node of every sample along each axis: a multiple of m, or the last index
        near_idx = []
        for n in shape:
            nodes = np.unique(np.append(np.arange(0, n, m), n - 1))
            i = np.arange(n)
            pos = np.clip(np.searchsorted(nodes, i), 1, len(nodes) - 1)
            left, right = nodes[pos - 1], nodes[pos]
            near_idx.append((nodes, np.where(i - left <= right - i, left, right)))
        (n0, i0), (n1, i1), (n2, i2) = near_idx
        dc_nodes = self._wide().evaluate(P[np.ix_(n0, n1, n2)].reshape(-1, 3)).reshape(len(n0), len(n1), len(n2))
        # the nodes' values spread to their samples (node index -> position in the node arrays)
        r0, r1, r2 = (np.searchsorted(nodes, idx) for nodes, idx in near_idx)
        dc = dc_nodes[np.ix_(r0, r1, r2)]
        r = np.linalg.norm(P - P[np.ix_(i0, i1, i2)], axis=-1)
        margin = np.abs(dc) - r
        out = np.where(dc < 0, -self.band, self.band)
        signed = margin > 0                       # the sign is the node's
        need_d = signed & (margin < self.band)    # ... and the distance may be under the band
        full = ~signed
        if need_d.any():
            q = np.ascontiguousarray(P[need_d])
            d = K.clamped_distance_points(self.vertices, self.faces, q, self._lo3, self._cell3, self._nb3,
                                          self._xyz_start, self._xyz_items, self._near, self.band)
            out[need_d] = np.where(dc[need_d] < 0, -d, d)
        if full.any():
            out[full] = self.evaluate(P[full])
        return out

    def _column_crossings(self, xs, ys):
        key = (len(xs), float(xs[0]), float(xs[-1]), len(ys), float(ys[0]), float(ys[-1]))
        with self._lock:
            if self._columns is None or self._columns[0] != key:
                px = np.tile(xs, len(ys))
                py = np.repeat(ys, len(xs))
                crossings = K.column_crossings(self.vertices, self.faces, px, py, self._xy_start,
                                               self._xy_items, self._x0, self._y0, self._cell_xy,
                                               self._nbx, self._nby)
                self._columns = (key, crossings)
            return self._columns[1]

    def inside_grid(self, xs, ys, zs) -> np.ndarray:
        """Inside flags (winding number > 0) on the tensor grid, ``(len(zs), len(ys), len(xs))`` bool.

        No distances are computed: the cheap half of :meth:`sample_grid`.
        """
        xs, ys, zs, w = self._winding_grid(xs, ys, zs)
        return (w > 0).reshape(len(zs), len(ys), len(xs))

    def _winding_grid(self, xs, ys, zs):
        """The axes as contiguous float64 and the winding numbers ``(len(zs), len(xs) * len(ys))`` int32."""
        xs = np.ascontiguousarray(xs, dtype=np.float64)
        ys = np.ascontiguousarray(ys, dtype=np.float64)
        zs = np.ascontiguousarray(zs, dtype=np.float64)
        start, zc, sg = self._column_crossings(xs, ys)
        w = np.empty((len(zs), len(xs) * len(ys)), np.int32)
        K.winding_on_columns(start, zc, sg, zs, w)
        return xs, ys, zs, w

    def sample_grid(self, xs, ys, zs):
        xs, ys, zs, w = self._winding_grid(xs, ys, zs)
        out = np.empty((len(zs), len(ys), len(xs)), np.float32)
        K.signed_distance_grid(self.vertices, self.faces, xs, ys, zs, w, self._lo3, self._cell3, self._nb3,
                               self._xyz_start, self._xyz_items, self._near, self.band, out)
        return out
