"""Items (triangles, tets) binned by their bounding boxes into a uniform grid: one kernel for every index.

:func:`bin_boxes` is the counting sort every spatial index of porecad uses
(the body's ray and distance queries, the nearest-surface index, tet point
location): item ``n`` lies in every bin its box ``[lo[n], hi[n]]`` touches;
bin ``(i, j, k)`` is ``(k * nb[1] + j) * nb[0] + i`` (x fastest), and
coordinates outside the grid are clamped to its edge bins.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["bin_boxes", "bin_index"]


@njit(cache=True, inline="always")
def _range(lo, hi, n, origin, cell, nb, rng):
    for a in range(3):
        rng[2 * a] = min(max(int(math.floor((lo[n, a] - origin[a]) / cell)), 0), nb[a] - 1)
        rng[2 * a + 1] = min(max(int(math.floor((hi[n, a] - origin[a]) / cell)), 0), nb[a] - 1)


@njit(cache=True)
def bin_boxes(lo, hi, origin, cell, nb):
    """CSR ``(start (B + 1,), items)`` of the items per bin; ``lo``, ``hi`` (N, 3) boxes, bins of edge ``cell``."""
    total = nb[0] * nb[1] * nb[2]
    start = np.zeros(total + 1, np.int64)
    rng = np.empty(6, np.int64)
    for n in range(lo.shape[0]):
        _range(lo, hi, n, origin, cell, nb, rng)
        for k in range(rng[4], rng[5] + 1):
            for j in range(rng[2], rng[3] + 1):
                for i in range(rng[0], rng[1] + 1):
                    start[(k * nb[1] + j) * nb[0] + i + 1] += 1
    for b in range(total):
        start[b + 1] += start[b]
    pos = start[:-1].copy()
    items = np.empty(start[-1], np.int32)
    for n in range(lo.shape[0]):
        _range(lo, hi, n, origin, cell, nb, rng)
        for k in range(rng[4], rng[5] + 1):
            for j in range(rng[2], rng[3] + 1):
                for i in range(rng[0], rng[1] + 1):
                    b = (k * nb[1] + j) * nb[0] + i
                    items[pos[b]] = n
                    pos[b] += 1
    return start, items


@njit(cache=True, inline="always")
def bin_index(i, j, k, nb):
    """The bin of grid cell ``(i, j, k)`` (the order :func:`bin_boxes` uses)."""
    return (k * nb[1] + j) * nb[0] + i
