"""Fields stored on a regular grid, trilinear in between.

Used for slowly varying fields that are costly per point — a body's depth
below its surface, thin-plate RBF interpolants, image maps: they are sampled
once on a coarse grid (:func:`cache_on_grid`) and interpolated on the fine
polygonisation grid. Trilinear interpolation is separable, so a tensor-grid
slab costs three 1-D passes. Outside the grid the nearest boundary value is
used (clamped indices).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .base import Field


def _axis_weights(coords, x0, h, n):
    """Left indices and weights of linear interpolation along one axis (clamped)."""
    t = (np.asarray(coords, dtype=np.float64) - x0) / h
    t = np.clip(t, 0.0, n - 1.0)
    i = np.minimum(np.floor(t).astype(np.int64), max(n - 2, 0))
    w = (t - i).astype(np.float32)
    return i, w


class GriddedField(Field):
    """Trilinear interpolation of values on a regular grid.

    Parameters
    ----------
    values : (nz, ny, nx) array
        Samples at ``origin + (i, j, k) * spacing`` stored ``[k, j, i]`` (the
        layout of :meth:`Field.sample_grid`).
    origin, spacing : (3,) float
    """

    def __init__(self, values, origin, spacing):
        v = np.ascontiguousarray(values, dtype=np.float32)
        if v.ndim != 3 or min(v.shape) < 2:
            raise InputError("a gridded field needs at least 2 samples per axis")
        self.values = v
        self.origin = np.asarray(origin, dtype=np.float64).reshape(3)
        self.spacing = np.asarray(spacing, dtype=np.float64).reshape(3)
        self.shape_xyz = (v.shape[2], v.shape[1], v.shape[0])

    def _weights(self, coords, axis):
        return _axis_weights(coords, self.origin[axis], self.spacing[axis], self.shape_xyz[axis])

    def sample_grid(self, xs, ys, zs):
        iz, wz = self._weights(zs, 2)
        k0, k1 = int(iz.min()), int(iz.max()) + 2
        sub = self.values[k0:k1]
        iz = iz - k0
        a = sub[iz] * (1 - wz)[:, None, None] + sub[iz + 1] * wz[:, None, None]  # (nzf, nyc, nxc)
        iy, wy = self._weights(ys, 1)
        b = a[:, iy] * (1 - wy)[None, :, None] + a[:, iy + 1] * wy[None, :, None]  # (nzf, nyf, nxc)
        ix, wx = self._weights(xs, 0)
        return np.ascontiguousarray(b[:, :, ix] * (1 - wx) + b[:, :, ix + 1] * wx, dtype=np.float32)

    def evaluate(self, points):
        p = np.asarray(points, dtype=np.float64)
        ix, wx = self._weights(p[:, 0], 0)
        iy, wy = self._weights(p[:, 1], 1)
        iz, wz = self._weights(p[:, 2], 2)
        v = self.values
        out = np.zeros(len(p), dtype=np.float64)
        for dz, fz in ((0, 1 - wz), (1, wz)):
            for dy, fy in ((0, 1 - wy), (1, wy)):
                for dx, fx in ((0, 1 - wx), (1, wx)):
                    out += v[iz + dz, iy + dy, ix + dx] * (fz * fy * fx)
        return out


def coarse_axes(box_min, box_max, spacing: float, max_samples: int = 4_000_000):
    """Axes of a grid covering the box at about ``spacing`` (coarsened to at most ``max_samples``)."""
    lo = np.asarray(box_min, dtype=float)
    hi = np.asarray(box_max, dtype=float)
    h = float(spacing)
    ext = np.maximum(hi - lo, 1e-9)
    while np.prod(np.ceil(ext / h) + 1) > max_samples:
        h *= 1.25
    n = np.maximum(np.ceil(ext / h).astype(np.int64), 1) + 1
    return [np.linspace(lo[a], hi[a], int(n[a])) for a in range(3)]


def cache_on_grid(field: Field, box_min, box_max, spacing: float, max_samples: int = 4_000_000):
    """Sample ``field`` on a coarse grid over the box; return the :class:`GriddedField`."""
    xs, ys, zs = coarse_axes(box_min, box_max, spacing, max_samples)
    vals = field.sample_grid(xs, ys, zs)
    h = [(ax[-1] - ax[0]) / (len(ax) - 1) for ax in (xs, ys, zs)]
    return GriddedField(vals, (xs[0], ys[0], zs[0]), h)
