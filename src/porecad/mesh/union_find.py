"""Union-find over ids that arrive in batches: pieces seen a slab at a time, joined across the seams.

Used by the streamed check of a mesh (:mod:`porecad.mesh.stream_check`) and by the banded printability
checks (:mod:`porecad.printing.banded`): each slab's pieces take new ids (:meth:`Forest.grow`), pieces
that touch across a seam are joined (:meth:`Forest.join`, vectorised over pairs), and at the end every id
maps to its piece's root (:meth:`Forest.roots`).
"""

from __future__ import annotations

import numpy as np


class Forest:
    """Ids ``0 .. len - 1``, each in one tree; the smallest id of a tree is its root."""

    def __init__(self):
        self.parent = np.zeros(0, np.int64)

    def __len__(self) -> int:
        return len(self.parent)

    def grow(self, n: int) -> int:
        """Add ``n`` ids, each its own tree; returns the first."""
        base = len(self.parent)
        self.parent = np.concatenate([self.parent, base + np.arange(int(n), dtype=np.int64)])
        return base

    def root(self, x) -> np.ndarray:
        """The roots of ids ``x`` (halving the paths on the way)."""
        x = np.asarray(x, np.int64)
        while True:
            p = self.parent[x]
            if np.array_equal(p, x):
                return x
            self.parent[x] = self.parent[p]
            x = p

    def join(self, a, b) -> None:
        """Join the trees of ids ``a[i]`` and ``b[i]``."""
        a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
        while len(a):
            ra, rb = self.root(a), self.root(b)
            differ = ra != rb
            if not differ.any():
                return
            self.parent[np.maximum(ra, rb)[differ]] = np.minimum(ra, rb)[differ]
            a, b = a[differ], b[differ]

    def roots(self) -> np.ndarray:
        """The root of every id."""
        return self.root(np.arange(len(self.parent)))
