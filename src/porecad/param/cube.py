"""The cube of the hexahedral parameterisation: labels, checks of corners and paths, face patches, corners (000 ch.3).

Cube labelling (000 Fig. 3.2, marching-cubes convention): corner ``k`` sits at
``(u, v, w)`` = ``CUBE[k]`` with 0 = (0,0,0), 1 = (1,0,0), 2 = (1,1,0),
3 = (0,1,0) and ``k + 4`` = corner ``k`` at ``w = 1``; edges e0 = 0–1, e1 = 1–2,
e2 = 2–3, e3 = 3–0, e4 = 4–5, e5 = 5–6, e6 = 6–7, e7 = 7–4, e8 = 0–4, e9 = 1–5,
e10 = 2–6, e11 = 3–7; faces f0 = 0-1-2-3 (w = 0), f1 = 4-5-6-7 (w = 1),
f2 = 0-1-5-4 (v = 0), f3 = 1-2-6-5 (u = 1), f4 = 2-3-7-6 (v = 1),
f5 = 3-0-4-7 (u = 0).

The twelve cube edges cut the surface into six patches (000 §3.4, Table 3.2),
found by a flood fill over triangles that does not cross a path edge (the
"in-plane growing" of 000 §3.2.2.2): :func:`label_patches`. Automatic corners
sit at the principal-axis box (:func:`choose_corners`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..mesh.operators import face_areas

__all__ = ["CORNER_NEIGHBOURS", "CUBE", "CUBE_EDGES", "CUBE_FACES", "FACE_EDGES", "FRAMES", "HEAT_RUNS", "LEFT_FACE",
           "RIGHT_FACE", "check_corners", "check_grid", "check_paths", "choose_corners", "closed_mesh",
           "directed_lookup", "edge_name", "face_name", "flood_patches", "label_patches", "pca_frame", "wrap_half"]

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


FRAMES = _face_frames()


def _left_right():
    """For each directed cube edge, the face on its left / right (outward-oriented surface)."""
    left, right = np.empty(12, np.int64), np.empty(12, np.int64)
    for k, (a, b) in enumerate(CUBE_EDGES):
        for f, (*_, lo) in enumerate(FRAMES):
            pairs = {(lo[i], lo[(i + 1) % 4]) for i in range(4)}
            if (a, b) in pairs:
                left[k] = f
            if (b, a) in pairs:
                right[k] = f
    return left, right


LEFT_FACE, RIGHT_FACE = _left_right()
#: for each VTK hexahedron corner, its three neighbours in right-handed order
CORNER_NEIGHBOURS = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7], [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]],
                      np.int64)


def edge_name(k):
    a, b = CUBE_EDGES[k]
    return f"e{k} (corners {a}→{b})"


def face_name(f):
    return f"f{f} (corners {'-'.join(str(c) for c in CUBE_FACES[f])})"


def wrap_half(x):
    """Wrap to the half-open interval [−½, ½)."""
    return (np.asarray(x) + 0.5) % 1.0 - 0.5


def closed_mesh(vertices, faces):
    """Validate a closed, edge-manifold, connected genus-0 triangle mesh; return (v, f) with f oriented outward.

    The genus from the Euler characteristic ``V − E + F = 2 − 2 g`` of the
    one closed surface: a cube map (six disc patches) exists only for g = 0.
    """
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
    used = np.unique(f)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    n_parts, _ = connected_components(sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(v),) * 2),
                                        directed=False)
    n_parts -= len(v) - len(used)  # unreferenced vertices are parts of their own
    if n_parts > 1:
        raise InputError(f"the body has {n_parts} separate parts; a cube map needs one closed surface")
    chi = len(used) - len(und) // 2 + len(f)  # Euler characteristic V - E + F (each edge listed twice in und)
    genus = (2 - chi) // 2
    if genus != 0:
        raise InputError(f"the body has genus {genus} ({genus} handle(s) or through-hole(s)): a cube map needs a "
                         "genus-0 body (no holes through it); infill, TIS and ARBF take any closed body")
    p = v[f]
    vol = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    if vol < 0:
        f = f[:, ::-1].copy()
    return v, f


def check_corners(corners, n_vertices):
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


def check_grid(grid):
    try:
        g = tuple(int(x) for x in grid)
        ok = len(g) == 3 and all(float(x) == int(x) for x in grid) and min(g) >= 1
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"grid must be three positive cell counts (nu, nv, nw); got {grid!r}")
    return g


def check_paths(paths, corners, n_vertices):
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
            raise InputError(f"edge {edge_name(k)} visits a vertex twice")
        inner = p[1:-1]
        for x in inner:
            if int(x) in corner_of:
                raise InputError(f"edge {edge_name(k)} passes through corner {corner_of[int(x)]} "
                                 f"(vertex {int(x)}); choose other corners")
        hit = inner[owner[inner] >= 0]
        if hit.size:
            o = int(owner[hit[0]])
            near = sorted(int(x) for x in set(CUBE_EDGES[o]) | set(CUBE_EDGES[k]))
            raise InputError(f"edges {edge_name(o)} and {edge_name(k)} touch or cross at vertex {int(hit[0])}; "
                             f"choose other corners around corners {near}")
        owner[inner] = k


def directed_lookup(f, nv):
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


def flood_patches(f, nv, paths):
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
    return ncomp, comp, directed_lookup(f, nv)


def label_patches(v, f, paths):
    """Flood fill the triangles into patches and match them to the cube faces; (F,) labels 0..5."""
    ncomp, comp, tri_left = flood_patches(f, len(v), paths)
    left_c, right_c = np.empty(12, np.int64), np.empty(12, np.int64)
    for k, p in enumerate(paths):
        p = np.asarray(p, np.int64)
        lc = np.unique(comp[tri_left(p[:-1], p[1:])])
        rc = np.unique(comp[tri_left(p[1:], p[:-1])])
        if len(lc) != 1 or len(rc) != 1:
            raise InputError(f"edge {edge_name(k)} borders more than two patches; the cube edges cross")
        left_c[k], right_c[k] = lc[0], rc[0]
    same = [k for k in range(12) if left_c[k] == right_c[k]]
    if ncomp != 6 or same:
        extra = f" (edge(s) {', '.join(edge_name(k) for k in same)} have the same patch on both sides)" if same else ""
        raise InputError(f"the 12 cube edges split the surface into {ncomp} patches, not 6{extra}: "
                         "the corner choice folds a face; choose other corners")
    face_of = {}
    for k in range(12):
        for c, fc in ((left_c[k], LEFT_FACE[k]), (right_c[k], RIGHT_FACE[k])):
            if face_of.setdefault(int(c), int(fc)) != fc:
                raise InputError(f"the corner choice folds face {face_name(int(fc))}: the patch on that side of "
                                 f"edge {edge_name(k)} is also face {face_name(face_of[int(c)])}; "
                                 "the corners are mirrored or out of order")
    if sorted(face_of.values()) != list(range(6)):  # pragma: no cover - implied by the checks above
        raise InputError("the corner choice folds a face: the patches do not match the six cube faces")
    labels = np.array([face_of[int(c)] for c in range(ncomp)], np.int64)[comp]
    for fc in range(6):  # every patch must be a disc: V − E + F = 1
        ft = f[labels == fc]
        e = np.unique(np.sort(np.concatenate([ft[:, [0, 1]], ft[:, [1, 2]], ft[:, [2, 0]]]), axis=1), axis=0)
        chi = len(np.unique(ft)) - len(e) + len(ft)
        if chi != 1:
            raise InputError(f"face {face_name(fc)} is not a disc (Euler characteristic {chi}); "
                             "the body has handles or the corner choice folds the face")
    return labels


def pca_frame(v, f):
    """Area-weighted centroid and right-handed principal frame (columns u, v, w; w the longest axis).

    Eigenvectors of the area-weighted covariance of the triangle centroids;
    ``v`` and ``w`` point so that their largest component is positive and
    ``u = v × w``.
    """
    area = face_areas(v, f)
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
    v, f = closed_mesh(vertices, faces)
    c, R = pca_frame(v, f)
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
