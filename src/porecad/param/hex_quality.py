"""Elements of a structured node grid and their quality: scaled Jacobians and determinants at sample points.

An element is an 8-node (trilinear) cell of the grid, or a 20-node
serendipity hexahedron built from a 2×2×2 block of cells (its 8 corners and
12 mid-edge nodes; :mod:`porecad.maps.hexmesh` order). At a point ``t`` of
the reference cube the map's derivative is linear in the element's nodes,
``∂x/∂t_k (t) = Σ_c D[k, c](t) x_c``; its determinant ``det[∂x/∂t_u,
∂x/∂t_v, ∂x/∂t_w]`` and the *scaled* Jacobian (the same with unit rows,
Knupp 2000: 1 for a right angle, ≤ 0 where the map folds) are what the
untangling (:mod:`porecad.param.grid_untangle`) raises. At a corner of a
trilinear cell the rows are its three edge vectors, so the scaled Jacobian
there is the standard corner measure of :func:`scaled_jacobian`.

The shape functions and their derivatives are those of
:mod:`porecad.maps.hexmesh`, which maps the scaffold.

Knupp, "Achieving finite element mesh quality via optimization of the
Jacobian matrix norm and associated quantities", IJNME 48, 2000.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError
from ..maps.hexmesh import HEX20_OFFSETS
from .cube import CORNER_NEIGHBOURS, CUBE

__all__ = ["barrier_terms", "rows_at", "gather_gradient", "grid_elements", "grid_to_hexes",
           "lattice_points", "min_det_ratio_at", "min_scaled_jacobian_at", "sample_dets", "sample_jacobians",
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


def grid_elements(shape, element: str = "hex8") -> np.ndarray:
    """Node ids (C order of a node grid of ``shape``) of its elements, cells in C order.

    ``hex8``: every cell, (nu nv nw, 8) in VTK order (as :func:`grid_to_hexes`).
    ``hex20``: every 2×2×2 block of cells (the grid has even cell counts),
    (nu nv nw / 8, 20): corners then mid-edge nodes
    (:data:`porecad.maps.hexmesh.HEX20_OFFSETS`).
    """
    s = np.asarray(shape[:3], np.int64)
    ids = np.arange(int(np.prod(s))).reshape(*s)
    if element == "hex8":
        c = s - 1
        return np.stack([ids[o[0]:o[0] + c[0], o[1]:o[1] + c[1], o[2]:o[2] + c[2]].ravel() for o in CUBE],
                        axis=1).astype(np.int64)
    if element != "hex20" or np.any((s - 1) % 2):
        raise InputError(f"elements are 'hex8', or 'hex20' on a grid of even cell counts; got {element!r}, "
                         f"{tuple(int(x) - 1 for x in s)} cells")
    c = (s - 1) // 2
    return np.stack([ids[o[0]:o[0] + 2 * c[0]:2, o[1]:o[1] + 2 * c[1]:2, o[2]:o[2] + 2 * c[2]:2].ravel()
                     for o in HEX20_OFFSETS], axis=1).astype(np.int64)


def lattice_points(ts, corners: bool = True) -> np.ndarray:
    """The points ``ts³`` of the reference cube, (S, 3); without ``corners`` the cube's 8 corners left out."""
    t = np.asarray(ts, np.float64)
    pts = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    if not corners:
        pts = pts[~np.all((pts == 0.0) | (pts == 1.0), axis=1)]
    return pts


def _rows(P, elems, D):
    """``∂x/∂t_k`` at every sample of every element, (H, S, 3, 3): one matrix product."""
    S, _, n = D.shape
    e = np.matmul(D.reshape(S * 3, n), P[elems])  # (H, S·3, 3)
    return e.reshape(len(elems), S, 3, 3)


def sample_jacobians(P, elems, D, grad: bool = False):
    """Scaled Jacobian ``det[ê_u, ê_v, ê_w]`` at the samples of ``D``, (H, S).

    With ``grad`` also ``∂J/∂e_k`` (H, S, 3, 3) for :func:`gather_gradient`
    (``∂J/∂e_k = (I − ê_k ê_kᵀ)(ê_{k+1} × ê_{k+2}) / |e_k|``).
    """
    e = _rows(P, elems, D)
    ln = np.maximum(np.linalg.norm(e, axis=3, keepdims=True), 1e-300)
    u = e / ln
    c0 = np.cross(u[:, :, 1], u[:, :, 2])
    J = np.einsum("hsd,hsd->hs", u[:, :, 0], c0)
    if not grad:
        return J
    crs = (c0, np.cross(u[:, :, 2], u[:, :, 0]), np.cross(u[:, :, 0], u[:, :, 1]))
    g = np.stack([(cr - u[:, :, k] * np.einsum("hsd,hsd->hs", u[:, :, k], cr)[..., None]) / ln[:, :, k]
                  for k, cr in enumerate(crs)], axis=2)
    return J, g


def sample_dets(P, elems, D, grad: bool = False):
    """Determinant ``det[∂x/∂t_u, ∂x/∂t_v, ∂x/∂t_w]`` at the samples of ``D``, (H, S); with ``grad`` ``∂/∂e_k``."""
    e = _rows(P, elems, D)
    c0 = np.cross(e[:, :, 1], e[:, :, 2])
    det = np.einsum("hsd,hsd->hs", e[:, :, 0], c0)
    if not grad:
        return det
    return det, np.stack([c0, np.cross(e[:, :, 2], e[:, :, 0]), np.cross(e[:, :, 0], e[:, :, 1])], axis=2)


