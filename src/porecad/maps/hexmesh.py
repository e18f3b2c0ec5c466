"""TPMS cells mapped into structured hexahedral meshes by isoparametric shape functions (000 ch.3, 004 §3).

A structured hex mesh of ``nu × nv × nw`` cells is a map from the parameter
box ``[0, nu] × [0, nv] × [0, nw]`` (one unit cube per cell) to space. The
TPMS solid is polygonised once in that box with one whole period per cell
(closed on the box faces), and every vertex is mapped through the shape
functions of its cell:

* ``hex8``: trilinear, ``x = Σ_a N_a(ξ) x_a`` with
  ``N_a = (1 + ξ ξ_a)(1 + η η_a)(1 + ζ ζ_a) / 8`` (004 eq. 6; 000 eqs.
  3.2.5–3.2.8 write the same map as nested linear interpolations);
* ``hex20``: quadratic serendipity, corner nodes
  ``N_a = (1 + ξξ_a)(1 + ηη_a)(1 + ζζ_a)(ξξ_a + ηη_a + ζζ_a − 2) / 8`` and
  mid-edge nodes (``ξ_a = 0``) ``N_a = (1 − ξ²)(1 + ηη_a)(1 + ζζ_a) / 4``
  (and permutations), with ``ξ, η, ζ ∈ [−1, 1]`` (004 Fig. 3).

A cell face's map depends only on the nodes of that face, which both cells
sharing it hold, so neighbouring cells are continuous and the polygonised
solid — one mesh in the parameter box — stays welded and closed after the
map (if the map does not fold: the scaled Jacobian is checked first).

The geometry of a mesh is a node grid: ``(nu+1, nv+1, nw+1, 3)`` corner nodes
for hex8, or ``(2nu+1, 2nv+1, 2nw+1, 3)`` nodes at half-cell steps for hex20
(the points with at most one odd index are the 8 corners and 12 mid-edge
nodes of each cell; the others are unused by the serendipity element).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import InputError
from ..fields.base import lattice_values
from ..splines.volume import triple_product

# corner offsets (i, j, k) in VTK hexahedron order
CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                    [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], np.int64)
# mid-edge nodes in half-steps (VTK quadratic hexahedron order of the 12 edges)
MID_EDGES = np.array([[1, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0],
                      [1, 0, 2], [2, 1, 2], [1, 2, 2], [0, 1, 2],
                      [0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]], np.int64)


def check_node_grid(nodes, element: str = "hex8") -> tuple[np.ndarray, tuple[int, int, int]]:
    """Validate a node grid; return it (float64) and the cell counts (nu, nv, nw)."""
    if element not in ("hex8", "hex20"):
        raise InputError(f"unsupported element type {element!r}; use hex8 or hex20")
    g = np.asarray(nodes, dtype=np.float64)
    if g.ndim != 4 or g.shape[3] != 3 or min(g.shape[:3]) < 2:
        raise InputError(f"a node grid has shape (nu+1, nv+1, nw+1, 3); got {g.shape}")
    if not np.all(np.isfinite(g)):
        raise InputError("the node grid has non-finite coordinates")
    if element == "hex20":
        if any(s % 2 == 0 for s in g.shape[:3]):
            raise InputError(f"a hex20 node grid has odd sizes (2nu+1, 2nv+1, 2nw+1); got {g.shape[:3]}")
        cells = tuple((s - 1) // 2 for s in g.shape[:3])
    else:
        cells = tuple(s - 1 for s in g.shape[:3])
    return g, cells


def corner_grid(nodes, element: str = "hex8") -> np.ndarray:
    """The corner nodes (nu+1, nv+1, nw+1, 3) of a hex8 or hex20 node grid."""
    g, _ = check_node_grid(nodes, element)
    return g[::2, ::2, ::2] if element == "hex20" else g


def scaled_jacobians(corners) -> np.ndarray:
    """Minimum corner scaled Jacobian of each cell, (nu, nv, nw).

    At each corner, the determinant of the three unit edge vectors along +u,
    +v, +w (reversed where the corner is on the far side): 1 for a cube, ≤ 0
    for a folded or degenerate corner (the standard hex quality measure).
    """
    g = np.asarray(corners, dtype=np.float64)
    nu, nv, nw = (s - 1 for s in g.shape[:3])
    out = np.full((nu, nv, nw), np.inf)
    for c in CORNERS:
        i0, j0, k0 = c
        base = g[i0:i0 + nu, j0:j0 + nv, k0:k0 + nw]
        vecs = []
        for a in range(3):
            step = np.zeros(3, np.int64)
            step[a] = 1 if c[a] == 0 else -1
            s0, s1, s2 = (c + step)
            other = g[s0:s0 + nu, s1:s1 + nv, s2:s2 + nw]
            e = (other - base) * (1.0 if c[a] == 0 else -1.0)
            n = np.linalg.norm(e, axis=-1, keepdims=True)
            vecs.append(e / np.where(n > 0, n, 1.0))
        det = np.einsum("...i,...i->...", vecs[0], np.cross(vecs[1], vecs[2]))
        out = np.minimum(out, det)
    return out


def scaled_jacobians_unstructured(points, hexes) -> np.ndarray:
    """Minimum corner scaled Jacobian of each hexahedron (H,) of an unstructured mesh (VTK order)."""
    from ..volmesh.hexshapes import HEX_CORNER_NEIGHBOURS
    P = np.asarray(points, dtype=np.float64)[np.asarray(hexes, dtype=np.int64)]  # (H, 8, 3)
    e = P[:, HEX_CORNER_NEIGHBOURS] - P[:, :, None, :]  # (H, 8, 3, 3)
    e = e / np.maximum(np.linalg.norm(e, axis=-1, keepdims=True), 1e-300)
    return np.linalg.det(e).min(axis=1)


def _cell_jacobian_ratios(g, element, base, samples):
    """min det(J) / mean |det(J)| over a samples³ lattice of each listed cell (base: (m, 3) cell indices)."""
    t = np.linspace(0.0, 1.0, samples)
    local = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    local = np.clip(local, 1e-6, 1 - 1e-6)  # stay inside the cell (one-sided derivatives at its faces)
    # exact: the shape functions' derivatives at the samples, each cell's nodes gathered once
    if element == "hex8":
        offsets, dN = CORNERS, _shape_hex8_derivatives(local)  # (S, 8, 3): dN_k / dt_b
    else:
        offsets, dN = HEX20_OFFSETS, _shape_hex20_derivatives(local)  # (S, 20, 3), on the half-step grid
        base = 2 * base
    nodes = np.stack([g[base[:, 0] + o[0], base[:, 1] + o[1], base[:, 2] + o[2]] for o in offsets], axis=1)
    J = np.tensordot(nodes, dN, axes=([1], [1]))  # (m, 3 coords, S, 3 params), a BLAS product
    det = triple_product(*(J[..., b].transpose(0, 2, 1) for b in range(3)))  # (m, S)
    scale = np.abs(det).mean(axis=1, keepdims=True)
    return (det / np.where(scale > 0, scale, 1.0)).min(axis=1)


def sampled_jacobians(nodes, element: str = "hex8", samples: int = 4, fine: int = 12,
                      suspect: float = 0.1) -> np.ndarray:
    """Smallest Jacobian determinant of the map inside each cell, (nu, nv, nw).

    Positive corner Jacobians do not make a trilinear (let alone a
    serendipity) cell injective: a twisted cell can fold inside. The
    determinant of the derivative of :func:`map_params` is sampled on a
    ``samples³`` lattice of each cell (corners included), normalised by the
    cell's mean |det|; cells below ``suspect`` are sampled again on a
    ``fine³`` lattice (a fold can hide between coarse samples). ≤ 0 means the
    map folds or degenerates there.
    """
    g, cells = check_node_grid(nodes, element)
    base = np.stack(np.meshgrid(*[np.arange(c) for c in cells], indexing="ij"), axis=-1).reshape(-1, 3)
    out = _cell_jacobian_ratios(g, element, base, samples)
    low = np.flatnonzero(out < suspect)
    for chunk in np.array_split(low, max(1, len(low) // 64)):
        if len(chunk):
            out[chunk] = np.minimum(out[chunk], _cell_jacobian_ratios(g, element, base[chunk], fine))
    return out.reshape(cells)


#: node offsets of a 20-node element in half-cell steps: the 8 corners (VTK order), then the 12 mid-edges
HEX20_OFFSETS = np.concatenate([2 * CORNERS, MID_EDGES])


def _hex8_derivatives(pts):
    D = np.ones((len(pts), 3, 8))
    for c in range(8):
        for k in range(3):
            for a in range(3):
                if a == k:
                    D[:, k, c] *= 1.0 if CORNERS[c, a] else -1.0
                else:
                    D[:, k, c] *= pts[:, a] if CORNERS[c, a] else 1.0 - pts[:, a]
    return D


def _hex20_derivatives(pts):
    xi = 2.0 * pts - 1.0
    D = np.zeros((len(pts), 3, 20))
    for n, off in enumerate(HEX20_OFFSETS):
        s = off.astype(np.float64) - 1.0  # −1, 0, +1 per axis
        lin = 1.0 + xi * s  # (S, 3)
        if n < 8:
            total = np.sum(xi * s, axis=1) - 2.0
            prod = np.prod(lin, axis=1)
            for k in range(3):
                others = np.prod(np.delete(lin, k, axis=1), axis=1)
                D[:, k, n] = 2.0 * 0.125 * (s[k] * others * total + prod * s[k])
        else:
            m = int(np.flatnonzero(off == 1)[0])
            for k in range(3):
                rest = [i for i in range(3) if i not in (m, k)]
                pr = np.prod(lin[:, rest], axis=1)
                if k == m:
                    D[:, k, n] = 2.0 * 0.25 * (-2.0 * xi[:, m]) * pr
                else:
                    D[:, k, n] = 2.0 * 0.25 * (1.0 - xi[:, m] ** 2) * s[k] * pr
    return D


def shape_derivatives(element: str, t) -> np.ndarray:
    """Derivatives of the shape functions at local points ``t`` (S, 3) in [0, 1]³: ``D`` (S, 3, n).

    ``∂x/∂t_k (t_s) = Σ_c D[s, k, c] x_c`` for hex8 (n = 8, VTK corners) or
    hex20 (n = 20: corners, then mid-edges, :data:`HEX20_OFFSETS`), the
    derivatives of :func:`shape_hex8` and :func:`shape_hex20`.
    """
    pts = np.atleast_2d(np.asarray(t, dtype=np.float64))
    if element == "hex8":
        return _hex8_derivatives(pts)
    if element == "hex20":
        return _hex20_derivatives(pts)
    raise InputError(f"unsupported element type {element!r}; use hex8 or hex20")


def corner_scaled_jacobians(nodes, element: str = "hex8") -> np.ndarray:
    """Minimum scaled Jacobian of each cell's map at its 8 corners, (nu, nv, nw).

    ``det[ê_u, ê_v, ê_w]`` of the unit columns of the map's derivative at a
    corner. For hex8 the columns are the cell's edge vectors, so this is
    :func:`scaled_jacobians` of the corner grid; for hex20 it measures the
    curved element itself (the tangents of its curved edges), not the
    straight cell of its corners.
    """
    g, cells = check_node_grid(nodes, element)
    if element == "hex8":
        return scaled_jacobians(g)
    D = shape_derivatives("hex20", CORNERS.astype(np.float64))  # (8, 3, 20)
    base = 2 * np.stack(np.meshgrid(*[np.arange(c) for c in cells], indexing="ij"), axis=-1).reshape(-1, 3)
    X = np.stack([g[base[:, 0] + o[0], base[:, 1] + o[1], base[:, 2] + o[2]] for o in HEX20_OFFSETS], axis=1)
    e = np.einsum("skc,hcd->hskd", D, X)
    e = e / np.maximum(np.linalg.norm(e, axis=-1, keepdims=True), 1e-300)
    return np.linalg.det(e).min(axis=1).reshape(cells)


def check_jacobian(nodes, element: str = "hex8", min_allowed: float = 0.0) -> dict:
    """Refuse inverted or degenerate cells with a one-line error naming the first; return the quality.

    Two tests: the corner scaled Jacobian (the standard hex quality; of the
    curved map for hex20, :func:`corner_scaled_jacobians`) and the map's
    Jacobian sampled inside every cell (:func:`sampled_jacobians`).
    """
    sj = corner_scaled_jacobians(nodes, element)
    worst = float(sj.min())
    if not worst > min_allowed:
        i, j, k = (int(x) for x in np.unravel_index(int(np.argmin(sj)), sj.shape))
        kind = "inverted" if worst < 0 else "degenerate"
        raise InputError(f"hexahedron ({i}, {j}, {k}) is {kind} (scaled Jacobian {worst:.3g}); "
                         f"{int(np.sum(sj <= min_allowed))} cell(s) with scaled Jacobian ≤ {min_allowed:g}")
    inner = sampled_jacobians(nodes, element)
    if not inner.min() > 0:
        i, j, k = (int(x) for x in np.unravel_index(int(np.argmin(inner)), inner.shape))
        raise InputError(f"hexahedron ({i}, {j}, {k}) folds inside (its map's Jacobian changes sign although "
                         f"its corners are valid); {int(np.sum(inner <= 0))} such cell(s): the mesh is too "
                         "twisted for one TPMS cell per hexahedron")
    return {"min_scaled_jacobian": worst, "mean_scaled_jacobian": float(sj.mean()),
            "cells_below_0.2": int(np.sum(sj < 0.2)), "cells": int(sj.size),
            "min_sampled_jacobian_ratio": float(inner.min())}


def _cell_coords(params, cells):
    p = np.asarray(params, dtype=np.float64)
    idx = np.clip(np.floor(p).astype(np.int64), 0, np.asarray(cells) - 1)
    return idx, p - idx


def shape_hex8(t) -> np.ndarray:
    """Trilinear shape functions (N, 8) at local coordinates ``t`` (N, 3) in [0, 1]³, VTK corner order."""
    t = np.asarray(t, dtype=np.float64)
    return np.stack([np.prod(np.where(c == 1, t, 1.0 - t), axis=1) for c in CORNERS], axis=1)


def _shape_hex8_derivatives(t) -> np.ndarray:
    """Derivatives (N, 8, 3) of the trilinear shape functions at local ``t`` (N, 3): ``dN_k / dt_b``."""
    t = np.asarray(t, dtype=np.float64)
    out = np.empty((len(t), len(CORNERS), 3))
    for k, c in enumerate(CORNERS):
        f = np.where(c == 1, t, 1.0 - t)  # (N, 3) factors
        for b in range(3):
            out[:, k, b] = (1.0 if c[b] == 1 else -1.0) * np.prod(np.delete(f, b, axis=1), axis=1)
    return out


def _shape_hex20_derivatives(t) -> np.ndarray:
    """Derivatives (N, 20, 3) of :func:`shape_hex20` at local ``t`` (N, 3): ``dN_k / dt_b`` (``ξ = 2 t − 1``)."""
    xi = 2.0 * np.asarray(t, dtype=np.float64) - 1.0
    out = np.empty((len(xi), 20, 3))
    for k, c in enumerate(CORNERS):  # N = Π (1 + ξ_a s_a) (Σ ξ_a s_a − 2) / 8
        sg = 2.0 * c - 1.0
        f = 1.0 + xi * sg
        prod, lin = np.prod(f, axis=1), np.sum(xi * sg, axis=1) - 2.0
        for b in range(3):
            others = np.prod(np.delete(f, b, axis=1), axis=1)
            out[:, k, b] = 2.0 * sg[b] * (others * lin + prod) / 8.0
    for k, m in enumerate(MID_EDGES, start=8):  # N = (1 − ξ_ax²) / 4 · Π_{a ≠ ax} (1 + ξ_a s_a)
        sg = m - 1.0
        ax = int(np.flatnonzero(m == 1)[0])
        f = 1.0 + xi * sg
        f[:, ax] = 1.0
        bump = (1.0 - xi[:, ax] ** 2) / 4.0
        for b in range(3):
            if b == ax:
                out[:, k, b] = 2.0 * (-xi[:, ax] / 2.0) * np.prod(f, axis=1)
            else:
                out[:, k, b] = 2.0 * bump * sg[b] * np.prod(np.delete(f, b, axis=1), axis=1)
    return out


def shape_hex20(t) -> np.ndarray:
    """Serendipity shape functions (N, 20) at local ``t`` (N, 3) in [0, 1]³: 8 corners, then the 12 mid-edges."""
    xi = 2.0 * np.asarray(t, dtype=np.float64) - 1.0  # in [-1, 1]
    cols = []
    for c in CORNERS:
        s = 2.0 * c - 1.0
        cols.append(np.prod(1.0 + xi * s, axis=1) * (np.sum(xi * s, axis=1) - 2.0) / 8.0)
    for m in MID_EDGES:
        s = m - 1.0  # -1, 0, +1 per axis; 0 on the edge's own axis
        axis = int(np.flatnonzero(m == 1)[0])
        w = (1.0 - xi[:, axis] ** 2) / 4.0
        for a in range(3):
            if a != axis:
                w = w * (1.0 + xi[:, a] * s[a])
        cols.append(w)
    return np.stack(cols, axis=1)


def map_hex8(corners, params) -> np.ndarray:
    """Trilinear map of parameter points (in cell units) through a corner grid."""
    g = np.asarray(corners, dtype=np.float64)
    idx, t = _cell_coords(params, tuple(s - 1 for s in g.shape[:3]))
    nodes = np.stack([g[idx[:, 0] + c[0], idx[:, 1] + c[1], idx[:, 2] + c[2]] for c in CORNERS], axis=1)
    return np.einsum("nk,nkd->nd", shape_hex8(t), nodes)


def map_hex20(nodes2, params) -> np.ndarray:
    """Serendipity (20-node) map of parameter points through a half-step node grid."""
    g = np.ascontiguousarray(nodes2, dtype=np.float64)
    p = np.ascontiguousarray(params, dtype=np.float64).reshape(-1, 3)
    cells = np.array([(s - 1) // 2 for s in g.shape[:3]], dtype=np.int64)
    return _map_hex20_kernel(g, p, cells, HEX20_OFFSETS, np.concatenate([2.0 * CORNERS - 1.0, MID_EDGES - 1.0]))


@njit(cache=True, nogil=True)
def _map_hex20_kernel(g, p, cells, offsets, signs):  # pragma: no cover - compiled
    """:func:`shape_hex20` times the cell's 20 nodes, per point (one pass, no (N, 20, 3) temporaries)."""
    out = np.zeros((p.shape[0], 3))
    xi = np.empty(3)
    b = np.empty(3, dtype=np.int64)
    for n in range(p.shape[0]):
        for a in range(3):
            i = min(max(int(np.floor(p[n, a])), 0), cells[a] - 1)
            b[a] = 2 * i
            xi[a] = 2.0 * (p[n, a] - i) - 1.0
        for k in range(20):
            s = signs[k]
            if k < 8:
                w = (1.0 + xi[0] * s[0]) * (1.0 + xi[1] * s[1]) * (1.0 + xi[2] * s[2])
                w *= (xi[0] * s[0] + xi[1] * s[1] + xi[2] * s[2] - 2.0) / 8.0
            else:
                w = 0.25
                for a in range(3):
                    w *= (1.0 - xi[a] * xi[a]) if s[a] == 0.0 else (1.0 + xi[a] * s[a])
            o = offsets[k]
            for d in range(3):
                out[n, d] += w * g[b[0] + o[0], b[1] + o[1], b[2] + o[2], d]
    return out


