"""Numba kernel: binary STL records straight from indexed float64 meshes.

One 50-byte record per triangle (little-endian): the unit normal and the
three corners as float32, then a zero 16-bit attribute. The normal is the
normalised cross product ``(p1 - p0) x (p2 - p0)`` of the stored (float32)
corners, computed in float64 (zero for a degenerate triangle). Records are filled block by block in one
thread: the loop is bound by memory, and a parallel kernel cost seconds to
compile on every first run (issue 22).

numba loads, and the kernels compile (or load from numba's cache), on their
first call (:class:`Kernel`): a command that writes no mesh does not import
numba through :mod:`porecad.io`.
"""

from __future__ import annotations

import math
import sys
import threading

import numpy as np

RECORD_BYTES = 50
_CHUNK = 2048
LITTLE_ENDIAN = sys.byteorder == "little"


class Kernel:
    """A numba kernel compiled on its first call: ``Kernel(function, **njit_options)(*args)``.

    ``py_func`` is the plain Python function; the compiled dispatcher is made
    once (under a lock: the STL writer calls it from several threads).
    """

    def __init__(self, function, **options):
        self.py_func = function
        self.options = options
        self.dispatcher = None
        self.lock = threading.Lock()
        self.__doc__ = function.__doc__

    def __call__(self, *args):
        if self.dispatcher is None:
            with self.lock:
                if self.dispatcher is None:
                    from numba import njit
                    self.dispatcher = njit(**self.options)(self.py_func)
        return self.dispatcher(*args)


def stl_records(vertices, faces, start, out):
    """Fill ``out`` (uint8, ``n * 50`` bytes) with the records of faces ``start .. start + n - 1``."""
    n = out.shape[0] // RECORD_BYTES
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    for ch in range(n_chunks):
        rec = np.empty(12, np.float32)
        rec_bytes = rec.view(np.uint8)
        for r in range(ch * _CHUNK, min(n, (ch + 1) * _CHUNK)):
            f = start + r
            for c in range(3):
                v = faces[f, c]
                rec[3 + 3 * c] = vertices[v, 0]
                rec[4 + 3 * c] = vertices[v, 1]
                rec[5 + 3 * c] = vertices[v, 2]
            # the normal of the triangle as stored: its float32 corners, in float64
            ax = np.float64(rec[6]) - np.float64(rec[3])
            ay = np.float64(rec[7]) - np.float64(rec[4])
            az = np.float64(rec[8]) - np.float64(rec[5])
            bx = np.float64(rec[9]) - np.float64(rec[3])
            by = np.float64(rec[10]) - np.float64(rec[4])
            bz = np.float64(rec[11]) - np.float64(rec[5])
            nx = ay * bz - az * by
            ny = az * bx - ax * bz
            nz = ax * by - ay * bx
            length = math.sqrt(nx * nx + ny * ny + nz * nz)
            if length > 0.0 and math.isfinite(length):
                rec[0] = nx / length
                rec[1] = ny / length
                rec[2] = nz / length
            else:
                rec[0] = 0.0
                rec[1] = 0.0
                rec[2] = 0.0
            o = r * RECORD_BYTES
            for b in range(48):
                out[o + b] = rec_bytes[b]
            out[o + 48] = 0
            out[o + 49] = 0


def exact_ids(bits):
    """First-occurrence ids of equal rows of ``bits`` ((N, 3) uint64 patterns) by open addressing.

    Returns ``(ids, first)``: ``ids[n]`` numbers the distinct rows in order of
    first occurrence and ``first[k]`` is the row index where id ``k`` first
    occurs (length = number of distinct rows).
    """
    n = bits.shape[0]
    size = 1
    while size < 2 * n + 16:
        size *= 2
    mask = size - 1
    table = np.full(size, -1, dtype=np.int64)
    ids = np.empty(n, dtype=np.int64)
    first = np.empty(n, dtype=np.int64)
    count = 0
    for r in range(n):
        a, b, c = bits[r, 0], bits[r, 1], bits[r, 2]
        h = (a * np.uint64(0x9E3779B97F4A7C15)) ^ (b * np.uint64(0xC2B2AE3D27D4EB4F)) \
            ^ (c * np.uint64(0x165667B19E3779F9))
        h ^= h >> np.uint64(29)
        slot = np.int64(h & np.uint64(mask))
        while True:
            t = table[slot]
            if t < 0:
                table[slot] = count
                first[count] = r
                ids[r] = count
                count += 1
                break
            q = first[t]
            if bits[q, 0] == a and bits[q, 1] == b and bits[q, 2] == c:
                ids[r] = t
                break
            slot = (slot + 1) & mask
    return ids, first[:count]


#: the kernels, compiled on first call
fill_stl_records = Kernel(stl_records, cache=True, nogil=True)
merge_exact_ids = Kernel(exact_ids, cache=True)
