"""Small tet meshes for tests and demonstrations (the domains of 000 Figs. 4.10-4.13, 5.6).

Every function returns ``(points, tets)``: ``(V, 3)`` float64 and ``(T, 4)``
int64, positively oriented (see :mod:`porecad.volmesh.tetmesh`), conforming,
and accepted by :func:`~porecad.volmesh.tetmesh.check_tet_mesh`.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from porecad.errors import InputError

__all__ = ["regular_tetrahedron", "two_tetrahedra", "icosahedron_tets", "cube_tets"]


def _positive(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Swap columns 2 and 3 of the negatively oriented tets."""
    q = points[tets]
    det = np.einsum("ij,ij->i", q[:, 1] - q[:, 0], np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]))
    t = tets.copy()
    t[det < 0] = t[det < 0][:, [0, 1, 3, 2]]
    return np.ascontiguousarray(t, dtype=np.int64)


def positive_size(value: float, name: str) -> float:
    """``value`` as a float; InputError naming ``name`` unless it is a finite positive length (mm)."""
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be a positive number of mm, got {value}")
    return value


def regular_tetrahedron(edge: float = 1.0):
    """One regular tetrahedron of edge ``a``, volume ``a³ / (6 √2)``.

    Vertices ``(0, 0, 0)``, ``(a, 0, 0)``, ``(a/2, a√3/2, 0)`` and the apex
    ``(a/2, a√3/6, a√(2/3))`` above the base's centroid.

    Returns
    -------
    points : (4, 3) float64
    tets : (1, 4) int64
    """
    a = positive_size(edge, "edge")
    p = np.array([[0.0, 0.0, 0.0],
                  [a, 0.0, 0.0],
                  [a / 2, a * math.sqrt(3) / 2, 0.0],
                  [a / 2, a * math.sqrt(3) / 6, a * math.sqrt(2.0 / 3.0)]])
    return p, _positive(p, np.array([[0, 1, 2, 3]]))


def two_tetrahedra(edge: float = 1.0):
    """Two regular tetrahedra of edge ``a`` sharing the face ``(0, 1, 2)`` (000 Figs. 4.10-4.12).

    The second apex is the first mirrored through the shared face.

    Returns
    -------
    points : (5, 3) float64
    tets : (2, 4) int64
    """
    p, _ = regular_tetrahedron(edge)
    p = np.vstack([p, p[3] * [1.0, 1.0, -1.0]])
    return p, _positive(p, np.array([[0, 1, 2, 3], [0, 1, 2, 4]]))


def icosahedron_tets(radius: float = 1.0):
    """A regular icosahedron of circumradius ``radius`` cut into 20 tets around its centre (000 Fig. 4.13).

    The 12 vertices are the cyclic permutations of ``(0, ±1, ±φ)``, scaled to
    ``radius``; the centre is point 12. Volume ``(5/12)(3 + √5) a³`` with edge
    ``a = radius / sin(2π/5)``. This mesh has no rainbow colouring (see
    :func:`~porecad.volmesh.tetmesh.rainbow_coloring`).

    Returns
    -------
    points : (13, 3) float64
    tets : (20, 4) int64
    """
    r = positive_size(radius, "radius")
    phi = (1 + math.sqrt(5)) / 2
    v = []
    for s1, s2 in itertools.product((-1.0, 1.0), repeat=2):
        v += [(0.0, s1, s2 * phi), (s1, s2 * phi, 0.0), (s2 * phi, 0.0, s1)]
    v = np.array(v)
    v *= r / np.linalg.norm(v[0])
    d = np.linalg.norm(v[:, None] - v[None], axis=2)
    edge = d[d > 0].min()
    adj = np.abs(d - edge) < 1e-9 * r
    tris = [(i, j, k) for i, j, k in itertools.combinations(range(12), 3)
            if adj[i, j] and adj[j, k] and adj[i, k]]
    p = np.vstack([v, np.zeros((1, 3))])
    t = np.array([(12, i, j, k) for i, j, k in tris], dtype=np.int64)
    return p, _positive(p, t)


def cube_tets(size: float = 1.0):
    """A cube ``[0, s]³`` cut into 6 tets around its main diagonal (Kuhn / Freudenthal split).

    Corner ``n`` has coordinates ``s * (n & 1, (n >> 1) & 1, (n >> 2) & 1)``;
    every tet holds the diagonal ``0 - 7`` and one edge of the skew hexagon
    ``1, 3, 2, 6, 4, 5`` of the remaining corners, so each has volume
    ``s³ / 6`` and the split of every cube face is the one along the face
    diagonal through corner 0 or 7 (conforming with a translated copy).

    Returns
    -------
    points : (8, 3) float64
    tets : (6, 4) int64
    """
    s = positive_size(size, "size")
    n = np.arange(8)
    p = s * np.stack([n & 1, (n >> 1) & 1, (n >> 2) & 1], axis=1).astype(np.float64)
    ring = [1, 3, 2, 6, 4, 5]
    t = np.array([(0, 7, ring[i], ring[(i + 1) % 6]) for i in range(6)], dtype=np.int64)
    return p, _positive(p, t)
