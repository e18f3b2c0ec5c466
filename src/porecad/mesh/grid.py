"""Regular sampling grids: sample ``(i, j, k)`` at ``origin + (i, j, k) * spacing``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, ResourceError


@dataclass(frozen=True)
class Grid:
    """A regular sampling grid: sample ``(i, j, k)`` lies at ``origin + (i, j, k) * spacing``.

    Attributes
    ----------
    origin : (3,) float
    spacing : (3,) float
    shape : (nx, ny, nz) int
    """

    origin: tuple
    spacing: tuple
    shape: tuple

    @classmethod
    def from_box(cls, box_min, box_max, samples_per_axis=None, spacing=None):
        """Grid whose first and last samples lie on the box faces.

        Give either the number of samples per axis (``(nx, ny, nz)`` or one
        int) or an approximate spacing (adjusted so the box is spanned exactly).
        """
        lo = np.asarray(box_min, dtype=float)
        hi = np.asarray(box_max, dtype=float)
        if lo.shape != (3,) or hi.shape != (3,) or np.any(hi <= lo):
            raise InputError("grid box must have max > min on every axis")
        if samples_per_axis is not None:
            n = np.broadcast_to(np.asarray(samples_per_axis, dtype=np.int64), (3,))
        elif spacing is not None:
            h = np.broadcast_to(np.asarray(spacing, dtype=float), (3,))
            if np.any(h <= 0):
                raise InputError("grid spacing must be positive")
            with np.errstate(over="ignore"):
                counts = np.maximum(np.ceil((hi - lo) / h), 1) + 1
            if not np.prod(counts) < 2.0 ** 62:  # inf or past int64: the cast would make a 2-sample grid
                raise ResourceError(f"a grid spacing of {float(np.min(h)):g} mm over {float(np.max(hi - lo)):g} mm "
                                    f"is {np.prod(counts):.3g} samples: use a larger spacing (voxel)")
            n = counts.astype(np.int64)
        else:
            raise InputError("give samples_per_axis or spacing")
        if np.any(n < 2):
            raise InputError("a grid needs at least 2 samples per axis")
        h = (hi - lo) / (n - 1)
        return cls(tuple(lo.tolist()), tuple(h.tolist()), tuple(int(v) for v in n))

    @property
    def box_min(self):
        return np.asarray(self.origin, dtype=float)

    @property
    def box_max(self):
        return self.box_min + np.asarray(self.spacing) * (np.asarray(self.shape) - 1)

    @property
    def n_samples(self) -> int:
        return int(np.prod(np.asarray(self.shape, dtype=np.int64)))

    def axis(self, a: int) -> np.ndarray:
        """Sample coordinates along axis ``a`` (computed as ``origin + i * h``)."""
        return self.origin[a] + np.arange(self.shape[a], dtype=np.float64) * self.spacing[a]