def map_params(nodes, params, element: str = "hex8") -> np.ndarray:
    g, _ = check_node_grid(nodes, element)
    return map_hex20(g, params) if element == "hex20" else map_hex8(g, params)


# ---------------------------------------------------------------------------------------- generators


def _half_steps(n, element):
    return np.linspace(0.0, 1.0, (2 * n + 1) if element == "hex20" else (n + 1))


def frustum_nodes(cells=(4, 4, 4), bottom=(20.0, 20.0), top=(10.0, 10.0), height=20.0, element="hex8"):
    """A prismoid (rectangular frustum, 004 Fig. 8): rectangle ``bottom`` at z = 0 to ``top`` at z = height."""
    nu, nv, nw = cells
    s, t, r = (_half_steps(n, element) for n in (nu, nv, nw))
    S, T, R = np.meshgrid(s, t, r, indexing="ij")
    a = bottom[0] + (top[0] - bottom[0]) * R
    b = bottom[1] + (top[1] - bottom[1]) * R
    return np.stack([(S - 0.5) * a, (T - 0.5) * b, R * height], axis=-1)


def cylinder_nodes(cells=(4, 4, 4), radius=10.0, height=20.0, element="hex8"):
    """A cylinder (004 Fig. 9) meshed by a structured grid: the square cross-section mapped onto the disc.

    ``(u, v) ∈ [−1, 1]²`` maps to ``(u √(1 − v²/2), v √(1 − u²/2)) · radius``
    (the elliptical grid mapping), which takes the square's sides onto the
    circle; nodes (incl. hex20 mid-edge nodes) lie exactly on the curved side.
    """
    nu, nv, nw = cells
    s, t, r = (_half_steps(n, element) for n in (nu, nv, nw))
    S, T, R = np.meshgrid(2 * s - 1, 2 * t - 1, r, indexing="ij")
    x = S * np.sqrt(1.0 - T ** 2 / 2.0) * radius
    y = T * np.sqrt(1.0 - S ** 2 / 2.0) * radius
    return np.stack([x, y, R * height], axis=-1)