def gather_gradient(D, w, g) -> np.ndarray:
    """``Σ_s w_s ∂J_s/∂x_c`` per element node, (H, n, 3), from ``w`` (H, S) and ``g = ∂J/∂e`` (H, S, 3, 3)."""
    S, _, n = D.shape
    W = (w[:, :, None, None] * g).reshape(len(w), S * 3, 3)
    return np.matmul(D.reshape(S * 3, n).T, W)


def rows_at(P, elems, D) -> np.ndarray:
    """``∂x/∂t_k`` at the samples of ``D`` of every element, (H, S, 3, 3) (one matrix product)."""
    return _rows(P, elems, D)


@njit(cache=True)
def barrier_terms(e, ratio, mu, kappa, mu2, kappa2, soft, scaled):  # pragma: no cover - compiled
    """Barrier energy on Jacobians at samples and its gradient with respect to the rows ``e`` (H, S, 3, 3).

    ``J`` is the scaled Jacobian ``det[ê₀, ê₁, ê₂]`` (``scaled``) or
    ``det[e₀, e₁, e₂] / ratio[h]``; the energy is
    ``κ₂ Σ (μ₂ − J)₊² (+ κ Σ (μ − J)₊² when soft)``. Returns
    ``(E, W (H, S, 3, 3) = ∂E/∂e, active (H,) bool)``, with
    ``∂J/∂e_k = (I − ê_k ê_kᵀ)(ê_{k+1} × ê_{k+2}) / |e_k|`` (scaled) or
    ``e_{k+1} × e_{k+2} / ratio`` (determinant).
    """
    H, S = e.shape[0], e.shape[1]
    W = np.zeros(e.shape)
    act = np.zeros(H, np.bool_)
    lo = mu if soft else mu2
    E = 0.0
    u = np.empty((3, 3))
    c = np.empty((3, 3))
    ln = np.empty(3)
    for h in range(H):
        for s in range(S):
            for k in range(3):
                if scaled:
                    l2 = e[h, s, k, 0] ** 2 + e[h, s, k, 1] ** 2 + e[h, s, k, 2] ** 2
                    ln[k] = max(np.sqrt(l2), 1e-300)
                else:
                    ln[k] = 1.0
                for d in range(3):
                    u[k, d] = e[h, s, k, d] / ln[k]
            for k in range(3):
                a, b = (k + 1) % 3, (k + 2) % 3
                c[k, 0] = u[a, 1] * u[b, 2] - u[a, 2] * u[b, 1]
                c[k, 1] = u[a, 2] * u[b, 0] - u[a, 0] * u[b, 2]
                c[k, 2] = u[a, 0] * u[b, 1] - u[a, 1] * u[b, 0]
            J = u[0, 0] * c[0, 0] + u[0, 1] * c[0, 1] + u[0, 2] * c[0, 2]
            if not scaled:
                J /= ratio[h]
            if J >= lo:
                continue
            v2 = max(mu2 - J, 0.0)
            E += kappa2 * v2 * v2
            w = -2.0 * kappa2 * v2
            if soft:
                v1 = max(mu - J, 0.0)
                E += kappa * v1 * v1
                w -= 2.0 * kappa * v1
            if w == 0.0:
                continue
            act[h] = True
            for k in range(3):
                if scaled:
                    uc = u[k, 0] * c[k, 0] + u[k, 1] * c[k, 1] + u[k, 2] * c[k, 2]
                    for d in range(3):
                        W[h, s, k, d] = w * (c[k, d] - u[k, d] * uc) / ln[k]
                else:
                    for d in range(3):
                        W[h, s, k, d] = w * c[k, d] / ratio[h]
    return E, W, act


@njit(cache=True)
def min_det_ratio_at(P, elems, D, vref):  # pragma: no cover - compiled
    """Minimum of ``det / vref`` of :func:`sample_dets` over the given elements (numba; for the polish loop)."""
    best = 1e300
    e = np.empty((3, 3))
    for h in range(elems.shape[0]):
        for s in range(D.shape[0]):
            for k in range(3):
                for d in range(3):
                    acc = 0.0
                    for c in range(D.shape[2]):
                        acc += D[s, k, c] * P[elems[h, c], d]
                    e[k, d] = acc
            det = (e[0, 0] * (e[1, 1] * e[2, 2] - e[1, 2] * e[2, 1])
                   - e[0, 1] * (e[1, 0] * e[2, 2] - e[1, 2] * e[2, 0])
                   + e[0, 2] * (e[1, 0] * e[2, 1] - e[1, 1] * e[2, 0])) / vref[h]
            if det < best:
                best = det
    return best


@njit(cache=True)
def min_scaled_jacobian_at(P, elems, D):  # pragma: no cover - compiled
    """Minimum of :func:`sample_jacobians` over the given elements (numba; the polish loop calls it per trial)."""
    best = 1e300
    e = np.empty((3, 3))
    for h in range(elems.shape[0]):
        for s in range(D.shape[0]):
            for k in range(3):
                l2 = 0.0
                for d in range(3):
                    acc = 0.0
                    for c in range(D.shape[2]):
                        acc += D[s, k, c] * P[elems[h, c], d]
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
