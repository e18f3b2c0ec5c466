"""Hexahedral parameterisation of a closed body: one structured ``nu × nv × nw`` hex grid (000 ch.3).

The body is treated as a deformed cube (000 §3.0, Fig. 3.1):

1. **Corners**: eight mesh vertices, given, or chosen automatically
   (:func:`choose_corners`: the principal-axis box; or, where that folds,
   corners around the two ends of the body, see below).
2. **Cube edges** (:func:`cube_edges`, 000 §3.2–3.3, Table 3.1 with the
   erratum edge 10 = 2→6): twelve geodesic edge paths from four heat sources
   (corners 0, 2, 5, 7, an inscribed tetrahedron, so every cube edge has one
   source end), by the heat method (:mod:`porecad.param.heat`).
3. **Faces** (:func:`surface_patches`, 000 §3.4, Table 3.2): the paths cut the
   surface into six patches, found by a flood fill over triangles that does
   not cross a path edge (the "in-plane growing" of 000 §3.2.2.2).
4. **Surface grid** (000 §3.5): each patch is mapped to the unit square and the
   patch's structured grid is pulled back to the surface.
5. **Volume grid** (000 §3.6): interior nodes by the discrete Laplace
   equation (000 eq. 3.2.3), ``x_ijk = (x_{i±1,j,k} + x_{i,j±1,k} + x_{i,j,k±1}) / 6``,
   with the surface nodes fixed; one sparse solve.
6. **Untangling** (not in 000): where a corner scaled Jacobian is below
   0.05, the grid Laplace energy plus a barrier on low corner Jacobians is
   minimised, interior nodes moving freely and surface nodes sliding inside
   their face or along their cube edge (:func:`_untangle`).

Cube labelling (000 Fig. 3.2, marching-cubes convention): corner ``k`` sits at
``(u, v, w)`` = ``CUBE[k]`` with 0 = (0,0,0), 1 = (1,0,0), 2 = (1,1,0),
3 = (0,1,0) and ``k + 4`` = corner ``k`` at ``w = 1``; edges e0 = 0–1, e1 = 1–2,
e2 = 2–3, e3 = 3–0, e4 = 4–5, e5 = 5–6, e6 = 6–7, e7 = 7–4, e8 = 0–4, e9 = 1–5,
e10 = 2–6, e11 = 3–7; faces f0 = 0-1-2-3 (w = 0), f1 = 4-5-6-7 (w = 1),
f2 = 0-1-5-4 (v = 0), f3 = 1-2-6-5 (u = 1), f4 = 2-3-7-6 (v = 1),
f5 = 3-0-4-7 (u = 0). Node ``nodes[i, j, k]`` sits at ``(u, v, w) = (i/nu, j/nv, k/nw)``.

Deviations from the dissertation, and why:

* **Surface nodes** (000 §3.5 places them by "evenly offset interception" of
  level curves of three harmonic fields). Here every patch gets its own
  harmonic map to the unit square (cotangent weights clipped to be
  positive, falling back to mean-value weights, Floater 2003, when a
  triangle flips), with its four boundary paths laid on the square's sides
  by arc length; the patch grid nodes ``(i/n_s, j/n_t)`` are located in the
  mapped triangulation and interpolated back barycentrically. A
  convex-boundary map with positive weights is bijective (Tutte, Floater),
  so every node lands on its patch exactly once; each cube edge is sampled
  by arc length once and reused by both of its patches, so shared edges
  carry identical nodes and the six face grids close up into the exact
  boundary of the node array. Level-curve interception needs closed
  iso-lines that cross each side edge once, which fails on bodies with bulges.
* **Guided side edges.** On a long, bowed body (the femur) the four geodesic
  side edges e8–e11 all hug the concave side of the shaft and touch. When
  the geodesic edges fail the checks, the side edges are instead shortest
  paths in disjoint corridors around straight lines of the conformal
  coordinates ``(w, θ)`` of the annulus between the two end loops
  (:func:`_guide_sides`).
* **Automatic corners at the ends.** Where the principal-axis box corners
  fold a face, the ends of the body are taken as the regions around its two
  extreme points whose (smoothed) normals face along the long axis (angle
  below 60°); a harmonic "dipole" field ``W`` (0 on one end, 1 on the other,
  000 §3.5) and its conjugate ``Θ`` give conformal cylinder coordinates; the
  corners sit just outside the ends at ``Θ`` spaced like the grid, and the
  end loops are shortest paths in disjoint ``Θ`` corridors
  (:func:`_guided_caps`). The rims of the ends lie where the surface turns
  from facing along the axis to facing sideways (convex shoulders), where
  hexahedra on a cube edge can have a positive Jacobian.
* **Untangling** (step 6) and midpoint subdivision of meshes that are coarse
  compared with the grid (the geometry is unchanged).

Sources: 000 = seed-000 dissertation notes §3; Crane, Weischedel, Wardetzky,
"Geodesics in heat", ACM TOG 32(5), 2013; Floater, "Mean value coordinates",
CAGD 20, 2003; Knupp, "Achieving finite element mesh quality via
optimization of the Jacobian matrix norm and associated quantities", IJNME
48, 2000 (corner scaled Jacobians).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from numba import njit
from scipy.sparse.linalg import factorized, splu

from ..errors import InputError
from .heat import (
    HeatGeodesics,
    _corner_cotangents,
    cotangent_laplacian,
    descent_path,
    face_gradient,
    mass_matrix,
)

__all__ = [
    "CUBE",
    "CUBE_EDGES",
    "CUBE_FACES",
    "FACE_EDGES",
    "HEAT_RUNS",
    "choose_corners",
    "cube_edges",
    "grid_to_hexes",
    "hex_parameterisation",
    "scaled_jacobian",
    "surface_patches",
]

#: corner k at (u, v, w) (marching-cubes order, 000 Fig. 3.2)
CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                 [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], np.int64)
#: edge k as (start corner, end corner) (000 §3.3)
CUBE_EDGES = np.array([(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
                       (0, 4), (1, 5), (2, 6), (3, 7)], np.int64)
#: face k as its corner loop (000 Table 3.2)
CUBE_FACES = np.array([(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)], np.int64)
#: the four edges bounding each face
FACE_EDGES = np.array([(0, 1, 2, 3), (4, 5, 6, 7), (0, 9, 4, 8), (1, 10, 5, 9), (2, 11, 6, 10), (3, 8, 7, 11)],
                      np.int64)
#: heat source corner → destination corners (000 Table 3.1, edge 10 = 2→6)
HEAT_RUNS = ((0, (1, 3, 4)), (2, (1, 3, 6)), (5, (1, 4, 6)), (7, (3, 4, 6)))

#: scaled Jacobian below which a cell counts as poor in ``info``
SJ_POOR = 0.2
#: untangling runs when a corner scaled Jacobian is below this, and aims above it
SJ_TARGET = 0.05
EDGE_GAP_MIN = 0.5  # untangling keeps each cube-edge gap at least this fraction of the even one
EDGE_GAP_POLISH = 0.35  # and the local search (:func:`_polish`) at least this one
#: seconds for all untangling of one parameterisation, by default (recipe ``body.untangle_limit``)
UNTANGLE_LIMIT = 90.0
#: the largest node grid parameterised (bounds memory and time before work starts)
MAX_NODES = 200_000
TETHER = 1.0  # weight of a surface node's move in its face map or along its edge, per grid cell squared


def _face_frames():
    """Per face: fixed axis, its value, the two in-face axes (p < q) and the outward loop."""
    frames = []
    for loop in CUBE_FACES:
        c = CUBE[loop]
        a = int(np.flatnonzero(np.all(c == c[0], axis=0))[0])
        p, q = [ax for ax in range(3) if ax != a]
        pts = c.astype(float)
        nrm = np.cross(pts[1] - pts[0], pts[2] - pts[1])
        out = pts.mean(0) - 0.5
        lo = tuple(int(x) for x in (loop if nrm @ out > 0 else loop[::-1]))
        frames.append((a, int(c[0, a]), p, q, lo))
    return frames


_FRAMES = _face_frames()


def _left_right():
    """For each directed cube edge, the face on its left / right (outward-oriented surface)."""
    left, right = np.empty(12, np.int64), np.empty(12, np.int64)
    for k, (a, b) in enumerate(CUBE_EDGES):
        for f, (*_, lo) in enumerate(_FRAMES):
            pairs = {(lo[i], lo[(i + 1) % 4]) for i in range(4)}
            if (a, b) in pairs:
                left[k] = f
            if (b, a) in pairs:
                right[k] = f
    return left, right


_LEFT, _RIGHT = _left_right()
#: for each VTK hexahedron corner, its three neighbours in right-handed order
_CORNER_NB = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7], [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]],
                      np.int64)


def _edge_name(k):
    a, b = CUBE_EDGES[k]
    return f"e{k} (corners {a}→{b})"


def _face_name(f):
    return f"f{f} (corners {'-'.join(str(c) for c in CUBE_FACES[f])})"


def _wrap(x):
    """Wrap to the half-open interval [−½, ½)."""
    return (np.asarray(x) + 0.5) % 1.0 - 0.5


# ----------------------------------------------------------------------------------------- checks


def _closed_mesh(vertices, faces):
    """Validate a closed, edge-manifold triangle mesh; return (v, f) with f oriented outward."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) < 4:
        raise InputError("a closed triangle mesh needs vertices (V, 3) and faces (F ≥ 4, 3); "
                         f"got {v.shape}, {f.shape}")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"face indices must lie in 0..{len(v) - 1}")
    if not np.all(np.isfinite(v)):
        raise InputError("the mesh has non-finite vertex coordinates")
    und = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, cnt = np.unique(und, axis=0, return_counts=True)
    if np.any(cnt != 2):
        raise InputError(f"the body is not a closed manifold mesh ({int(np.sum(cnt == 1))} open and "
                         f"{int(np.sum(cnt > 2))} non-manifold edges)")
    p = v[f]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    if vol < 0:
        f = f[:, ::-1].copy()
    return v, f


def _check_corners(corners, n_vertices):
    c = np.asarray(corners)
    if c.shape != (8,) or not np.issubdtype(c.dtype, np.integer):
        raise InputError(f"corners must be 8 vertex indices; got shape {c.shape}")
    c = c.astype(np.int64)
    bad = np.flatnonzero((c < 0) | (c >= n_vertices))
    if bad.size:
        raise InputError(f"corner {int(bad[0])} (vertex {int(c[bad[0]])}) is not a vertex of the mesh "
                         f"(0..{n_vertices - 1})")
    for i in range(8):
        for j in range(i + 1, 8):
            if c[i] == c[j]:
                raise InputError(f"corners {i} and {j} are the same vertex {int(c[i])}")
    return c


def _check_grid(grid):
    try:
        g = tuple(int(x) for x in grid)
        ok = len(g) == 3 and all(float(x) == int(x) for x in grid) and min(g) >= 1
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"grid must be three positive cell counts (nu, nv, nw); got {grid!r}")
    return g


