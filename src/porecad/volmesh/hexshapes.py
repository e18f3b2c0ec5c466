"""Hexahedral meshes as plain arrays: small generators, validation, faces, volume (000 Fig. 5.7).

A hex mesh is ``points`` ``(V, 3)`` float64 (mm) and ``hexes`` ``(H, 8)``
int64 in the VTK hexahedron order: corners ``0 1 2 3`` go round the bottom
face counter-clockwise seen from above (from the side of the top face), and
corner ``4 + k`` lies above corner ``k``. For the unit cube::

    0 (0,0,0)  1 (1,0,0)  2 (1,1,0)  3 (0,1,0)
    4 (0,0,1)  5 (1,0,1)  6 (1,1,1)  7 (0,1,1)

A hex is *valid* when the Jacobian at each of its eight corners is positive:
at corner ``k`` with the three neighbouring corners ``(i, j, l)`` of
:data:`HEX_CORNER_NEIGHBOURS` (right-handed for a valid hex),

.. math:: J_k = \\det\\,[\\,p_i - p_k,\\; p_j - p_k,\\; p_l - p_k\\,] > 0 .

:data:`HEX_FACES` lists the six faces with corners ordered so that the
right-hand normal points out of a valid hex.
"""

from __future__ import annotations

import numpy as np

from porecad.errors import InputError

from .shapes import positive_size

__all__ = ["HEX_FACES", "HEX_EDGES", "HEX_CORNER_NEIGHBOURS", "HEX_TETS", "single_hex", "hex_grid", "hex_rod",
           "check_hex_mesh", "hex_corner_jacobians", "hex_boundary_faces", "hex_face_groups", "hex_volumes"]

#: The six faces (outward right-hand normal for a valid hex): z0, z1, y0, x1, y1, x0 of the unit cube.
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]],
                     dtype=np.int64)
#: The twelve edges.
HEX_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                      [0, 4], [1, 5], [2, 6], [3, 7]], dtype=np.int64)
#: For corner ``k``, its three edge neighbours in right-handed order (the corner Jacobian's columns).
HEX_CORNER_NEIGHBOURS = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                                  [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]], dtype=np.int64)
#: Six tets around the diagonal 0-6 (positively oriented for the unit cube); used for volumes and point location.
HEX_TETS = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]],
                    dtype=np.int64)
_CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                 dtype=np.float64)


def _count(value, name: str) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < 1:
        raise InputError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def hex_grid(nx: int = 2, ny: int = 2, nz: int = 2, size: float = 1.0):
    """``nx × ny × nz`` cubes of edge ``size`` filling ``[0, nx s] × [0, ny s] × [0, nz s]`` (000 Fig. 5.7b).

    Grid node ``(i, j, k)`` is point ``i + (nx + 1) (j + (ny + 1) k)``; hex
    ``(i, j, k)`` is row ``i + nx (j + ny k)``. Conforming, every hex valid.

    Returns
    -------
    points : ((nx+1)(ny+1)(nz+1), 3) float64
    hexes : (nx ny nz, 8) int64, VTK order
    """
    nx, ny, nz = _count(nx, "nx"), _count(ny, "ny"), _count(nz, "nz")
    s = positive_size(size, "size")
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    points = s * np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1).astype(np.float64)

    def node(a, b, c):
        return a + (nx + 1) * (b + (ny + 1) * c)

    hk, hj, hi = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    hi, hj, hk = hi.ravel(), hj.ravel(), hk.ravel()
    off = _CUBE.astype(np.int64)
    hexes = np.stack([node(hi + off[c, 0], hj + off[c, 1], hk + off[c, 2]) for c in range(8)], axis=1)
    return points, np.ascontiguousarray(hexes, dtype=np.int64)


def single_hex(size: float = 1.0):
    """One cube ``[0, s]³`` as a hex (000 Fig. 5.7a). Returns ``(points (8, 3), hexes (1, 8))``."""
    return hex_grid(1, 1, 1, size)


def hex_rod(n: int = 4, size: float = 1.0):
    """A rod of ``n`` cubes of edge ``size`` in a row along x (000 Fig. 5.7c: ``n = 4``)."""
    return hex_grid(n, 1, 1, size)


def hex_corner_jacobians(points, hexes) -> np.ndarray:
    """Corner Jacobians ``J_k`` (module docstring) of every hex, ``(H, 8)`` (mm³)."""
    p = np.asarray(points, dtype=np.float64)
    q = p[np.asarray(hexes, dtype=np.int64)]  # (H, 8, 3)
    e = q[:, HEX_CORNER_NEIGHBOURS] - q[:, :, None, :]  # (H, 8, 3 neighbours, 3)
    return np.einsum("hki,hki->hk", e[:, :, 0], np.cross(e[:, :, 1], e[:, :, 2]))


def hex_volumes(points, hexes) -> np.ndarray:
    """Volume of every hex as the sum of its six tets around the diagonal 0-6 (:data:`HEX_TETS`), mm³.

    Exact for hexes with planar faces whose split matches the diagonal
    (cubes, parallelepipeds), a close approximation otherwise.
    """
    p = np.asarray(points, dtype=np.float64)
    q = p[np.asarray(hexes, dtype=np.int64)][:, HEX_TETS]  # (H, 6, 4, 3)
    a, b, c = q[:, :, 1] - q[:, :, 0], q[:, :, 2] - q[:, :, 0], q[:, :, 3] - q[:, :, 0]
    return np.einsum("hti,hti->ht", a, np.cross(b, c)).sum(axis=1) / 6.0