def hex_scaffold(nodes, tpms_type, structure, threshold, resolution, element="hex8", threads=None,
                 progress=None, clip=None) -> dict:
    """Polygonise one TPMS period per cell in the parameter box and map it into the hex mesh.

    Parameters
    ----------
    clip : Field, optional
        A physical-space field (negative inside, e.g. the body's signed
        distance). The solid is cut to it in field space: at every parameter
        sample ``u`` the structure value ``s(u)`` becomes
        ``max(s(u), k clip(x(u)))`` with ``x(u)`` the isoparametric map and
        ``k`` a scale that makes the clip term inactive one sample inside the
        body (see ``_clipped_sampler``), so one marching-cubes pass yields
        ``scaffold ∩ body`` (the R-function intersection, Ricci 1973). The
        cut surface is then made of mapped marching-cubes triangles like the
        rest, so a valid map cannot make it self-intersect — unlike a mesh
        Boolean, which leaves slivers where the femur's triangles graze the
        scaffold's.

    Returns ``{'vertices', 'faces', 'params', 'inside_fraction', 'jacobian'}``:
    a closed, outward-oriented solid (the parameter-box solid is closed on the
    box faces; a map with positive Jacobian keeps it so).
    """
    from ..fields.tpms import TPMSField
    from ..mesh.polygonise import Grid, polygonise
    from ..solids import StructureField, check_structure
    g, cells = check_node_grid(nodes, element)
    quality = check_jacobian(g, element)
    s = check_structure(structure)
    if s == "surface":
        raise InputError("a hex scaffold needs a solid structure: pore, rod or sheet")
    res = int(resolution)
    if res < 4 or res != resolution:
        raise InputError(f"resolution (samples per cell edge) must be an integer ≥ 4, got {resolution!r}")
    field = StructureField(TPMSField(tpms_type, cell_size=1.0), s, threshold=threshold)
    grid = Grid.from_box((0.0, 0.0, 0.0), tuple(float(c) for c in cells),
                         samples_per_axis=tuple(c * (res - 1) + 1 for c in cells))
    sample = field.sample_grid
    if clip is not None:
        sample = _clipped_sampler(field, clip, g, element, cells, res)
    out = polygonise(sample, grid, caps=True, threads=threads, progress=progress)
    params = np.clip(out.vertices, 0.0, np.asarray(cells, dtype=np.float64))
    vertices = map_params(g, params, element)
    return {"vertices": vertices, "faces": out.faces.astype(np.int64), "params": params,
            "inside_fraction": out.inside_fraction, "jacobian": quality, "cells": cells}