def _check_paths(paths, corners, n_vertices):
    """Refuse paths that share a vertex other than a common corner (touch or cross)."""
    if len(paths) != 12:
        raise InputError(f"a hexahedron has 12 edges; got {len(paths)} paths")
    corner_of = {int(c): k for k, c in enumerate(corners)}
    owner = np.full(n_vertices, -1, np.int64)
    for k, path in enumerate(paths):
        p = np.asarray(path, np.int64)
        a, b = CUBE_EDGES[k]
        if p.ndim != 1 or len(p) < 2 or p[0] != corners[a] or p[-1] != corners[b]:
            raise InputError(f"path {k} must run from corner {a} to corner {b} (vertices {int(corners[a])} → "
                             f"{int(corners[b])})")
        if p.min() < 0 or p.max() >= n_vertices:
            raise InputError(f"path {k} has vertex indices outside 0..{n_vertices - 1}")
        if len(np.unique(p)) != len(p):
            raise InputError(f"edge {_edge_name(k)} visits a vertex twice")
        inner = p[1:-1]
        for x in inner:
            if int(x) in corner_of:
                raise InputError(f"edge {_edge_name(k)} passes through corner {corner_of[int(x)]} "
                                 f"(vertex {int(x)}); choose other corners")
        hit = inner[owner[inner] >= 0]
        if hit.size:
            o = int(owner[hit[0]])
            near = sorted(int(x) for x in set(CUBE_EDGES[o]) | set(CUBE_EDGES[k]))
            raise InputError(f"edges {_edge_name(o)} and {_edge_name(k)} touch or cross at vertex {int(hit[0])}; "
                             f"choose other corners around corners {near}")
        owner[inner] = k


def _directed_lookup(f, nv):
    """``left(p, q)``: the triangle holding each directed edge ``p[i] → q[i]`` (the one on its left)."""
    tri_of = np.repeat(np.arange(len(f)), 3)
    dkey = f.ravel() * nv + f[:, [1, 2, 0]].ravel()
    dorder = np.argsort(dkey)
    dsorted = dkey[dorder]

    def left(p, q):
        key = np.asarray(p, np.int64) * nv + np.asarray(q, np.int64)
        pos = np.minimum(np.searchsorted(dsorted, key), len(dsorted) - 1)
        miss = dsorted[pos] != key
        if np.any(miss):
            i = int(np.flatnonzero(miss)[0])
            raise InputError(f"a path steps from vertex {int(np.ravel(p)[i])} to {int(np.ravel(q)[i])}, "
                             "which is not a mesh edge")
        return tri_of[dorder[pos]]

    return left


def _flood(f, nv, paths):
    """Triangle patches of a closed mesh cut along the paths: ``(ncomp, comp (F,), left)``."""
    nf = len(f)
    tri_of = np.repeat(np.arange(nf), 3)
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    und = np.minimum(a, b) * nv + np.maximum(a, b)
    order = np.argsort(und, kind="stable")
    us = und[order]
    pkeys = [np.zeros(0, np.int64)]
    for p in paths:
        p = np.asarray(p, np.int64)
        pkeys.append(np.minimum(p[:-1], p[1:]) * nv + np.maximum(p[:-1], p[1:]))
    keep = ~np.isin(us[0::2], np.concatenate(pkeys))
    t1, t2 = tri_of[order[0::2]], tri_of[order[1::2]]
    adj = sp.coo_matrix((np.ones(int(keep.sum())), (t1[keep], t2[keep])), shape=(nf, nf))
    ncomp, comp = connected_components(adj, directed=False)
    return ncomp, comp, _directed_lookup(f, nv)


def _label_patches(v, f, paths):
    """Flood fill the triangles into patches and match them to the cube faces; (F,) labels 0..5."""
    ncomp, comp, tri_left = _flood(f, len(v), paths)
    left_c, right_c = np.empty(12, np.int64), np.empty(12, np.int64)
    for k, p in enumerate(paths):
        p = np.asarray(p, np.int64)
        lc = np.unique(comp[tri_left(p[:-1], p[1:])])
        rc = np.unique(comp[tri_left(p[1:], p[:-1])])
        if len(lc) != 1 or len(rc) != 1:
            raise InputError(f"edge {_edge_name(k)} borders more than two patches; the cube edges cross")
        left_c[k], right_c[k] = lc[0], rc[0]
    same = [k for k in range(12) if left_c[k] == right_c[k]]
    if ncomp != 6 or same:
        extra = f" (edge(s) {', '.join(_edge_name(k) for k in same)} have the same patch on both sides)" if same else ""
        raise InputError(f"the 12 cube edges split the surface into {ncomp} patches, not 6{extra}: "
                         "the corner choice folds a face; choose other corners")
    face_of = {}
    for k in range(12):
        for c, fc in ((left_c[k], _LEFT[k]), (right_c[k], _RIGHT[k])):
            if face_of.setdefault(int(c), int(fc)) != fc:
                raise InputError(f"the corner choice folds face {_face_name(int(fc))}: the patch on that side of "
                                 f"edge {_edge_name(k)} is also face {_face_name(face_of[int(c)])}; "
                                 "the corners are mirrored or out of order")
    if sorted(face_of.values()) != list(range(6)):  # pragma: no cover - implied by the checks above
        raise InputError("the corner choice folds a face: the patches do not match the six cube faces")
    labels = np.array([face_of[int(c)] for c in range(ncomp)], np.int64)[comp]
    for fc in range(6):  # every patch must be a disc: V − E + F = 1
        ft = f[labels == fc]
        e = np.unique(np.sort(np.concatenate([ft[:, [0, 1]], ft[:, [1, 2]], ft[:, [2, 0]]]), axis=1), axis=0)
        chi = len(np.unique(ft)) - len(e) + len(ft)
        if chi != 1:
            raise InputError(f"face {_face_name(fc)} is not a disc (Euler characteristic {chi}); "
                             "the body has handles or the corner choice folds the face")
    return labels


# ----------------------------------------------------------------------------------------- corners


def _areas(v, f):
    p = v[f]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def _pca_frame(v, f):
    """Area-weighted centroid and right-handed principal frame (columns u, v, w; w the longest axis).

    Eigenvectors of the area-weighted covariance of the triangle centroids;
    ``v`` and ``w`` point so that their largest component is positive and
    ``u = v × w``.
    """
    area = _areas(v, f)
    cen = v[f].mean(axis=1)
    c = (area[:, None] * cen).sum(0) / area.sum()
    d = cen - c
    cov = (d * area[:, None]).T @ d / area.sum()
    _, vec = np.linalg.eigh(cov)  # ascending variance
    w_ax, v_ax = vec[:, 2], vec[:, 1]
    w_ax = w_ax * np.sign(w_ax[np.argmax(np.abs(w_ax))])
    v_ax = v_ax * np.sign(v_ax[np.argmax(np.abs(v_ax))])
    return c, np.stack([np.cross(v_ax, w_ax), v_ax, w_ax], axis=1)


def choose_corners(vertices, faces) -> np.ndarray:
    """Cube corners at the principal-axis bounding box, each snapped to the nearest vertex.

    The frame is the eigenbasis of the area-weighted covariance of the
    triangle centroids: ``w`` the longest principal axis, ``v`` the middle
    one and ``u = v × w``, so ``(u, v, w)`` is right-handed. Box corner ``k``
    is ``c + Σ_a (lo_a + CUBE[k, a] (hi_a − lo_a)) axis_a`` with ``[lo, hi]``
    the extent of the vertices along each axis: 0–3 at ``w = lo``, 4–7 at
    ``w = hi``, ``k + 4`` above ``k`` (000 Fig. 3.2 order).

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int

    Returns
    -------
    (8,) int64
        Vertex index of each cube corner.

    Raises
    ------
    InputError
        When two box corners snap to the same vertex.
    """
    v, f = _closed_mesh(vertices, faces)
    c, R = _pca_frame(v, f)
    used = np.unique(f)
    proj = (v[used] - c) @ R
    lo, hi = proj.min(0), proj.max(0)
    box = c + (lo + CUBE * (hi - lo)) @ R.T
    d2 = ((v[used][None, :, :] - box[:, None, :]) ** 2).sum(-1)
    corners = used[np.argmin(d2, axis=1)].astype(np.int64)
    for i in range(8):
        for j in range(i + 1, 8):
            if corners[i] == corners[j]:
                raise InputError(f"box corners {i} and {j} snap to the same vertex {int(corners[i])}; "
                                 "pass the corners explicitly")
    return corners


# ----------------------------------------------------------------------------------------- cube edges


def _trace_edges(v, f, corners, heat=None):
    """The 12 geodesic paths of Table 3.1 (4 heat runs); returns (paths, number of Dijkstra fallbacks).

    Paths descend the heat distance by the steepest edge
    (:func:`porecad.param.heat.descent_path` with ``step="steepest"``): the
    smallest-neighbour rule sends the three paths of one source onto the same
    vertex next to it on coarse meshes (seen on the femur and on a
    32-sided cylinder), where the steepest edge keeps their directions apart.
    """
    heat = HeatGeodesics(v, f) if heat is None else heat
    paths = [None] * 12
    fallbacks = 0
    lookup = {(int(a), int(b)): k for k, (a, b) in enumerate(CUBE_EDGES)}
    for src, dests in HEAT_RUNS:
        dist = heat.distance([corners[src]])
        for dst in dests:
            path, fb = descent_path(dist, heat.graph, int(corners[dst]), int(corners[src]), return_fallback=True,
                                    step="steepest")
            fallbacks += int(fb)
            if (dst, src) in lookup:  # traced dest → source already runs the canonical way
                paths[lookup[(dst, src)]] = path
            else:
                paths[lookup[(src, dst)]] = path[::-1].copy()
    return paths, fallbacks


def _mesh_edges(v, f):
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    return e, np.maximum(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1), 1e-300)


def _shortest(n, e, ln, a, b, allowed):
    """Dijkstra edge path ``a → b`` through ``allowed`` vertices (None when unreachable)."""
    ok = allowed[e[:, 0]] & allowed[e[:, 1]]
    g = sp.coo_matrix((ln[ok], (e[ok, 0], e[ok, 1])), shape=(n, n)).tocsr()
    dist, pred = dijkstra(g, directed=False, indices=int(a), return_predecessors=True)
    if not np.isfinite(dist[b]):
        return None
    path = [int(b)]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    return np.asarray(path[::-1], np.int64)


