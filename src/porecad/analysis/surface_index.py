"""Exact distances from points to a triangle mesh, for the analysis (closest points, not voxel counts).

:class:`SurfaceIndex` bins the triangles that meet a region of interest into
a uniform grid of cubic cells and answers, for query points with an upper
bound on their distance (a surface point known to be that close, or a search
radius), the exact distance and closest point on the mesh
(:mod:`porecad.analysis._nearest_kernel`). The region is what keeps a large
mesh cheap: an analysis block indexes only the triangles near itself.
"""

from __future__ import annotations

import numpy as np

from ..errors import ResourceError

#: most cells one index may hold (the CSR start array is 8 bytes a cell)
MAX_CELLS = 40_000_000


def face_boxes(vertices, faces):
    """Bounding boxes ``(lo, hi)`` (float32, ``(F, 3)`` each, rounded outwards) of the triangles."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    lo = np.minimum(np.minimum(a, b), c).astype(np.float32)
    hi = np.maximum(np.maximum(a, b), c).astype(np.float32)
    return np.nextafter(lo, np.float32(-np.inf)), np.nextafter(hi, np.float32(np.inf))


class SurfaceIndex:
    """Triangles of a mesh binned over a box, for exact nearest-point queries.

    Parameters
    ----------
    vertices, faces : arrays
        The mesh (any triangle soup; orientation does not matter here).
    cell : float
        Cell edge (mm). Queries cost about the number of cells their bound
        spans plus the triangles in the cells that meet the bound's sphere,
        so a cell of one to a few voxels suits both short and long queries.
    lo, hi : (3,) arrays, optional
        The region indexed (default: the mesh's bounds). Triangles outside it
        are dropped, so a query must lie inside ``[lo + ub, hi - ub]`` to be
        exact.
    boxes : (lo, hi), optional
        :func:`face_boxes` of the mesh, when several indices of one mesh are made.
    """

    def __init__(self, vertices, faces, cell: float, lo=None, hi=None, boxes=None):
        from ..bodies.distance_kernels import bin_triangles_xyz

        v = np.ascontiguousarray(vertices, dtype=np.float64)
        f = np.ascontiguousarray(faces, dtype=np.int64)
        lo = v.min(axis=0) if lo is None else np.asarray(lo, dtype=np.float64)
        hi = v.max(axis=0) if hi is None else np.asarray(hi, dtype=np.float64)
        tmin, tmax = face_boxes(v, f) if boxes is None else boxes
        if len(f):
            keep = np.all((tmax >= lo) & (tmin <= hi), axis=1)
            f = np.ascontiguousarray(f[keep])
            tmin, tmax = tmin[keep], tmax[keep]
        # the boxes (float32, rounded outwards) reject far triangles before the exact test
        self.box_lo, self.box_hi = np.ascontiguousarray(tmin), np.ascontiguousarray(tmax)
        ext = np.maximum(hi - lo, 1e-9)
        cell = float(cell)
        while float(np.prod(np.ceil(ext / cell) + 1)) > MAX_CELLS:
            cell *= 1.26
        self.vertices, self.faces, self.cell = v, f, cell
        self.lo = np.ascontiguousarray(lo, dtype=np.float64)
        self.nb = (np.ceil(ext / cell).astype(np.int64) + 1)
        if float(np.prod(self.nb.astype(float))) > MAX_CELLS:  # pragma: no cover - guarded by the loop
            raise ResourceError("surface index too large")
        self.start, self.items = bin_triangles_xyz(v, f, self.lo, cell, self.nb)

    @property
    def n_faces(self) -> int:
        return int(len(self.faces))

    def nearest(self, points, upper, with_triangles: bool = False):
        """Exact ``(distance, closest point)`` of each point, among triangles within ``upper`` (mm).

        ``upper`` is a number or one bound per point; where no indexed
        triangle lies within it the distance is ``upper`` and the closest
        point NaN. With ``with_triangles`` also the index of the closest
        triangle in :attr:`faces` (-1 where none).
        """
        from ..kernel_threads import run_interleaved, thread_count
        from ._nearest_kernel import nearest

        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        n = len(p)
        ub = np.empty(n)           # writable and contiguous: one compiled kernel for every caller
        ub[:] = np.asarray(upper, dtype=np.float64)
        if not (n and len(self.faces)):
            return _none_found(ub, with_triangles)
        t = max(1, min(thread_count(), n // 64))
        order = _runs_in_blocks(n, t)
        if order is not None:       # each thread's run takes blocks of neighbouring points
            p, ub = p[order], ub[order]
        dist = np.empty(n)
        closest = np.empty((n, 3))
        tri = np.empty(n, dtype=np.int64)
        run_interleaved(nearest, n, self.vertices, self.faces, self.box_lo, self.box_hi, p, ub, self.lo,
                        float(self.cell), self.nb, self.start, self.items, dist, closest, tri, threads=t,
                        min_per_thread=1)
        if order is not None:
            back = np.empty_like(order)
            back[order] = np.arange(n)
            dist, closest, tri = dist[back], closest[back], tri[back]
        return (dist, closest, tri) if with_triangles else (dist, closest)


def _none_found(ub, with_triangles):
    """:meth:`SurfaceIndex.nearest`'s answer where no triangle is indexed (or no point asked)."""
    dist = ub.copy()
    closest = np.full((len(ub), 3), np.nan)
    tri = np.full(len(ub), -1, dtype=np.int64)
    return (dist, closest, tri) if with_triangles else (dist, closest)


def _runs_in_blocks(n: int, t: int, per_run: int = 4):
    """The order that gives each of ``t`` interleaved runs (items ``r, r + t, ...``) ``per_run`` blocks
    of neighbouring points: ``order[q]`` is the point handled as item ``q`` (None for one run).

    Callers list their points in raster order, so a block is a compact region: its run revisits the
    same cells and triangles (cache), where interleaved points would make every run walk the whole
    region (about 20 % more CPU time on 2 threads). Blocks dealt round-robin keep the runs' work
    about even where one part of the region costs more than another.
    """
    if t <= 1:
        return None
    blocks = np.array_split(np.arange(n, dtype=np.int64), t * per_run)
    dealt = np.concatenate([blocks[b] for r in range(t) for b in range(r, t * per_run, t)])
    sizes = [(n - r + t - 1) // t for r in range(t)]     # items of run r
    q = np.concatenate([r + t * np.arange(m, dtype=np.int64) for r, m in enumerate(sizes)])
    order = np.empty(n, dtype=np.int64)
    order[q] = dealt
    return order