def _faces_sorted(hexes: np.ndarray):
    f = hexes[:, HEX_FACES].reshape(-1, 4)
    return f, np.sort(f, axis=1)


def hex_face_groups(hexes):
    """Group the ``6 H`` hex faces by their vertex sets.

    Returns ``(inverse, counts)``: face ``6 h + k`` (local face ``k`` of
    :data:`HEX_FACES`) belongs to group ``inverse[6 h + k]``, shared by
    ``counts[group]`` hexes.
    """
    h = np.asarray(hexes, dtype=np.int64)
    _, s = _faces_sorted(h)
    _, inverse, counts = np.unique(s, axis=0, return_inverse=True, return_counts=True)
    return inverse.reshape(-1), counts


def hex_boundary_faces(hexes):
    """The boundary quads of a hex mesh (faces of one hex only), outward.

    Returns ``(quads (F, 4), owner (F,), local (F,))`` in order of
    ``(owner, local)``; ``quads[i] = hexes[owner[i], HEX_FACES[local[i]]]``.
    """
    h = np.asarray(hexes, dtype=np.int64)
    inverse, counts = hex_face_groups(h)
    once = np.flatnonzero(counts[inverse] == 1)
    owner, local = once // 6, once % 6
    return np.ascontiguousarray(h[owner[:, None], HEX_FACES[local]]), owner, local


def check_hex_mesh(points, hexes, rel_tol: float = 1e-9):
    """Validate a hex mesh and return it with every hex valid (all corner Jacobians positive).

    Checks, in order (the first failure raises a one-line :class:`InputError`
    naming the hex): shapes ``(V, 3)`` and ``(H, 8)`` with ``H >= 1``,
    finite coordinates, indices in range, no repeated vertex in a hex; no
    degenerate corner (``|J_k| <= rel_tol · l_mean³``); orientation — a mesh
    whose hexes are all mirrored (every ``J_k < 0``) is turned over (top and
    bottom faces swapped), otherwise a hex with a negative corner Jacobian is
    inverted; conformity — no face shared by more than two hexes.

    Returns
    -------
    points : (V, 3) float64
    hexes : (H, 8) int64
    """
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != 3 or not (np.issubdtype(p.dtype, np.number)):
        raise InputError(f"points must be a numeric (V, 3) array, got shape {p.shape}")
    p = np.ascontiguousarray(p, dtype=np.float64)
    h = np.asarray(hexes)
    if h.ndim != 2 or h.shape[1] != 8:
        raise InputError(f"hexes must have shape (H, 8), got {h.shape}")
    if len(h) == 0:
        raise InputError("hex mesh has no hexahedra")
    if not np.issubdtype(h.dtype, np.integer):
        raise InputError(f"hexes must be integer vertex indices, got dtype {h.dtype}")
    h = np.ascontiguousarray(h, dtype=np.int64)
    finite = np.isfinite(p).all(axis=1)
    if not finite.all():
        i = int(np.argmin(finite))
        raise InputError(f"point {i} has a non-finite coordinate ({', '.join(map(str, p[i]))})")
    bad = ((h < 0) | (h >= len(p))).any(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"hex {i} references a vertex outside 0..{len(p) - 1} "
                         f"(vertices {', '.join(map(str, h[i]))})")
    srt = np.sort(h, axis=1)
    rep = (srt[:, 1:] == srt[:, :-1]).any(axis=1)
    if rep.any():
        i = int(np.argmax(rep))
        raise InputError(f"hex {i} repeats a vertex (vertices {', '.join(map(str, h[i]))})")
    q = p[h]
    l_mean = float(np.linalg.norm(q[:, HEX_EDGES[:, 1]] - q[:, HEX_EDGES[:, 0]], axis=2).mean())
    J = hex_corner_jacobians(p, h)
    eps = float(rel_tol) * l_mean ** 3
    flat = np.abs(J) <= eps
    if flat.any():
        i, k = np.unravel_index(int(np.argmax(flat)), flat.shape)
        raise InputError(f"hex {i} is degenerate at corner {k} (corner Jacobian {J[i, k]:.4g} mm³; "
                         f"vertices {', '.join(map(str, h[i]))})")
    if (J < 0).all():
        h = np.ascontiguousarray(h[:, [4, 5, 6, 7, 0, 1, 2, 3]])
        J = hex_corner_jacobians(p, h)
    neg = J < 0
    if neg.any():
        i, k = np.unravel_index(int(np.argmax(neg)), neg.shape)
        raise InputError(f"hex {i} is inverted or self-intersecting: negative corner Jacobian "
                         f"{J[i, k]:.4g} mm³ at corner {k} (vertices {', '.join(map(str, h[i]))})")
    inverse, counts = hex_face_groups(h)
    if (counts > 2).any():
        g = int(np.argmax(counts > 2))
        members = np.flatnonzero(inverse == g) // 6
        raise InputError(f"hex mesh is not conforming: one face is shared by {len(members)} hexes "
                         f"({', '.join(map(str, members[:8]))})")
    return p, h