def _periodic_angle(x, tri, cut):
    """Harmonic coordinate with period 1 around an annulus (the conjugate of the axial field).

    Minimises the Dirichlet energy ``Σ_f ∫|∇θ|²`` (cotangent stiffness) with
    natural boundary conditions, where ``θ`` jumps by 1 across ``cut`` (a
    vertex path from one boundary loop to the other): triangles on the left
    of the cut see ``θ − 1`` at the cut vertices. One vertex is pinned.
    """
    n = len(x)
    cut = np.asarray(cut, np.int64)
    on_cut = np.zeros(n, bool)
    on_cut[cut] = True
    left = _directed_lookup(tri, n)
    seeds_l = left(cut[:-1], cut[1:])
    seeds_r = left(cut[1:], cut[:-1])
    # triangles around the cut, joined across edges at a cut vertex that are not cut edges
    nt = len(tri)
    tri_of = np.repeat(np.arange(nt), 3)
    a, b = tri.ravel(), tri[:, [1, 2, 0]].ravel()
    und = np.minimum(a, b) * n + np.maximum(a, b)
    ckeys = np.minimum(cut[:-1], cut[1:]) * n + np.maximum(cut[:-1], cut[1:])
    order = np.argsort(und, kind="stable")
    us = und[order]
    first = np.ones(len(us), bool)
    first[1:] = us[1:] != us[:-1]
    pair = first[:-1] & ~first[1:]  # interior edges appear twice after sorting
    i1, i2 = order[:-1][pair], order[1:][pair]
    join = (on_cut[a[i1]] | on_cut[b[i1]]) & ~np.isin(und[i1], ckeys)
    adj = sp.coo_matrix((np.ones(int(join.sum())), (tri_of[i1][join], tri_of[i2][join])), shape=(nt, nt))
    _, comp = connected_components(adj, directed=False)
    lcomp = np.unique(comp[seeds_l])
    if np.any(np.isin(lcomp, comp[seeds_r])):
        raise InputError("the side region between the two end loops is not an annulus")
    is_left = np.isin(comp, lcomp) & np.any(on_cut[tri], axis=1)
    delta = np.where(is_left[:, None] & on_cut[tri], -1.0, 0.0)
    cots = _corner_cotangents(x, tri)
    rows, cols, vals = [], [], []
    rhs = np.zeros(n)
    for c in range(3):
        i, j = tri[:, (c + 1) % 3], tri[:, (c + 2) % 3]
        w = 0.5 * cots[:, c]
        rows += [i, j, i, j]
        cols += [i, j, j, i]
        vals += [w, w, -w, -w]
        dd = delta[:, (c + 1) % 3] - delta[:, (c + 2) % 3]
        rhs -= np.bincount(i, weights=w * dd, minlength=n) - np.bincount(j, weights=w * dd, minlength=n)
    K = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    keep = np.arange(1, n)
    theta = np.zeros(n)
    theta[keep] = splu(K[keep][:, keep].tocsc()).solve(rhs[keep])
    return theta


def _annulus_cut(n, e, ln, inner, l0, l1):
    """Shortest edge path from loop ``l0`` to loop ``l1`` whose inner vertices are all free (None if none)."""
    on0, on1 = np.zeros(n, bool), np.zeros(n, bool)
    on0[l0], on1[l1] = True, True
    # edges usable: inner–inner, and loop–inner as the first / last step
    ok = (inner[e[:, 0]] & inner[e[:, 1]]) | (on0[e[:, 0]] & inner[e[:, 1]]) | (inner[e[:, 0]] & on0[e[:, 1]]) \
        | (on1[e[:, 0]] & inner[e[:, 1]]) | (inner[e[:, 0]] & on1[e[:, 1]])
    g = sp.coo_matrix((ln[ok], (e[ok, 0], e[ok, 1])), shape=(n, n)).tocsr()
    g = g + g.T
    # loop-1 vertices must not be passed through: only entered
    dist, pred, _ = dijkstra(g, directed=True, indices=l0, return_predecessors=True, min_only=True)
    if not np.any(np.isfinite(dist[l1])):
        return None
    end = int(l1[np.argmin(dist[l1])])
    path = [end]
    while pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    path = np.asarray(path[::-1], np.int64)
    k = np.flatnonzero(on0[path])[-1]  # leave loop 0 once
    return path[k:]


def _guide_sides(v, f, corners, paths, beta=0.3):
    """Side edges e8–e11 as shortest paths in disjoint corridors of the side annulus.

    Conformal coordinates ``(w, θ)`` of the annulus between the end loops
    (e0–e3 and e4–e7): ``w`` harmonic with ``w = 0`` / ``1`` on the loops,
    ``θ`` its periodic conjugate (:func:`_periodic_angle`). Side edge ``k``
    from corner ``a`` (w = 0) to corner ``b`` (w = 1) is the shortest edge
    path among the vertices with ``|θ − θ_a − w Δ_k| ≤ beta · gap`` (``gap``
    the angular distance to the neighbouring lines, ``Δ_k`` the twist
    between its corners); corridors with ``beta < ½`` are disjoint, so the
    side edges cannot touch or cross.
    """
    nv = len(v)
    ncomp, comp, left = _flood(f, nv, paths[:8])
    sides = {}
    for k in range(8):
        p = paths[k]
        for cc, fc in ((np.unique(comp[left(p[:-1], p[1:])]), _LEFT[k]),
                       (np.unique(comp[left(p[1:], p[:-1])]), _RIGHT[k])):
            if len(cc) != 1:
                raise InputError(f"edge {_edge_name(k)} borders more than two regions; the end loops cross")
            sides.setdefault("side" if fc >= 2 else f"cap{fc}", set()).add(int(cc[0]))
    if ncomp != 3 or any(len(x) != 1 for x in sides.values()) or len({next(iter(x)) for x in sides.values()}) != 3:
        raise InputError(f"the end loops e0–e3 and e4–e7 split the surface into {ncomp} regions, not 3 "
                         "(two caps and the side): the corner choice folds a face; choose other corners")
    ann = next(iter(sides["side"]))
    loc, tri = np.unique(f[comp == ann], return_inverse=True)
    tri = tri.reshape(-1, 3)
    x = v[loc]
    n = len(loc)
    gl = np.full(nv, -1, np.int64)
    gl[loc] = np.arange(n)
    e, ln = _mesh_edges(x, tri)
    if n - len(e) + len(tri) != 0:
        raise InputError("the side region between the end loops is not an annulus")
    l0 = np.unique(gl[np.concatenate([paths[k] for k in range(4)])])
    l1 = np.unique(gl[np.concatenate([paths[k] for k in range(4, 8)])])
    if np.intersect1d(l0, l1).size:
        raise InputError("the end loops e0–e3 and e4–e7 touch; choose other corners")
    fixed = np.concatenate([l0, l1])
    w = _harmonic_map(x, tri, fixed, np.concatenate([np.zeros(len(l0)), np.ones(len(l1))])[:, None],
                      "cotangent")[:, 0]
    inner = np.ones(n, bool)
    inner[fixed] = False
    cl = gl[corners]
    cut = _annulus_cut(n, e, ln, inner, l0, l1)
    if cut is None:
        raise InputError("the end loops are not joined through the side region; choose other corners")
    theta = _periodic_angle(x, tri, cut)
    ta, tb = theta[cl[:4]], theta[cl[4:]]
    d = _wrap(tb - ta)
    twist = np.angle(np.mean(np.exp(2j * np.pi * d))) / (2 * np.pi)
    dk = twist + _wrap(d - twist)
    s = 1.0 if _wrap(ta[1] - ta[0]) > 0 else -1.0
    g0 = (s * (np.roll(ta, -1) - ta)) % 1.0  # gap between side edge k and k+1 at w = 0
    slope = s * (np.roll(dk, -1) - dk)
    if abs(g0.sum() - 1.0) > 1e-6 or np.any(g0 <= 0) or np.any(g0 + slope <= 0):
        raise InputError("the side edges e8–e11 would cross: corners 0–3 and 4–7 are twisted against each other; "
                         "choose other corners")
    out = list(paths)
    for k in range(4):
        a, b = cl[k], cl[k + 4]
        gk = _wrap(theta - (ta[k] + w * dk[k]))
        gap = np.minimum(g0[k] + w * slope[k], g0[k - 1] + w * slope[k - 1])
        for bt in (beta, 0.45):
            allowed = inner & (np.abs(gk) <= bt * np.maximum(gap, 1e-12))
            allowed[[a, b]] = True
            pth = _shortest(n, e, ln, a, b, allowed)
            if pth is not None:
                break
        else:
            raise InputError(f"side edge {_edge_name(k + 8)} finds no path in its corridor; the mesh is too coarse "
                             "between the end loops or the corners are badly placed")
        out[k + 8] = loc[pth]
    return out


def _edges_for_corners(v, f, corners, sides="auto", heat=None):
    """Table 3.1 geodesics; side edges geodesic, guided, or guided when the geodesic ones fail ("auto")."""
    paths, fallbacks = _trace_edges(v, f, corners, heat)
    if sides == "guided":
        paths = _guide_sides(v, f, corners, paths)
    try:
        _check_paths(paths, corners, len(v))
        labels = _label_patches(v, f, paths)
    except InputError as err:
        if sides != "auto":
            raise
        try:
            paths = _guide_sides(v, f, corners, paths)
        except InputError:
            raise err from None
        _check_paths(paths, corners, len(v))
        labels = _label_patches(v, f, paths)
    return paths, labels, fallbacks


def cube_edges(vertices, faces, corners, sides: str = "auto") -> list[np.ndarray]:
    """The 12 cube edges as geodesic vertex paths along mesh edges (000 §3.2–3.3, Table 3.1).

    Four heat-method runs (:class:`porecad.param.heat.HeatGeodesics`, one
    factorisation) from corners 0, 2, 5 and 7 give three edges each
    (0 → 1, 3, 4; 2 → 1, 3, 6; 5 → 1, 4, 6; 7 → 3, 4, 6); each path is traced
    from the destination down the distance (:func:`porecad.param.heat.descent_path`)
    and oriented to the canonical edge direction.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
        Closed, edge-manifold triangle mesh (any consistent orientation).
    corners : (8,) int
        Corner vertices in the order of 000 Fig. 3.2 (see module docstring).
    sides : {"auto", "geodesic", "guided"}
        Side edges e8–e11: the geodesics of Table 3.1, or shortest paths in
        conformal corridors (:func:`_guide_sides`), or the geodesics unless
        they fail the checks below.

    Returns
    -------
    list of 12 (n_k,) int64
        Path ``k`` runs from ``corners[CUBE_EDGES[k, 0]]`` to ``corners[CUBE_EDGES[k, 1]]``.

    Raises
    ------
    InputError
        One line naming the corner(s), edges or face when two paths touch or
        cross, a path passes through another corner, or the paths do not cut
        the surface into six discs bounded by the edges of Table 3.2 in the
        right orientation (a corner choice that folds a face).
    """
    if sides not in ("auto", "geodesic", "guided"):
        raise InputError(f"sides must be 'auto', 'geodesic' or 'guided'; got {sides!r}")
    v, f = _closed_mesh(vertices, faces)
    c = _check_corners(corners, len(v))
    paths, _, _ = _edges_for_corners(v, f, c, sides)
    return paths