def cut_band(g, element, resolution, safety: float = 3.0) -> float:
    """The distance band (mm) a body's field must be exact in for the cut of :func:`hex_scaffold`: ``safety``
    times the longest physical step between neighbouring samples (an edge of the node grid over the samples per
    cell edge; for ``hex20`` two half-steps of the grid, which follow a curved edge).

    Farther than one step from the body's surface the cut value cannot change a sign of the sampled field or an
    interpolated vertex (the body term is inactive inside and positive beside every positive neighbour
    outside), so a wider band only costs distance queries.
    """
    grid = np.asarray(g, dtype=np.float64)
    step = 2 if element == "hex20" else 1
    longest = max(float(np.linalg.norm(np.diff(grid, axis=a), axis=-1).max()) for a in range(3))
    return float(safety) * step * longest / max(int(resolution) - 1, 1)


def _clipped_sampler(field, clip, g, element, cells, resolution):
    """``sample_grid`` of ``max(s(u), k clip(x(u)))`` over the parameter box (see :func:`hex_scaffold`).

    ``k = S / δ`` with ``S`` the largest ``|s|`` of the structure field and
    ``δ`` the mean physical sample spacing: one sample inside the body the
    clip term is already below every structure value, so away from the cut
    the max picks ``s`` at both ends of every grid edge and marching cubes
    interpolates exactly as without the cut. (A weaker clip term, e.g. ``d``
    in cell units, would replace the structure's inner values and pull the
    interpolated surface inwards everywhere.) ``clip`` must be exact to at
    least ``δ`` (a band of a few samples).
    """
    c = np.asarray(cells, dtype=np.float64)
    corner = g[::2, ::2, ::2] if element == "hex20" else g
    edges = [np.linalg.norm(np.diff(corner, axis=a), axis=-1).mean() for a in range(3)]
    delta = float(np.mean(edges)) / (int(resolution) - 1)
    probe = np.linspace(0.0, 1.0, 17)
    top = float(np.max(np.abs(field.sample_grid(probe, probe, probe))))
    k = 2.0 * max(top, 1e-12) / delta

    def sample(xs, ys, zs):
        s = field.sample_grid(xs, ys, zs)
        W, V, U = np.meshgrid(zs, ys, xs, indexing="ij")
        u = np.stack([U.ravel(), V.ravel(), W.ravel()], axis=1)
        x = map_params(g, np.clip(u, 0.0, c), element)
        d = k * lattice_values(clip, x.reshape(s.shape + (3,)))
        return np.maximum(s, d.astype(np.float32))

    return sample


