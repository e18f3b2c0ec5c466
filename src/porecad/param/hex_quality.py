"""Hexahedra of a structured node grid and their quality: corner and sampled scaled Jacobians (Knupp 2000).

Knupp, "Achieving finite element mesh quality via optimization of the
Jacobian matrix norm and associated quantities", IJNME 48, 2000 (corner
scaled Jacobians).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError
from .cube import CORNER_NEIGHBOURS, CUBE

__all__ = ["SAMPLE_D", "SAMPLE_D_ALL", "corner_jacobians", "grid_to_hexes", "min_corner_jacobian",
           "min_sample_jacobian", "min_sample_ratio", "sample_derivatives", "sample_dets", "sample_jacobians",
           "scaled_jacobian"]


def grid_to_hexes(nodes):
    """Points and VTK hexahedra of a structured node grid.

    Parameters
    ----------
    nodes : (nu+1, nv+1, nw+1, 3) float

    Returns
    -------
    points : (N, 3) float64
        ``nodes`` in C order: point ``(i (nv+1) + j)(nw+1) + k`` is ``nodes[i, j, k]``.
    hexes : (nu nv nw, 8) int64
        VTK order: cell ``(i, j, k)`` → ``(i,j,k), (i+1,j,k), (i+1,j+1,k), (i,j+1,k)``
        and the same at ``k + 1`` (counter-clockwise seen from ``+w`` for a
        right-handed grid); cells in C order of ``(i, j, k)``.
    """
    g = np.asarray(nodes, np.float64)
    if g.ndim != 4 or g.shape[3] != 3 or min(g.shape[:3]) < 2:
        raise InputError(f"a node grid has shape (nu+1, nv+1, nw+1, 3); got {g.shape}")
    s = np.array(g.shape[:3])
    ids = np.arange(int(np.prod(s))).reshape(*s)
    cells = s - 1
    hexes = np.stack([ids[o[0]:o[0] + cells[0], o[1]:o[1] + cells[1], o[2]:o[2] + cells[2]].ravel()
                      for o in CUBE], axis=1).astype(np.int64)
    return g.reshape(-1, 3).copy(), hexes


def corner_jacobians(P, hexes, grad: bool = False):
    """Scaled Jacobian at the 8 corners of each hex, (H, 8); with ``grad`` also its gradient pieces.

    Corner ``a`` with neighbours ``(b, c, d)``: ``J = ê₁ · (ê₂ × ê₃)`` with
    ``ê_k = e_k / |e_k|``; ``∂J/∂e_k = (I − ê_k ê_kᵀ)(ê_{k+1} × ê_{k+2}) / |e_k|``.
    """
    Js, parts = [], []
    for c in range(8):
        a = hexes[:, c]
        nb = hexes[:, CORNER_NEIGHBOURS[c]]
        e = P[nb] - P[a][:, None, :]
        ln = np.maximum(np.linalg.norm(e, axis=2, keepdims=True), 1e-300)
        u = e / ln
        crs = (np.cross(u[:, 1], u[:, 2]), np.cross(u[:, 2], u[:, 0]), np.cross(u[:, 0], u[:, 1]))
        Js.append(np.einsum("ij,ij->i", u[:, 0], crs[0]))
        if grad:
            g = [(cr - u[:, k] * np.einsum("ij,ij->i", u[:, k], cr)[:, None]) / ln[:, k] for k, cr in enumerate(crs)]
            parts.append((a, nb, g))
    return np.stack(Js, axis=1), parts


def sample_derivatives(ts=(0.0, 1 / 3, 0.5, 2 / 3, 1.0), corners: bool = False):
    """Trilinear derivative weights at the non-corner points of the ``ts³`` lattice, (S, 3, 8).

    ``∂x/∂u_k (p_s) = Σ_c D[s, k, c] x_c`` with the corners ``x_c`` in VTK
    (:data:`CUBE`) order. The default lattice holds the 27-point lattice (the
    corners of the 8 sub-hexes at the mid-edge, face-centre and centre points:
    the trilinear map restricted to a sub-hex is the sub-hex's own trilinear
    map, so their corner Jacobians are the map's Jacobian there) and the
    4×4×4 lattice of :func:`porecad.maps.hexmesh.sampled_jacobians`.
    """
    t = np.asarray(ts, np.float64)
    pts = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    if not corners:  # the corner measure has them
        pts = pts[~np.all((pts == 0.0) | (pts == 1.0), axis=1)]
    D = np.ones((len(pts), 3, 8))
    for c in range(8):
        for k in range(3):
            for a in range(3):
                if a == k:
                    D[:, k, c] *= 1.0 if CUBE[c, a] else -1.0
                else:
                    D[:, k, c] *= pts[:, a] if CUBE[c, a] else 1.0 - pts[:, a]
    return D


SAMPLE_D = sample_derivatives()
SAMPLE_D_ALL = sample_derivatives(corners=True)  # for the (unscaled) determinant, which sees collapsed edges


def sample_jacobians(P, hexes, D=SAMPLE_D, grad: bool = False):
    """Scaled Jacobian ``det[ê_u, ê_v, ê_w]`` of the trilinear map at the samples of ``D``, (H, S).

    With ``grad`` also its gradient with respect to the 8 corners, (H, S, 8, 3).
    """
    X = P[hexes]  # (H, 8, 3)
    e = np.einsum("skc,hcd->hskd", D, X)  # (H, S, 3, 3): rows ∂x/∂u, ∂x/∂v, ∂x/∂w
    ln = np.maximum(np.linalg.norm(e, axis=3, keepdims=True), 1e-300)
    u = e / ln
    c0 = np.cross(u[:, :, 1], u[:, :, 2])
    J = np.einsum("hsd,hsd->hs", u[:, :, 0], c0)
    if not grad:
        return J
    crs = (c0, np.cross(u[:, :, 2], u[:, :, 0]), np.cross(u[:, :, 0], u[:, :, 1]))
    g = np.stack([(cr - u[:, :, k] * np.einsum("hsd,hsd->hs", u[:, :, k], cr)[..., None]) / ln[:, :, k]
                  for k, cr in enumerate(crs)], axis=2)  # (H, S, 3, 3): ∂J/∂e_k
    return J, np.einsum("skc,hskd->hscd", D, g)


def sample_dets(P, hexes, D=SAMPLE_D_ALL, grad: bool = False):
    """Determinant ``det[∂x/∂u, ∂x/∂v, ∂x/∂w]`` at the samples of ``D``, (H, S); with ``grad`` (H, S, 8, 3)."""
    e = np.einsum("skc,hcd->hskd", D, P[hexes])
    c0 = np.cross(e[:, :, 1], e[:, :, 2])
    det = np.einsum("hsd,hsd->hs", e[:, :, 0], c0)
    if not grad:
        return det
    g = np.stack([c0, np.cross(e[:, :, 2], e[:, :, 0]), np.cross(e[:, :, 0], e[:, :, 1])], axis=2)
    return det, np.einsum("skc,hskd->hscd", D, g)


@njit(cache=True)
def min_sample_ratio(P, hexes, D, vref):  # pragma: no cover - compiled
    """Minimum of ``det / vref`` of :func:`sample_dets` over the given hexahedra (numba; for the polish loop)."""
    best = 1e300
    e = np.empty((3, 3))
    for h in range(hexes.shape[0]):
        for s in range(D.shape[0]):
            for k in range(3):
                for d in range(3):
                    acc = 0.0
                    for c in range(8):
                        acc += D[s, k, c] * P[hexes[h, c], d]
                    e[k, d] = acc
            det = (e[0, 0] * (e[1, 1] * e[2, 2] - e[1, 2] * e[2, 1])
                   - e[0, 1] * (e[1, 0] * e[2, 2] - e[1, 2] * e[2, 0])
                   + e[0, 2] * (e[1, 0] * e[2, 1] - e[1, 1] * e[2, 0])) / vref[h]
            if det < best:
                best = det
    return best


@njit(cache=True)
def min_sample_jacobian(P, hexes, D):  # pragma: no cover - compiled
    """Minimum of :func:`sample_jacobians` over the given hexahedra (numba; for the polish loop)."""
    best = 1e300
    e = np.empty((3, 3))
    for h in range(hexes.shape[0]):
        for s in range(D.shape[0]):
            for k in range(3):
                l2 = 0.0
                for d in range(3):
                    acc = 0.0
                    for c in range(8):
                        acc += D[s, k, c] * P[hexes[h, c], d]
                    e[k, d] = acc
                    l2 += acc * acc
                ln = np.sqrt(l2)
                for d in range(3):
                    e[k, d] = e[k, d] / ln if ln > 0 else 0.0
            det = (e[0, 0] * (e[1, 1] * e[2, 2] - e[1, 2] * e[2, 1])
                   - e[0, 1] * (e[1, 0] * e[2, 2] - e[1, 2] * e[2, 0])
                   + e[0, 2] * (e[1, 0] * e[2, 1] - e[1, 1] * e[2, 0]))
            if det < best:
                best = det
    return best


def scaled_jacobian(points, hexes) -> np.ndarray:
    """Minimum corner scaled Jacobian of each hexahedron, (H,).

    At corner ``a`` with neighbours ``(b, c, d)`` (right-handed in VTK order:
    0 → (1, 3, 4), 1 → (2, 0, 5), …, 7 → (6, 4, 3)) the scaled Jacobian is
    ``det[ê_ab, ê_ac, ê_ad]`` with ``ê`` the unit edge vectors (Knupp 2000):
    1 for a right-angled corner, ≤ 0 for a degenerate or inverted one.
    A zero-length edge counts as 0.
    """
    x = np.asarray(points, np.float64)
    h = np.asarray(hexes, np.int64)
    if x.ndim != 2 or x.shape[1] != 3 or h.ndim != 2 or h.shape[1] != 8:
        raise InputError(f"need points (N, 3) and hexes (H, 8); got {x.shape} and {h.shape}")
    if h.size and (h.min() < 0 or h.max() >= len(x)):
        raise InputError(f"hex vertex indices must lie in 0..{len(x) - 1}")
    out = np.full(len(h), np.inf)
    for c in range(8):
        e = x[h[:, CORNER_NEIGHBOURS[c]]] - x[h[:, c]][:, None, :]
        ln = np.linalg.norm(e, axis=2, keepdims=True)
        e = np.where(ln > 0, e / np.where(ln > 0, ln, 1.0), 0.0)
        out = np.minimum(out, np.linalg.det(e))
    return out


@njit(cache=True)
def min_corner_jacobian(P, hexes, nbtab):  # pragma: no cover - compiled
    """Minimum corner scaled Jacobian over the given hexahedra (numba; the polish loop calls it per trial)."""
    best = 1e300
    e = np.empty((3, 3))
    for h in range(hexes.shape[0]):
        for c in range(8):
            a = hexes[h, c]
            for k in range(3):
                b = hexes[h, nbtab[c, k]]
                l2 = 0.0
                for d in range(3):
                    e[k, d] = P[b, d] - P[a, d]
                    l2 += e[k, d] * e[k, d]
                ln = np.sqrt(l2)
                for d in range(3):
                    e[k, d] = e[k, d] / ln if ln > 0 else 0.0
            det = (e[0, 0] * (e[1, 1] * e[2, 2] - e[1, 2] * e[2, 1])
                   - e[0, 1] * (e[1, 0] * e[2, 2] - e[1, 2] * e[2, 0])
                   + e[0, 2] * (e[1, 0] * e[2, 1] - e[1, 1] * e[2, 0]))
            if det < best:
                best = det
    return best