def surface_patches(vertices, faces, paths) -> np.ndarray:
    """Face label of every triangle, (F,) int64 in 0..5 (000 §3.4, Table 3.2).

    A flood fill over triangles (connected components of the triangle
    adjacency graph without the path edges) gives the patches; the patch on
    the left of each directed path edge (outward orientation) is matched to
    the cube face on the left of that cube edge.

    Parameters
    ----------
    vertices, faces : closed triangle mesh
    paths : list of 12 vertex paths, e.g. from :func:`cube_edges`

    Raises
    ------
    InputError
        Paths that touch or cross, or do not cut six correctly oriented discs.
    """
    v, f = _closed_mesh(vertices, faces)
    if len(paths) != 12:
        raise InputError(f"a hexahedron has 12 edges; got {len(paths)} paths")
    paths = [np.asarray(p, np.int64).ravel() for p in paths]
    if any(len(p) < 2 for p in paths):
        raise InputError("every path needs at least two vertices")
    corners = np.empty(8, np.int64)
    for k, (a, b) in enumerate(CUBE_EDGES):
        corners[a], corners[b] = paths[k][0], paths[k][-1]
    _check_corners(corners, len(v))
    _check_paths(paths, corners, len(v))
    return _label_patches(v, f, paths)


# ----------------------------------------------------------------------------------------- the ends