def grid_hexes(corners):
    """A corner node grid as an unstructured hex mesh: ``points (N, 3)``, ``hexes (H, 8)`` (VTK order).

    Node ``(i, j, k)`` is point ``(i * (nv+1) + j) * (nw+1) + k``; cell ``(i, j, k)`` is row
    ``(i * nv + j) * nw + k``.
    """
    g = np.asarray(corners, dtype=np.float64)
    nu, nv, nw = (s - 1 for s in g.shape[:3])
    ids = np.arange(g.shape[0] * g.shape[1] * g.shape[2]).reshape(g.shape[:3])
    hexes = np.stack([ids[c[0]:c[0] + nu, c[1]:c[1] + nv, c[2]:c[2] + nw].reshape(-1) for c in CORNERS], axis=1)
    return g.reshape(-1, 3), hexes.astype(np.int64)


def region_pore_sizes(vertices, faces, regions, spacing):
    """Mean local thickness (mm) of the pore space inside each axis-aligned box of ``regions``.

    The mesh is voxelised at ``spacing`` (:func:`porecad.analysis.pores.voxelize`);
    the void voxels of a box are its pores; their local thickness (maximal
    inscribed spheres) is averaged. Boxes should lie inside the scaffold's domain.
    """
    from ..analysis.pores import voxelize
    from ..analysis.thickness import local_thickness
    solid, origin, h, _ = voxelize(vertices, faces, spacing)
    out = []
    for lo, hi in regions:
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        i0 = np.maximum(np.ceil((lo - origin) / h).astype(int), 0)
        i1 = np.minimum(np.floor((hi - origin) / h).astype(int) + 1, np.array(solid.shape[::-1]))
        sub = ~solid[i0[2]:i1[2], i0[1]:i1[1], i0[0]:i1[0]]
        if not sub.any():
            out.append(float("nan"))
            continue
        lt = local_thickness(sub, h)
        out.append(float(lt[sub].mean()))
    return out
