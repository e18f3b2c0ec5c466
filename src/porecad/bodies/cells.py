"""Complete cells: the lattice cells whose whole extent lies inside a body.

Documents 001 and 002 (Fig. 1) ask for scaffolds without cut boundary cells.
:func:`complete_cells` keeps a cell of the TPMS lattice (cells of size ``L``
from ``origin``) when every grid sample in its closed box lies at least
``margin`` inside the body (so the surface, which is within one sample
diagonal of some sample wherever it crosses, cannot cut the box).
:class:`CellUnion` is the field of the union of the kept boxes: in a kept cell
minus the distance to its nearest face shared with a dropped cell, in a
dropped cell plus the distance to its nearest face shared with a kept cell, so
its zero set lies exactly on the shared cell faces.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..fields.base import Field


@njit(cache=True)
def _mark_bad(sdf, xs, ys, zs, origin, L, c_lo, margin, bad):
    nk, nj, ni = sdf.shape
    ncx, ncy, ncz = bad.shape[2], bad.shape[1], bad.shape[0]
    eps = 1e-9
    for k in range(nk):
        uz = (zs[k] - origin[2]) / L[2]
        kz0 = int(math.floor(uz + eps)) - c_lo[2]
        kz1 = kz0 - 1 if abs(uz - round(uz)) < eps else kz0
        for j in range(nj):
            uy = (ys[j] - origin[1]) / L[1]
            jy0 = int(math.floor(uy + eps)) - c_lo[1]
            jy1 = jy0 - 1 if abs(uy - round(uy)) < eps else jy0
            for i in range(ni):
                if sdf[k, j, i] <= -margin:
                    continue
                ux = (xs[i] - origin[0]) / L[0]
                ix0 = int(math.floor(ux + eps)) - c_lo[0]
                ix1 = ix0 - 1 if abs(ux - round(ux)) < eps else ix0
                for cz in range(kz1, kz0 + 1):
                    if cz < 0 or cz >= ncz:
                        continue
                    for cy in range(jy1, jy0 + 1):
                        if cy < 0 or cy >= ncy:
                            continue
                        for cx in range(ix1, ix0 + 1):
                            if 0 <= cx < ncx:
                                bad[cz, cy, cx] = True


def complete_cells(body_sample, grid, origin, cell_size, margin, progress=None):
    """Kept-cell mask of the lattice over the grid box.

    Parameters
    ----------
    body_sample : callable
        ``body_sample(xs, ys, zs)`` -> signed distance (negative inside), e.g.
        ``MeshBody.sample_grid``.
    grid : porecad.mesh.Grid
    origin, cell_size : (3,) float
        Lattice origin and cell edge lengths (mm).
    margin : float
        Required depth of every sample of a kept cell (one sample diagonal).

    Returns
    -------
    kept : (ncz, ncy, ncx) bool
    c_lo : (3,) int
        Lattice index of ``kept[0, 0, 0]`` (x, y, z).
    """
    origin = np.asarray(origin, dtype=np.float64)
    L = np.asarray(cell_size, dtype=np.float64)
    lo, hi = grid.box_min, grid.box_max
    c_lo = np.ceil((lo - origin) / L - 1e-9).astype(np.int64)      # first cell starting inside the box
    c_hi = np.floor((hi - origin) / L + 1e-9).astype(np.int64)     # one past the last cell ending inside
    n = np.maximum(c_hi - c_lo, 0)
    bad = np.zeros((n[2], n[1], n[0]), dtype=np.bool_)
    if n.min() == 0:
        return bad, c_lo
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    step = max(1, int((16 << 20) // (4 * len(xs) * len(ys))))
    n_slabs = (len(zs) + step - 1) // step
    for s, a in enumerate(range(0, len(zs), step)):
        z = zs[a:a + step]
        sdf = np.asarray(body_sample(xs, ys, z), dtype=np.float32)
        _mark_bad(sdf, xs, ys, z, origin, L, c_lo, float(margin), bad)
        if progress is not None:
            progress(s + 1, n_slabs)
    return ~bad, c_lo


@njit(cache=True, parallel=True, nogil=True)
def _cell_union_grid(xs, ys, zs, origin, L, kept, c_lo, out):
    nk, nj, ni = zs.shape[0], ys.shape[0], xs.shape[0]
    half = 0.5 * min(L[0], min(L[1], L[2]))
    for kj in prange(nk * nj):
        k = kj // nj
        j = kj - k * nj
        uz = (zs[k] - origin[2]) / L[2]
        uy = (ys[j] - origin[1]) / L[1]
        cz = int(math.floor(uz))
        cy = int(math.floor(uy))
        fz = uz - cz
        fy = uy - cy
        cz -= c_lo[2]
        cy -= c_lo[1]
        for i in range(ni):
            ux = (xs[i] - origin[0]) / L[0]
            cx = int(math.floor(ux))
            fx = ux - cx
            cx -= c_lo[0]
            inside = _kept(kept, cx, cy, cz)
            best = half
            if _kept(kept, cx - 1, cy, cz) != inside:
                best = min(best, fx * L[0])
            if _kept(kept, cx + 1, cy, cz) != inside:
                best = min(best, (1.0 - fx) * L[0])
            if _kept(kept, cx, cy - 1, cz) != inside:
                best = min(best, fy * L[1])
            if _kept(kept, cx, cy + 1, cz) != inside:
                best = min(best, (1.0 - fy) * L[1])
            if _kept(kept, cx, cy, cz - 1) != inside:
                best = min(best, fz * L[2])
            if _kept(kept, cx, cy, cz + 1) != inside:
                best = min(best, (1.0 - fz) * L[2])
            out[k, j, i] = -best if inside else best


@njit(cache=True, inline="always")
def _kept(kept, cx, cy, cz):
    if cx < 0 or cy < 0 or cz < 0 or cz >= kept.shape[0] or cy >= kept.shape[1] or cx >= kept.shape[2]:
        return False
    return kept[cz, cy, cx]


class CellUnion(Field):
    """Signed distance-like field of the union of the kept lattice cells (negative inside)."""

    def __init__(self, kept, c_lo, origin, cell_size):
        self.kept = np.ascontiguousarray(kept, dtype=np.bool_)
        self.c_lo = np.asarray(c_lo, dtype=np.int64)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.L = np.broadcast_to(np.asarray(cell_size, dtype=np.float64), (3,)).copy()

    @property
    def n_cells(self) -> int:
        return int(self.kept.sum())

    def evaluate(self, points):
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.empty((len(p), 1, 1), np.float32)
        for q in range(len(p)):  # small inputs only (tests, probes)
            _cell_union_grid(p[q:q + 1, 0].copy(), p[q:q + 1, 1].copy(), p[q:q + 1, 2].copy(), self.origin,
                             self.L, self.kept, self.c_lo, out[q:q + 1])
        return out.ravel().astype(np.float64)

    def sample_grid(self, xs, ys, zs):
        out = np.empty((len(zs), len(ys), len(xs)), np.float32)
        _cell_union_grid(np.asarray(xs, np.float64), np.asarray(ys, np.float64), np.asarray(zs, np.float64),
                         self.origin, self.L, self.kept, self.c_lo, out)
        return out