class _Cylinder:
    """Conformal cylinder coordinates ``(W, Θ)`` of a closed genus-0 body between two end regions.

    ``W`` is harmonic on the surface with ``W = 0`` on the region ``r0`` and
    ``W = 1`` on ``r1`` (clipped cotangent weights: no interior extrema, so
    every level set is one loop around the body, the "dipole field" of 000
    §3.5); ``Θ`` (period 1) is its conjugate on the surface without the
    regions (:func:`_periodic_angle`), oriented counter-clockwise seen from
    ``+W`` (``∇Θ · (∇W × n) > 0``). ``sigma`` is the area-weighted mean of
    ``|∇Θ| / |∇W|``, so ``(σ W, Θ)`` is locally isotropic.
    """

    def __init__(self, v, f, r0, r1):
        n = len(v)
        r0, r1 = np.unique(r0), np.unique(r1)
        fixed = np.concatenate([r0, r1])
        vals = np.concatenate([np.zeros(len(r0)), np.ones(len(r1))])[:, None]
        self.W = _harmonic_map(v, f, fixed, vals, "cotangent")[:, 0]
        inr = np.zeros(n, bool)
        inr[fixed] = True
        keep = ~np.any(inr[f], axis=1)
        loc, tri = np.unique(f[keep], return_inverse=True)
        tri = tri.reshape(-1, 3)
        e, ln = _mesh_edges(v, f)
        full = sp.coo_matrix((ln, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
        dist, pred, _ = dijkstra(full, directed=False, indices=r0, return_predecessors=True, min_only=True)
        end = int(r1[np.argmin(dist[r1])])
        cut = [end]
        while pred[cut[-1]] >= 0:
            cut.append(int(pred[cut[-1]]))
        cut = np.asarray(cut[::-1], np.int64)
        cut = cut[~inr[cut]]  # region 0 → region 1, outside both
        gl = np.full(n, -1, np.int64)
        gl[loc] = np.arange(len(loc))
        theta = _periodic_angle(v[loc], tri, gl[cut])
        x = v[loc]
        gW = face_gradient(x, tri, self.W[loc])
        tf = theta[tri]
        tf = tf[:, :1] + _wrap(tf - tf[:, :1])  # undo the jump inside each face
        pts = x[tri]
        nrm = np.cross(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0])
        dbl = np.linalg.norm(nrm, axis=1)
        nu = nrm / np.maximum(dbl, 1e-300)[:, None]
        gT = np.zeros((len(tri), 3))
        for c in range(3):
            gT += tf[:, c, None] * np.cross(nu, pts[:, (c + 2) % 3] - pts[:, (c + 1) % 3])
        gT /= np.maximum(dbl, 1e-300)[:, None]
        if np.sum(dbl * np.einsum("ij,ij->i", gT, np.cross(gW, nu))) < 0:
            theta = -theta
        self.Theta = np.full(n, np.nan)
        self.Theta[loc] = theta % 1.0
        gw = np.linalg.norm(gW, axis=1)
        ok = gw > 0
        self.sigma = float(np.sum(dbl[ok] * np.linalg.norm(gT[ok], axis=1) / gw[ok]) / np.sum(dbl[ok]))


def _end_regions(v, f, frame, length, cos_max=0.5):
    """The two ends: vertices around the extreme points whose normals face along ``∓w``.

    Vertex normals are smoothed by one heat step ``(A − ℓ² L) n_s = A n``
    (``ℓ`` = ``length``); an end is the connected set of vertices around the
    lowest (highest) vertex along ``w`` with ``n_s · (∓w) ≥ cos_max``, its
    holes filled (so it is a disc).
    """
    n = len(v)
    c, R = frame
    p = v[f]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    A = mass_matrix(v, f)
    solve = factorized((sp.diags(A) - length ** 2 * cotangent_laplacian(v, f)).tocsc())
    vn = np.stack([solve(A * vn[:, d]) for d in range(3)], axis=1)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    nw = vn @ R[:, 2]
    proj = (v - c) @ R[:, 2]
    e, _ = _mesh_edges(v, f)

    def grow(seed, mask):
        mask = mask.copy()
        mask[seed] = True
        k = mask[e[:, 0]] & mask[e[:, 1]]
        _, lab = connected_components(sp.coo_matrix((np.ones(int(k.sum())), (e[k, 0], e[k, 1])), shape=(n, n)),
                                      directed=False)
        inside = lab == lab[seed]
        out = ~inside
        k = out[e[:, 0]] & out[e[:, 1]]
        nc, lab = connected_components(sp.coo_matrix((np.ones(int(k.sum())), (e[k, 0], e[k, 1])), shape=(n, n)),
                                       directed=False)
        big = np.argmax(np.bincount(lab[out], minlength=nc))
        return np.flatnonzero(~(out & (lab == big)))

    r0 = grow(int(np.argmin(proj)), nw <= -cos_max)
    r1 = grow(int(np.argmax(proj)), nw >= cos_max)
    touch = np.zeros(n, bool)
    touch[r0] = True
    k = touch[e[:, 0]] | touch[e[:, 1]]
    if np.isin(r1, e[k].ravel()).any():
        raise InputError("the two ends of the body meet; the body is too short for one hexahedral block")
    return r0, r1


def _end_corners(v, f, grid, cyl, frame, offset):
    """Corners just outside the two ends, spaced in ``Θ`` like the grid.

    Corners 0–3 at ``W = offset/σ``, 4–7 at ``W = 1 − offset/σ`` (no twist),
    at ``Θ = θ_0 + (0, n_u, n_u + n_v, 2n_u + n_v) / (2(n_u + n_v))`` so the
    side faces get conformally square-ish cells; ``θ_0`` puts corner 0 in the
    ``(−u, −v)`` direction of the principal frame at mid-length. Each corner
    is the vertex nearest to its target in ``(σ W, Θ)``.
    """
    nu_, nv_, _ = grid
    c, R = frame
    ok = np.isfinite(cyl.Theta) & (cyl.W > 0) & (cyl.W < 1)
    cand = np.flatnonzero(ok)
    mid = cand[np.argsort(np.abs(cyl.W[cand] - 0.5))[:max(8, len(cand) // 50)]]
    rel = (v[mid] - c) @ R
    th0 = cyl.Theta[mid[np.argmax(-rel[:, 0] - rel[:, 1])]]
    gaps = np.array([nu_, nv_, nu_, nv_], float) / (2.0 * (nu_ + nv_))
    targets = th0 + np.concatenate([[0.0], np.cumsum(gaps)[:3]])
    corners = np.empty(8, np.int64)
    for k in range(8):
        wl = offset / cyl.sigma if k < 4 else 1.0 - offset / cyl.sigma
        d2 = (cyl.sigma * (cyl.W[cand] - wl)) ** 2 + _wrap(cyl.Theta[cand] - targets[k % 4]) ** 2
        corners[k] = cand[np.argmin(d2)]
    return _check_corners(corners, len(v))


def _guided_caps(v, f, corners, cyl, beta=0.3):
    """End loops e0–e3 and e4–e7 as shortest paths in disjoint corridors around each end.

    Edge ``a → b`` uses the vertices with ``Θ`` strictly between ``Θ_a`` and
    ``Θ_b`` (counter-clockwise), outside the end regions (``0 < W < 1``) and
    at most ``δ = beta (Θ_b − Θ_a) / σ`` beyond the line joining the
    corners' ``W`` in ``(Θ, W)`` towards the side (widened when that leaves
    no path). The corridors of one loop are disjoint.
    """
    n = len(v)
    e, ln = _mesh_edges(v, f)
    T = cyl.Theta
    ok = np.isfinite(T) & (cyl.W > 0.0) & (cyl.W < 1.0)
    out = [None] * 8
    for k in range(8):
        a, b = (int(x) for x in CUBE_EDGES[k])
        ca, cb = corners[a], corners[b]
        span = (T[cb] - T[ca]) % 1.0
        if not 0.0 < span < 0.75:
            raise InputError(f"corners {a} and {b} are not in counter-clockwise order around the body")
        rel = (T - T[ca]) % 1.0
        level = cyl.W[ca] + (cyl.W[cb] - cyl.W[ca]) * rel / span
        delta = beta * span / max(cyl.sigma, 1e-12)
        beyond = (cyl.W - level) if k < 4 else (level - cyl.W)
        for grow in (1.0, 2.0, 4.0):
            allowed = ok & (rel > 0) & (rel < span) & (beyond <= grow * delta)
            allowed[corners] = False
            allowed[[ca, cb]] = True
            pth = _shortest(n, e, ln, ca, cb, allowed)
            if pth is not None:
                break
        else:
            raise InputError(f"edge {_edge_name(k)} finds no path in its corridor near the end of the body")
        out[k] = pth
    return out


# ----------------------------------------------------------------------------------------- surface grid


def _arc_param(v, path):
    """Normalised arc-length parameter τ ∈ [0, 1] of each path vertex."""
    seg = np.linalg.norm(np.diff(v[path], axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(path))


def _mean_value_weights(x, tri):
    """Directed mean-value weights ``w_ij = (tan(γ/2) + tan(δ/2)) / |x_i − x_j|`` (Floater 2003)."""
    rows, cols, vals = [], [], []
    for c in range(3):
        i, j, k = tri[:, c], tri[:, (c + 1) % 3], tri[:, (c + 2) % 3]
        e1, e2 = x[j] - x[i], x[k] - x[i]
        l1, l2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
        th = np.arccos(np.clip(np.einsum("ij,ij->i", e1, e2) / np.maximum(l1 * l2, 1e-300), -1.0, 1.0))
        t = np.tan(0.5 * th)
        rows += [i, i]
        cols += [j, k]
        vals += [t / np.maximum(l1, 1e-300), t / np.maximum(l2, 1e-300)]
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def _cot_weights(x, tri):
    """Symmetric cotangent weights ``½ (cot α + cot β)`` clipped to a small positive floor."""
    cots = _corner_cotangents(x, tri)
    i = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    j = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    w = 0.5 * np.concatenate([cots[:, 0], cots[:, 1], cots[:, 2]])
    key = np.minimum(i, j) * len(x) + np.maximum(i, j)
    uk, inv = np.unique(key, return_inverse=True)
    ws = np.bincount(inv, weights=w)
    ws = np.maximum(ws, 1e-3 * float(np.mean(np.abs(ws))))
    a, b = uk // len(x), uk % len(x)
    return np.concatenate([a, b]), np.concatenate([b, a]), np.concatenate([ws, ws])


def _harmonic_map(x, tri, bnd, bnd_val, kind):
    """Discrete harmonic extension: ``Σ_j w_ij (u_j − u_i) = 0`` at the free vertices, ``u = bnd_val`` on ``bnd``."""
    n = len(x)
    rows, cols, vals = (_cot_weights if kind == "cotangent" else _mean_value_weights)(x, tri)
    W = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    Lm = (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()
    bnd_val = np.asarray(bnd_val, float).reshape(len(bnd), -1)
    u = np.zeros((n, bnd_val.shape[1]))
    u[bnd] = bnd_val
    free = np.ones(n, bool)
    free[bnd] = False
    ii = np.flatnonzero(free)
    if ii.size:
        rhs = -(Lm[ii][:, bnd] @ bnd_val)
        u[ii] = splu(Lm[ii][:, ii].tocsc()).solve(np.ascontiguousarray(rhs))
    return u


def _signed_areas(uv, tri):
    p = uv[tri]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


class _PatchLocator:
    """Point location in a planar patch map ``uv`` and the piecewise-linear map back to 3D.

    Triangles are binned by their bounding boxes on a ``G × G`` grid over the
    unit square; a query tests the triangles of its bin and keeps the one it
    is least outside of (barycentrics clamped). Degenerate (zero-area)
    triangles of the map are skipped.
    """

    def __init__(self, x, tri, uv):
        a2 = 2.0 * _signed_areas(uv, tri)
        tid = np.flatnonzero(np.abs(a2) > 1e-14)
        self.P = uv[tri[tid]]
        self.a2 = a2[tid]
        self.X = x[tri[tid]]
        B = np.stack([self.P[:, 1] - self.P[:, 0], self.P[:, 2] - self.P[:, 0]], axis=2)  # (T, 2, 2)
        E = np.stack([self.X[:, 1] - self.X[:, 0], self.X[:, 2] - self.X[:, 0]], axis=2)  # (T, 3, 2)
        self.M = E @ np.linalg.inv(B)  # d x / d (s, t), (T, 3, 2)
        G = int(np.clip(np.sqrt(len(tid)) / 2, 4, 128))
        self.G = G
        lo = np.clip(np.floor((self.P.min(1) - 1e-9) * G), 0, G - 1).astype(np.int64)
        hi = np.clip(np.floor((self.P.max(1) + 1e-9) * G), 0, G - 1).astype(np.int64)
        ni, nj = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
        cnt = ni * nj
        rep = np.repeat(np.arange(len(tid)), cnt)
        off = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        b = (lo[rep, 0] + off // nj[rep]) * G + lo[rep, 1] + off % nj[rep]
        order = np.argsort(b, kind="stable")
        self.bin_tri = rep[order]
        self.bin_ptr = np.concatenate([[0], np.cumsum(np.bincount(b, minlength=G * G))])

    def _bary(self, t, q):
        P, a2 = self.P[t], self.a2[t]
        l0 = ((P[:, 1, 0] - q[:, 0]) * (P[:, 2, 1] - q[:, 1]) - (P[:, 1, 1] - q[:, 1]) * (P[:, 2, 0] - q[:, 0])) / a2
        l1 = ((P[:, 2, 0] - q[:, 0]) * (P[:, 0, 1] - q[:, 1]) - (P[:, 2, 1] - q[:, 1]) * (P[:, 0, 0] - q[:, 0])) / a2
        return np.stack([l0, l1, 1.0 - l0 - l1], axis=1)

    def locate(self, q):
        """Triangle (of the non-degenerate ones) and clamped barycentrics of each query, (m,), (m, 3)."""
        q = np.asarray(q, float).reshape(-1, 2)
        m = len(q)
        G = self.G
        bi = np.clip(np.floor(q * G), 0, G - 1).astype(np.int64)
        b = bi[:, 0] * G + bi[:, 1]
        cnt = self.bin_ptr[b + 1] - self.bin_ptr[b]
        best_t = np.zeros(m, np.int64)
        best_b = np.zeros((m, 3))
        best_s = np.full(m, -np.inf)
        if cnt.sum():
            qi = np.repeat(np.arange(m), cnt)
            off = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            t = self.bin_tri[self.bin_ptr[b][qi] + off]
            bc = self._bary(t, q[qi])
            sc = bc.min(1)
            order = np.lexsort((-sc, qi))
            first = np.ones(len(order), bool)
            first[1:] = qi[order][1:] != qi[order][:-1]
            sel = order[first]
            best_t[qi[sel]], best_b[qi[sel]], best_s[qi[sel]] = t[sel], bc[sel], sc[sel]
        for i in np.flatnonzero(best_s < -1e-9):  # outside every triangle of its bin: search all
            bc = self._bary(np.arange(len(self.P)), np.repeat(q[i:i + 1], len(self.P), axis=0))
            k = int(np.argmax(bc.min(1)))
            if bc[k].min() > best_s[i]:
                best_t[i], best_b[i] = k, bc[k]
        bb = np.clip(best_b, 0.0, None)
        return best_t, bb / bb.sum(1, keepdims=True)

    def evaluate(self, q):
        """3D points and their derivatives ``d x / d (s, t)``, (m, 3), (m, 3, 2)."""
        t, bc = self.locate(q)
        return np.einsum("mk,mkd->md", bc, self.X[t]), self.M[t]


def _surface_grid(v, f, labels, paths, grid, weights):
    """Boundary nodes of the (nu+1, nv+1, nw+1) grid (NaN inside).

    Returns ``(nodes, kinds, locators, taus)``: the weights used per face,
    a :class:`_PatchLocator` per face and the arc-length parameters of the paths.
    """
    N = np.asarray(grid, np.int64)
    nodes = np.full((N[0] + 1, N[1] + 1, N[2] + 1, 3), np.nan)
    taus = [_arc_param(v, p) for p in paths]
    for k, (a, b) in enumerate(CUBE_EDGES):  # cube edges: sampled once by arc length, shared by both faces
        d = int(np.flatnonzero(CUBE[a] != CUBE[b])[0])
        sgn = int(CUBE[b, d] - CUBE[a, d])
        t = np.linspace(0.0, 1.0, N[d] + 1)
        pts = np.stack([np.interp(t, taus[k], v[paths[k], dd]) for dd in range(3)], axis=1)
        idx = np.tile(CUBE[a] * N, (N[d] + 1, 1))
        idx[:, d] += sgn * np.arange(N[d] + 1)
        nodes[idx[:, 0], idx[:, 1], idx[:, 2]] = pts
    kinds, locators = [], []
    for fc, (ax, val, p, q, lo) in enumerate(_FRAMES):
        loc, tri = np.unique(f[labels == fc], return_inverse=True)
        tri = tri.reshape(-1, 3)
        x = v[loc]
        gl = np.full(len(v), -1, np.int64)
        gl[loc] = np.arange(len(loc))
        bidx, buv = [], []
        for k in FACE_EDGES[fc]:
            a, b = CUBE_EDGES[k]
            A = CUBE[a, [p, q]].astype(float)
            B = CUBE[b, [p, q]].astype(float)
            bidx.append(gl[paths[k]])
            buv.append(A + taus[k][:, None] * (B - A))
        bidx, first = np.unique(np.concatenate(bidx), return_index=True)
        buv = np.concatenate(buv)[first]
        c2 = CUBE[list(lo)][:, [p, q]].astype(float)
        expect = np.sign(np.sum(c2[:, 0] * np.roll(c2[:, 1], -1) - np.roll(c2[:, 0], -1) * c2[:, 1]))
        for kind in ((weights, "mean-value") if weights == "cotangent" else (weights,)):
            uv = _harmonic_map(x, tri, bidx, buv, kind)
            flipped = int(np.sum(_signed_areas(uv, tri) * expect < -1e-12))
            if not flipped:
                break
        else:
            raise InputError(f"face {_face_name(fc)} cannot be mapped to a square without folds "
                             f"({flipped} flipped triangles)")
        kinds.append(kind)
        locator = _PatchLocator(x, tri, uv)
        locators.append(locator)
        ns, nt = int(N[p]), int(N[q])
        if ns > 1 and nt > 1:
            ii, jj = np.meshgrid(np.arange(1, ns), np.arange(1, nt), indexing="ij")
            pts, _ = locator.evaluate(np.stack([ii.ravel() / ns, jj.ravel() / nt], axis=1))
            idx = np.zeros((ii.size, 3), np.int64)
            idx[:, ax] = val * N[ax]
            idx[:, p], idx[:, q] = ii.ravel(), jj.ravel()
            nodes[idx[:, 0], idx[:, 1], idx[:, 2]] = pts
    return nodes, kinds, locators, taus


# ----------------------------------------------------------------------------------------- volume grid


def _laplace_volume(nodes):
    """Fill the interior nodes by the 6-neighbour discrete Laplace equation (000 eq. 3.2.3), one sparse solve.

    The interior unknowns satisfy ``6 x_ijk − Σ_{interior nb} x = Σ_{boundary nb} x``, i.e.
    ``(T_u ⊗ I ⊗ I + I ⊗ T_v ⊗ I + I ⊗ I ⊗ T_w) x = b`` with ``T = tridiag(−1, 2, −1)``.
    """
    n = np.array(nodes.shape[:3]) - 2  # interior counts
    if np.any(n < 1):
        return nodes
    out = nodes.copy()
    inner = (slice(1, -1),) * 3
    b = out.copy()
    b[inner] = 0.0
    rhs = (b[:-2, 1:-1, 1:-1] + b[2:, 1:-1, 1:-1] + b[1:-1, :-2, 1:-1] + b[1:-1, 2:, 1:-1]
           + b[1:-1, 1:-1, :-2] + b[1:-1, 1:-1, 2:]).reshape(-1, 3)

    def T(m):
        return sp.diags([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])

    I = [sp.identity(int(m)) for m in n]
    A = (sp.kron(sp.kron(T(n[0]), I[1]), I[2]) + sp.kron(sp.kron(I[0], T(n[1])), I[2])
         + sp.kron(sp.kron(I[0], I[1]), T(n[2]))).tocsc()
    out[inner] = splu(A).solve(np.ascontiguousarray(rhs)).reshape(*n, 3)
    return out


# ----------------------------------------------------------------------------------------- hexes and quality


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


def _corner_jacobians(P, hexes, grad: bool = False):
    """Scaled Jacobian at the 8 corners of each hex, (H, 8); with ``grad`` also its gradient pieces.

    Corner ``a`` with neighbours ``(b, c, d)``: ``J = ê₁ · (ê₂ × ê₃)`` with
    ``ê_k = e_k / |e_k|``; ``∂J/∂e_k = (I − ê_k ê_kᵀ)(ê_{k+1} × ê_{k+2}) / |e_k|``.
    """
    Js, parts = [], []
    for c in range(8):
        a = hexes[:, c]
        nb = hexes[:, _CORNER_NB[c]]
        e = P[nb] - P[a][:, None, :]
        ln = np.maximum(np.linalg.norm(e, axis=2, keepdims=True), 1e-300)
        u = e / ln
        crs = (np.cross(u[:, 1], u[:, 2]), np.cross(u[:, 2], u[:, 0]), np.cross(u[:, 0], u[:, 1]))
        Js.append(np.einsum("ij,ij->i", u[:, 0], crs[0]))
        if grad:
            g = [(cr - u[:, k] * np.einsum("ij,ij->i", u[:, k], cr)[:, None]) / ln[:, k] for k, cr in enumerate(crs)]
            parts.append((a, nb, g))
    return np.stack(Js, axis=1), parts


def _sample_derivatives(ts=(0.0, 1 / 3, 0.5, 2 / 3, 1.0), corners: bool = False):
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


_SAMPLE_D = _sample_derivatives()
_SAMPLE_D_ALL = _sample_derivatives(corners=True)  # for the (unscaled) determinant, which sees collapsed edges


def _sample_jacobians(P, hexes, D=_SAMPLE_D, grad: bool = False):
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


def _sample_dets(P, hexes, D=_SAMPLE_D_ALL, grad: bool = False):
    """Determinant ``det[∂x/∂u, ∂x/∂v, ∂x/∂w]`` at the samples of ``D``, (H, S); with ``grad`` (H, S, 8, 3)."""
    e = np.einsum("skc,hcd->hskd", D, P[hexes])
    c0 = np.cross(e[:, :, 1], e[:, :, 2])
    det = np.einsum("hsd,hsd->hs", e[:, :, 0], c0)
    if not grad:
        return det
    g = np.stack([c0, np.cross(e[:, :, 2], e[:, :, 0]), np.cross(e[:, :, 0], e[:, :, 1])], axis=2)
    return det, np.einsum("skc,hskd->hscd", D, g)


@njit(cache=True)
def _min_sample_ratio(P, hexes, D, vref):  # pragma: no cover - compiled
    """Minimum of ``det / vref`` of :func:`_sample_dets` over the given hexahedra (numba; for the polish loop)."""
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
def _min_sample_jacobian(P, hexes, D):  # pragma: no cover - compiled
    """Minimum of :func:`_sample_jacobians` over the given hexahedra (numba; for the polish loop)."""
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
        e = x[h[:, _CORNER_NB[c]]] - x[h[:, c]][:, None, :]
        ln = np.linalg.norm(e, axis=2, keepdims=True)
        e = np.where(ln > 0, e / np.where(ln > 0, ln, 1.0), 0.0)
        out = np.minimum(out, np.linalg.det(e))
    return out


# ----------------------------------------------------------------------------------------- untangling


def _boundary_dofs(shape, locators, paths, taus, v):
    """Movable boundary nodes: face nodes with their ``(s, t)``, cube-edge nodes with their ``τ``."""
    N = np.array(shape) - 1
    ids = np.arange(int(np.prod(shape))).reshape(shape)
    faces, edges = [], []
    for fc, (ax, val, p, q, _) in enumerate(_FRAMES):
        ns, nt = int(N[p]), int(N[q])
        if ns < 2 or nt < 2:
            continue
        sl = [slice(1, -1)] * 3
        sl[ax] = int(val * N[ax])
        ii, jj = np.meshgrid(np.arange(1, ns) / ns, np.arange(1, nt) / nt, indexing="ij")
        faces.append((ids[tuple(sl)].ravel(), np.stack([ii.ravel(), jj.ravel()], 1), locators[fc], (ns, nt)))
    for k, (a, b) in enumerate(CUBE_EDGES):
        d = int(np.flatnonzero(CUBE[a] != CUBE[b])[0])
        n = int(N[d])
        if n < 2:
            continue
        idx = np.tile(CUBE[a] * N, (n - 1, 1))
        idx[:, d] += int(CUBE[b, d] - CUBE[a, d]) * np.arange(1, n)
        edges.append((ids[idx[:, 0], idx[:, 1], idx[:, 2]], np.arange(1, n) / n, v[paths[k]], taus[k], n))
    return ids, faces, edges


def _untangle(nodes, locators, paths, taus, v, mu=0.2, kappa=20.0, mu2=SJ_TARGET, kappa2=2000.0, maxiter=300,
              tether=TETHER, deadline=None, progress=None):
    """Raise low corner Jacobians; interior nodes move freely, surface nodes slide on their face or edge.

    Minimises
    ``E = Σ_grid edges |x_i − x_j|² / h² + κ Σ_corners (μ − J)₊² + κ₂ Σ_corners (μ₂ − J)₊²
    + τ_t Σ_surface nodes |n ⊙ (s − s₀)|²``
    (``J`` the corner scaled Jacobian, ``h²`` the mean squared grid edge; the
    last term tethers each surface node to its place in the harmonic face map
    or on its cube edge, in grid cells: without it the edge springs pull the
    surface nodes together where the surface is concave, the boundary quads
    cut the body's corners and the grid loses volume — 11 % of the femur at
    5×7×20 — by an amount that depends on the L-BFGS path, hence on the SciPy
    version)
    over the interior nodes, the face nodes (by their ``(s, t)`` in the
    face's harmonic map, so they stay on their patch) and the cube-edge
    nodes (by their arc-length parameter ``τ``); the corners stay. The first
    term is the grid Laplace energy whose minimiser for the interior is 000
    eq. 3.2.3; the others are barriers on flat and inverted corners. A
    barrier ``κ₂ Σ (EDGE_GAP_MIN − n Δτ)₊²`` keeps the cube-edge nodes from
    bunching (uneven edge gaps fold the cells beside the edge inside).
    L-BFGS-B with restarts (the surface map is piecewise linear, line
    searches stall at its kinks), then a derivative-free local search on the
    nodes of the corners still below ``μ₂`` (:func:`_polish`).

    ``deadline`` (a :func:`time.perf_counter` value) stops the descent and
    the search at the first iteration past it; ``progress(done, total)`` is
    called per L-BFGS iteration (total: the iteration budget).

    Returns the node grid, the number of L-BFGS iterations and whether the deadline stopped it.
    """
    from scipy.optimize import minimize

    shape = nodes.shape[:3]
    flat = nodes.reshape(-1, 3).copy()
    _, hexes = grid_to_hexes(nodes)
    ids, faces, edges = _boundary_dofs(shape, locators, paths, taus, v)
    inner = ids[1:-1, 1:-1, 1:-1].ravel()
    x0 = np.concatenate([flat[inner].ravel()] + [fc[1].ravel() for fc in faces] + [ed[1] for ed in edges])
    sizes = [inner.size * 3] + [fc[1].size for fc in faces] + [ed[1].size for ed in edges]
    cuts = np.cumsum(sizes)[:-1]
    bounds = [(None, None)] * (inner.size * 3) + [(1e-6, 1 - 1e-6)] * int(sum(sizes[1:]))
    ea, eb = [], []
    for ax in range(3):
        sa, sb = [slice(None)] * 3, [slice(None)] * 3
        sa[ax], sb[ax] = slice(0, -1), slice(1, None)
        ea.append(ids[tuple(sa)].ravel())
        eb.append(ids[tuple(sb)].ravel())
    ea, eb = np.concatenate(ea), np.concatenate(eb)
    h2 = float(np.mean(np.sum((flat[ea] - flat[eb]) ** 2, axis=1)))

    def assemble(x):
        parts = np.split(x, cuts)
        P = flat.copy()
        P[inner] = parts[0].reshape(-1, 3)
        jac = []
        for fc, st in zip(faces, parts[1:1 + len(faces)]):
            X, M = fc[2].evaluate(st.reshape(-1, 2))
            P[fc[0]] = X
            jac.append(M)
        for ed, t in zip(edges, parts[1 + len(faces):]):
            poly, tau = ed[2], ed[3]
            P[ed[0]] = np.stack([np.interp(t, tau, poly[:, d]) for d in range(3)], 1)
            seg = np.clip(np.searchsorted(tau, t, side="right") - 1, 0, len(tau) - 2)
            jac.append((poly[seg + 1] - poly[seg]) / np.maximum(tau[seg + 1] - tau[seg], 1e-12)[:, None])
        return P, jac

    def fun(x):
        P, jac = assemble(x)
        D = P[eb] - P[ea]
        E = float(np.sum(D * D)) / h2
        G = np.zeros_like(P)
        np.add.at(G, eb, 2.0 * D / h2)
        np.add.at(G, ea, -2.0 * D / h2)
        J, parts = _corner_jacobians(P, hexes, True)
        v1, v2 = np.maximum(mu - J, 0.0), np.maximum(mu2 - J, 0.0)
        E += kappa * float(np.sum(v1 ** 2)) + kappa2 * float(np.sum(v2 ** 2))
        for c, (a, nb, gs) in enumerate(parts):
            w = -2.0 * (kappa * v1[:, c] + kappa2 * v2[:, c])
            act = w != 0
            if np.any(act):
                for k in range(3):
                    gk = gs[k][act] * w[act, None]
                    np.add.at(G, nb[act, k], gk)
                    np.add.at(G, a[act], -gk)
        if watch.size:  # the map's Jacobian inside the watched cells (the corners alone let a cell fold inside)
            Js, Gs = _sample_jacobians(P, hexes[watch], grad=True)
            vs = np.maximum(mu2 - Js, 0.0)
            E += kappa2 * float(np.sum(vs ** 2))
            Gc = np.einsum("hs,hscd->hcd", -2.0 * kappa2 * vs, Gs)
            # and its determinant against the cell's size: the scaled one stays finite where an
            # edge of the cell collapses, and the map can fold between the samples there
            Ds, Gd = _sample_dets(P, hexes[watch], grad=True)
            vd = np.maximum(mu2 - Ds / vref[:, None], 0.0)
            E += kappa2 * float(np.sum(vd ** 2))
            Gc += np.einsum("hs,hscd->hcd", -2.0 * kappa2 * vd / vref[:, None], Gd)
            np.add.at(G, hexes[watch], Gc)
        out = [G[inner].ravel()]
        xs = np.split(x, cuts)
        for fc, M, st, st0 in zip(faces, jac[:len(faces)], xs[1:1 + len(faces)], x0s[1:1 + len(faces)]):
            sc = np.tile(np.asarray(fc[3], float), len(st) // 2)
            dd = (st - st0) * sc
            E += tether * float(np.sum(dd * dd))
            out.append(np.einsum("mdk,md->mk", M, G[fc[0]]).ravel() + 2.0 * tether * dd * sc)
        for ed, T, t, t0_ in zip(edges, jac[len(faces):], xs[1 + len(faces):], x0s[1 + len(faces):]):
            n = ed[4]
            d = np.maximum(EDGE_GAP_MIN - n * np.diff(np.concatenate([[0.0], t, [1.0]])), 0.0)
            E += kappa2 * float(np.sum(d * d))
            dt = (t - t0_) * n
            E += tether * float(np.sum(dt * dt))
            g = np.einsum("md,md->m", T, G[ed[0]]) + 2.0 * kappa2 * n * (d[1:] - d[:-1]) + 2.0 * tether * dt * n
            out.append(g)
        return E, np.concatenate(out)

    x0s = np.split(x0, cuts)

    budget_all = 5 * 10 * maxiter
    count = [0]
    stopped = [False]

    def cb(_):
        count[0] += 1
        if progress is not None and count[0] % 10 == 0:
            progress(min(count[0], budget_all), budget_all)
        if deadline is not None and time.perf_counter() > deadline:
            stopped[0] = True
            raise StopIteration

    def descend(x, budget):
        it, best = 0, fun(x)[0]
        for _ in range(10):
            if stopped[0]:
                break
            res = minimize(fun, x, jac=True, method="L-BFGS-B", bounds=bounds, callback=cb,
                           options={"maxiter": budget, "maxcor": 10})
            it += int(res.nit)
            improved = res.fun < best - 1e-6 * abs(best)
            if res.fun <= best:
                x, best = res.x, float(res.fun)
            if res.success or not improved or it >= budget:
                break
        return x, it

    # corners first; then, while some cell's map folds (or nearly) inside although its corners are
    # valid, add the interior samples of those cells (and of their neighbours) to the barrier
    watch, vref = np.zeros(0, np.int64), np.ones(0)
    x, nit = descend(x0, maxiter)
    cell_ids = np.arange(len(hexes)).reshape(tuple(np.array(shape) - 1))
    for _ in range(4):
        if stopped[0]:
            break
        P, _ = assemble(x)
        dets = _sample_dets(P, hexes)
        vol = np.maximum(np.abs(dets).mean(axis=1), 1e-300)
        low = np.flatnonzero((_sample_jacobians(P, hexes).min(axis=1) < mu2) | (dets.min(axis=1) / vol < mu2))
        low = np.setdiff1d(low, watch)
        if not low.size:
            break
        mask = np.zeros(cell_ids.shape, bool)
        mask.ravel()[low] = True
        grown = mask.copy()  # one layer of neighbours: moving a node changes all cells around it
        for ax in range(3):
            a = [slice(None)] * 3
            b = [slice(None)] * 3
            a[ax], b[ax] = slice(1, None), slice(None, -1)
            grown[tuple(a)] |= mask[tuple(b)]
            grown[tuple(b)] |= mask[tuple(a)]
        watch = np.union1d(watch, cell_ids[grown].ravel())
        vref = vol[watch]  # the cells' mean |det|, fixed during the descent
        x, it = descend(x, maxiter)
        nit += it
    P, _ = assemble(x)
    if not stopped[0]:
        P = _polish(P, hexes, faces, edges, np.split(x, cuts), inner, mu2, watch=watch, vref=vref,
                    deadline=deadline)
    if progress is not None:
        progress(budget_all, budget_all)
    return P.reshape(nodes.shape), nit, stopped[0] or (deadline is not None and time.perf_counter() > deadline)


@njit(cache=True)
def _min_corner_jacobian(P, hexes, nbtab):  # pragma: no cover - compiled
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


def _gap_short(t, r, q, n):
    """Whether moving the ``r``-th interior cube-edge node to ``τ = q`` shortens a gap below ``EDGE_GAP_POLISH / n``."""
    lo = t[r - 1] if r > 0 else 0.0
    hi = t[r + 1] if r + 1 < len(t) else 1.0
    new = min(q - lo, hi - q)
    return new * n < EDGE_GAP_POLISH and new < min(t[r] - lo, hi - t[r])  # a short gap may still grow


def _polish(P, hexes, faces, edges, parts, inner, target, rounds=30, watch=None, vref=None, deadline=None):
    """Local search on the nodes of the corners below ``target``: maximise the minimum Jacobian of their cells.

    Each movable node of such a corner tries steps along its own coordinates
    (3D for interior nodes, ``(s, t)`` for face nodes, ``τ`` for edge nodes)
    of ½, ¼, ⅛ and 1/16 of the local spacing, and keeps the best step that
    raises the minimum corner Jacobian over the (up to 8) cells around it.
    Derivative-free, so the kinks of the piecewise-linear surface do not stall it.
    The cells in ``watch`` also count their Jacobian at the interior samples
    (:func:`_sample_jacobians`): all 8 nodes of such a cell with a sample
    below ``target`` are tried.
    """
    P = P.copy()
    watched = np.zeros(len(hexes), bool)
    vcell = np.ones(len(hexes))
    if watch is not None:
        watched[np.asarray(watch, np.int64)] = True
        vcell[np.asarray(watch, np.int64)] = vref
    n = len(P)
    kind = np.zeros(n, np.int64)  # 0 fixed, 1 interior, 2 face, 3 edge
    where = np.zeros((n, 2), np.int64)
    kind[inner] = 1
    where[inner, 1] = np.arange(inner.size)
    st = [parts[1 + i].reshape(-1, 2).copy() for i in range(len(faces))]
    tt = [parts[1 + len(faces) + i].copy() for i in range(len(edges))]
    for fi, fc in enumerate(faces):
        kind[fc[0]] = 2
        where[fc[0], 0], where[fc[0], 1] = fi, np.arange(fc[0].size)
    for ei, ed in enumerate(edges):
        kind[ed[0]] = 3
        where[ed[0], 0], where[ed[0], 1] = ei, np.arange(ed[0].size)
    order = np.argsort(hexes.ravel(), kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(hexes.ravel(), minlength=n))])
    cell_of = order // 8

    def cells(a):
        return cell_of[ptr[a]:ptr[a + 1]]

    def local_min(cs):
        val = float(_min_corner_jacobian(P, hexes[cs], _CORNER_NB))
        cw = cs[watched[cs]]
        if cw.size:
            val = min(val, float(_min_sample_jacobian(P, hexes[cw], _SAMPLE_D)),
                      float(_min_sample_ratio(P, hexes[cw], _SAMPLE_D_ALL, vcell[cw])))
        return val

    steps8 = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, -1], [1, -1], [-1, 1]], float)
    for _ in range(rounds):
        if deadline is not None and time.perf_counter() > deadline:
            break
        J = _corner_jacobians(P, hexes)[0]
        bad = np.argwhere(J < target)
        wi = np.flatnonzero(watched)
        if wi.size:
            low = np.minimum(_sample_jacobians(P, hexes[wi]).min(axis=1),
                             _sample_dets(P, hexes[wi]).min(axis=1) / vcell[wi])
            bad_in = wi[low < target]
        else:
            bad_in = wi
        if not len(bad) and not bad_in.size:
            break
        cand = set(int(x) for x in hexes[bad[:, 0], bad[:, 1]])
        cand.update(int(x) for x in hexes[bad_in].ravel())
        for h, c in bad:
            cand.update(int(x) for x in hexes[h, _CORNER_NB[c]])
        moved = False
        for a in sorted(cand):
            k = kind[a]
            if k == 0:
                continue
            cs = cells(a)
            base = local_min(cs)
            keep = P[a].copy()
            if k == 1:
                nb = np.unique(hexes[cs])
                dirs = np.vstack([np.eye(3), -np.eye(3)]) * float(np.mean(np.linalg.norm(P[nb] - P[a], axis=1)))
                cur = P[a].copy()
            elif k == 2:
                fi, r = where[a]
                dirs = steps8 / np.array(faces[fi][3], float)
                cur = st[fi][r].copy()
            else:
                ei, r = where[a]
                dirs = np.array([[1.0], [-1.0]]) / edges[ei][4]
                cur = np.array([tt[ei][r]])
            best_val, best = base, None
            for frac in (0.5, 0.25, 0.125, 0.0625):
                for d in dirs:
                    q = cur + frac * d
                    if k == 1:
                        P[a] = q
                    elif np.any(q <= 1e-6) or np.any(q >= 1 - 1e-6):
                        continue
                    elif k == 3 and _gap_short(tt[ei], r, q[0], edges[ei][4]):
                        continue
                    elif k == 2:
                        P[a] = faces[fi][2].evaluate(q)[0][0]
                    else:
                        poly, tau = edges[ei][2], edges[ei][3]
                        P[a] = [np.interp(q[0], tau, poly[:, dd]) for dd in range(3)]
                    val = local_min(cs)
                    if val > best_val + 1e-9:
                        best_val, best = val, (q.copy(), P[a].copy())
                P[a] = keep
            if best is not None:
                P[a] = best[1]
                if k == 2:
                    st[fi][r] = best[0]
                elif k == 3:
                    tt[ei][r] = best[0][0]
                moved = True
        if not moved:
            break
    return P


# ----------------------------------------------------------------------------------------- driver


def _untangle_estimate(nodes, locators, v):
    """Seconds the untangling may take: one timed energy-like evaluation × a typical iteration count.

    The L-BFGS descent evaluates the energy about 1.1 times per iteration and
    typically needs a few hundred iterations (about ``0.6 (nodes)^⅓ · 40``
    measured on the femur and on noisy blobs); one evaluation is dominated by
    the corner Jacobians with their gradient and the face-map lookups, which
    are timed here once.
    """
    t = time.perf_counter()
    pts, hexes = grid_to_hexes(nodes)
    _corner_jacobians(pts, hexes, True)
    _sample_jacobians(pts, hexes[: max(1, len(hexes) // 4)])
    q = np.full((max(1, len(pts) // 3), 2), 0.5)
    locators[0].evaluate(q)
    per = 2.0 * (time.perf_counter() - t) + 5e-6 * len(pts)  # + the L-BFGS-B step itself
    iters = 25.0 * float(len(pts)) ** (1.0 / 3.0)
    return per * 1.1 * iters


def _refine(v, f, grid, max_faces=200_000):
    """Midpoint-subdivide while the mean edge is longer than ⅖ of the mean boundary-cell side.

    The boundary cell side is ``√(area / n_quads)`` with
    ``n_quads = 2 (n_u n_v + n_v n_w + n_w n_u)``; subdivision keeps the
    geometry (and the original vertices first) and gives the cube edges and
    corridors room on coarse meshes.
    """
    nu_, nv_, nw_ = grid
    side = np.sqrt(_areas(v, f).sum() / (2.0 * (nu_ * nv_ + nv_ * nw_ + nw_ * nu_)))
    k = 0
    import trimesh.remesh

    while len(f) * 4 <= max_faces:
        _, ln = _mesh_edges(v, f)
        if ln.mean() <= 0.4 * side:
            break
        v, f = trimesh.remesh.subdivide(v, f)
        v, f = np.asarray(v, np.float64), np.asarray(f, np.int64)
        k += 1
    return v, f, k


def hex_parameterisation(vertices, faces, grid=(5, 7, 20), corners=None, weights: str = "cotangent",
                         untangle: bool = True, subdivide: bool = True, untangle_limit: float | None = UNTANGLE_LIMIT,
                         progress=None):
    """Structured hexahedral grid of a closed body (000 ch.3, §3.0–3.6).

    Stages: corners → 12 cube edges → six face patches → surface grid
    (per-patch harmonic map to the unit square; *deviates* from the "evenly
    offset interception" of 000 §3.5, see the module docstring) → interior
    nodes by the discrete Laplace equation ``x_ijk = Σ_{6 neighbours} x / 6``
    (000 eq. 3.2.3) in one sparse solve → untangling where a corner scaled
    Jacobian is below 0.05.

    Automatic corners (``corners=None``) try, in order, the principal-axis
    box (:func:`choose_corners`, Table 3.1 geodesics, guided side edges
    where the geodesic ones fail) and corners just outside the two ends of
    the body at three distances (module docstring); the first grid whose
    every hexahedron has a positive scaled Jacobian is returned, else the
    best one found.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
        Closed, edge-manifold, genus-0 triangle mesh.
    grid : (nu, nv, nw)
        Cells along u, v, w (000: the femur at 5×7×20 and 5×10×60).
    corners : (8,) int, optional
        Cube corner vertices (000 Fig. 3.2 order, right-handed, indices of
        ``vertices``); default automatic.
    weights : {"cotangent", "mean-value"}
        Patch map weights: clipped cotangent (falls back to mean-value for a
        patch where a triangle flips) or mean-value.
    untangle : bool
        Run the untangling step (:func:`_untangle`) when a corner scaled
        Jacobian is below 0.05.
    subdivide : bool
        Midpoint-subdivide meshes that are coarse compared with the grid
        (:func:`_refine`); vertex indices of the input stay valid.
    untangle_limit : float or None
        Seconds for all untangling (every corner choice tried shares them;
        default :data:`UNTANGLE_LIMIT`; ``None``: no limit). A choice whose
        untangling the limit stops is kept only if its grid is valid, and its
        rejection says so.
    progress : callable, optional
        ``progress(stage, done, total)`` per stage (``setup``, ``corners``,
        ``geodesics``, ``surface grid``, ``volume``, ``untangle``); before the
        untangling, the stage name carries the estimated time
        (``untangle ~N s``, also in ``info["estimates"]``).

    Returns
    -------
    nodes : (nu+1, nv+1, nw+1, 3) float64
        ``nodes[i, j, k]`` at ``(u, v, w) = (i/nu, j/nv, k/nw)``; the six
        boundary slices lie on the surface.
    info : dict
        ``corners``; ``corner_choice`` ("given", "box" or "ends (offset …)");
        ``grid``; ``vertices``, ``faces`` (the mesh the paths and labels
        refer to: the input, or its subdivision), ``subdivisions``; ``paths``
        (12 vertex paths); ``patch_labels`` (per face of ``faces``);
        ``patch_maps`` (weights used per face); ``path_fallbacks`` (Dijkstra
        paths in the heat runs); ``times`` (s: ``setup`` (mesh checks and
        subdivision), ``corners`` (corner choices tried and not kept),
        ``geodesics`` (corners and cube edges of the kept choice, heat
        factorisation included), ``patches``, ``surface_grid``, ``volume``,
        ``untangle``, ``total``);
        ``min_scaled_jacobian``, ``fraction_below_0.2`` (cells with scaled
        Jacobian < 0.2), ``min_scaled_jacobian_laplace`` (before
        untangling), ``untangle_iterations``; ``nodes``, ``boundary_nodes``,
        ``interior_nodes``, ``hexes``; ``rejected`` (corner choices that
        failed, with their reason).

    Raises
    ------
    InputError
        Bad mesh, grid or corners; given corners whose cube edges touch,
        cross or fold a face; no automatic corner choice that works.
    """
    if weights not in ("cotangent", "mean-value"):
        raise InputError(f"weights must be 'cotangent' or 'mean-value'; got {weights!r}")
    N = _check_grid(grid)
    if int(np.prod(np.array(N) + 1)) > MAX_NODES:
        raise InputError(f"a {N[0]}x{N[1]}x{N[2]} grid has more than {MAX_NODES:,} nodes; use a coarser grid")
    if untangle_limit is not None and not (isinstance(untangle_limit, (int, float)) and np.isfinite(untangle_limit)
                                           and untangle_limit > 0):
        raise InputError(f"the untangle time limit must be a positive number of seconds, got {untangle_limit!r}")

    def report(stage, done=1, total=1):
        if progress is not None:
            progress(stage, done, total)

    t_start = time.perf_counter()
    deadline = None if untangle_limit is None else float(untangle_limit)  # seconds left for untangling
    estimates = {}
    report("setup", 0, 1)
    v, f = _closed_mesh(vertices, faces)
    given = None if corners is None else _check_corners(corners, len(v))
    nsub = 0
    if subdivide:
        v, f, nsub = _refine(v, f, N)
    frame = _pca_frame(v, f)
    lazy = {}
    t_setup = time.perf_counter() - t_start
    report("setup", 1, 1)

    def box_edges(c):
        if "heat" not in lazy:
            lazy["heat"] = HeatGeodesics(v, f)
        paths, labels, fb = _edges_for_corners(v, f, c, "auto", lazy["heat"])
        return c, paths, labels, fb

    def end_edges(offset):
        if "cyl" not in lazy:
            side = np.sqrt(_areas(v, f).sum() / (2.0 * (N[0] * N[1] + N[1] * N[2] + N[2] * N[0])))
            lazy["cyl"] = _Cylinder(v, f, *_end_regions(v, f, frame, length=0.4 * side))
        c = _end_corners(v, f, N, lazy["cyl"], frame, offset)
        paths = _guided_caps(v, f, c, lazy["cyl"]) + [None] * 4
        paths = _guide_sides(v, f, c, paths)
        _check_paths(paths, c, len(v))
        return c, paths, _label_patches(v, f, paths), 0

    if given is not None:
        tries = [("given", lambda: box_edges(given))]
    else:
        tries = [("box", lambda: box_edges(choose_corners(v, f)))]
        tries += [(f"ends (offset {o:g})", lambda o=o: end_edges(o)) for o in (0.01, 0.005, 0.02)]
    best, rejected = None, []
    t_tried = 0.0  # time of the corner choices that were tried and not kept
    for n_try, (name, make) in enumerate(tries):
        report("corners", n_try, len(tries))
        t0 = time.perf_counter()
        try:
            c, paths, labels, fb = make()
        except InputError as err:
            if given is not None:
                raise
            rejected.append((name, str(err)))
            t_tried += time.perf_counter() - t0
            continue
        t1 = time.perf_counter()
        report("geodesics", 1, 1)
        nodes, kinds, locators, taus = _surface_grid(v, f, labels, paths, N, weights)
        t2 = time.perf_counter()
        report("surface grid", 1, 1)
        nodes = _laplace_volume(nodes)
        t3 = time.perf_counter()
        pts, hexes = grid_to_hexes(nodes)
        sj0 = float(scaled_jacobian(pts, hexes).min())
        si0 = float(_sample_jacobians(pts, hexes).min())
        nit, stopped = 0, False
        report("volume", 1, 1)
        if untangle and min(sj0, si0) < SJ_TARGET:
            est = _untangle_estimate(nodes, locators, v)
            left = None if deadline is None else max(deadline, 0.0)
            estimates[name] = est if left is None else min(est, left)
            stage = f"untangle ~{estimates[name]:.0f} s"
            nodes, nit, stopped = _untangle(nodes, locators, paths, taus, v,
                                            deadline=None if left is None else time.perf_counter() + left,
                                            progress=(lambda d, t, s_=stage: report(s_, d, t)))
        t4 = time.perf_counter()
        if deadline is not None and untangle and min(sj0, si0) < SJ_TARGET:
            deadline -= t4 - t3
        pts, hexes = grid_to_hexes(nodes)
        sj = scaled_jacobian(pts, hexes)
        si = float(_sample_jacobians(pts, hexes).min())  # inside the cells
        cand = dict(name=name, corners=c, paths=paths, labels=labels, fallbacks=fb, kinds=kinds, nodes=nodes,
                    sj=sj, sj0=sj0, si=si, q=min(float(sj.min()), si), nit=nit, stopped=stopped,
                    times={"geodesics": t1 - t0, "surface_grid": t2 - t1, "volume": t3 - t2, "untangle": t4 - t3})
        if best is None or cand["q"] > best["q"]:
            if best is not None:
                t_tried += sum(best["times"].values())
            best = cand
        else:
            t_tried += sum(cand["times"].values())
        if best["q"] > 0:
            break
        why = f"min scaled Jacobian {float(sj.min()):.3g} (corners), {si:.3g} (inside)"
        if stopped:
            why += f" when the untangling stopped at its time limit ({untangle_limit:g} s in all)"
        rejected.append((name, why))
        if deadline is not None and deadline <= 0 and untangle:
            break  # no time left to untangle another choice
    report("corners", len(tries), len(tries))
    if best is None:
        raise InputError("no automatic corner choice gives a valid cube: "
                         + "; ".join(f"{n}: {m}" for n, m in rejected) + "; pass corners explicitly")
    tp = time.perf_counter()
    _label_patches(v, f, best["paths"])  # timed once for the report (the check ran inside the corner stage)
    t_patches = time.perf_counter() - tp
    nodes, sj = best["nodes"], best["sj"]
    N_arr = np.array(N)
    n_all = int(np.prod(N_arr + 1))
    n_in = int(np.prod(np.maximum(N_arr - 1, 0)))
    times = {"setup": t_setup, "corners": t_tried, **best["times"], "patches": t_patches}
    times["geodesics"] = max(times["geodesics"] - t_patches, 0.0)
    times["total"] = time.perf_counter() - t_start
    info = {
        "corners": best["corners"],
        "corner_choice": best["name"],
        "grid": N,
        "vertices": v,
        "faces": f,
        "subdivisions": nsub,
        "paths": best["paths"],
        "patch_labels": best["labels"],
        "patch_maps": best["kinds"],
        "path_fallbacks": int(best["fallbacks"]),
        "times": times,
        "min_scaled_jacobian": float(sj.min()),
        "min_scaled_jacobian_inside": best["si"],
        f"fraction_below_{SJ_POOR:g}": float(np.mean(sj < SJ_POOR)),
        "min_scaled_jacobian_laplace": best["sj0"],
        "untangle_iterations": best["nit"],
        "untangle_stopped": bool(best.get("stopped", False)),
        "estimates": estimates,
        "nodes": n_all,
        "boundary_nodes": n_all - n_in,
        "interior_nodes": n_in,
        "hexes": int(sj.size),
        "rejected": [r for r in rejected if r[0] != best["name"]],
    }
    return nodes, info
