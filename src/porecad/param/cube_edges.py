"""The twelve cube edges of the hexahedral parameterisation as vertex paths (000 §3.2–3.3, Table 3.1).

Geodesic edges from four heat sources (corners 0, 2, 5, 7, an inscribed
tetrahedron, so every cube edge has one source end), by the heat method
(:mod:`porecad.param.heat`); where they fail the checks, side edges guided
by the conformal coordinates ``(w, θ)`` of the annulus between the two end
loops (:func:`guide_sides`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse.linalg import splu

from ..errors import InputError
from ..mesh.operators import corner_cotangents, cotangent_laplacian
from .cube import (
    CUBE_EDGES,
    HEAT_RUNS,
    LEFT_FACE,
    RIGHT_FACE,
    check_corners,
    check_paths,
    closed_mesh,
    directed_lookup,
    edge_name,
    flood_patches,
    label_patches,
    wrap_half,
)
from .heat import HeatGeodesics, descent_path
from .patch_maps import harmonic_map

__all__ = ["cube_edges", "edges_for_corners", "guide_sides", "mesh_edges", "periodic_angle", "shortest_path",
           "surface_patches", "trace_edges"]


def trace_edges(v, f, corners, heat=None):
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


def mesh_edges(v, f):
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    return e, np.maximum(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1), 1e-300)


def shortest_path(n, e, ln, a, b, allowed):
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


def periodic_angle(x, tri, cut):
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
    left = directed_lookup(tri, n)
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
    cots = corner_cotangents(x, tri)
    rhs = np.zeros(n)
    for c in range(3):
        i, j = tri[:, (c + 1) % 3], tri[:, (c + 2) % 3]
        w = 0.5 * cots[:, c]
        dd = delta[:, (c + 1) % 3] - delta[:, (c + 2) % 3]
        rhs -= np.bincount(i, weights=w * dd, minlength=n) - np.bincount(j, weights=w * dd, minlength=n)
    K = -cotangent_laplacian(x, tri)  # the cotangent stiffness
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


def guide_sides(v, f, corners, paths, beta=0.3):
    """Side edges e8–e11 as shortest paths in disjoint corridors of the side annulus.

    Conformal coordinates ``(w, θ)`` of the annulus between the end loops
    (e0–e3 and e4–e7): ``w`` harmonic with ``w = 0`` / ``1`` on the loops,
    ``θ`` its periodic conjugate (:func:`periodic_angle`). Side edge ``k``
    from corner ``a`` (w = 0) to corner ``b`` (w = 1) is the shortest edge
    path among the vertices with ``|θ − θ_a − w Δ_k| ≤ beta · gap`` (``gap``
    the angular distance to the neighbouring lines, ``Δ_k`` the twist
    between its corners); corridors with ``beta < ½`` are disjoint, so the
    side edges cannot touch or cross.
    """
    nv = len(v)
    ncomp, comp, left = flood_patches(f, nv, paths[:8])
    sides = {}
    for k in range(8):
        p = paths[k]
        for cc, fc in ((np.unique(comp[left(p[:-1], p[1:])]), LEFT_FACE[k]),
                       (np.unique(comp[left(p[1:], p[:-1])]), RIGHT_FACE[k])):
            if len(cc) != 1:
                raise InputError(f"edge {edge_name(k)} borders more than two regions; the end loops cross")
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
    e, ln = mesh_edges(x, tri)
    if n - len(e) + len(tri) != 0:
        raise InputError("the side region between the end loops is not an annulus")
    l0 = np.unique(gl[np.concatenate([paths[k] for k in range(4)])])
    l1 = np.unique(gl[np.concatenate([paths[k] for k in range(4, 8)])])
    if np.intersect1d(l0, l1).size:
        raise InputError("the end loops e0–e3 and e4–e7 touch; choose other corners")
    fixed = np.concatenate([l0, l1])
    w = harmonic_map(x, tri, fixed, np.concatenate([np.zeros(len(l0)), np.ones(len(l1))])[:, None],
                      "cotangent")[:, 0]
    inner = np.ones(n, bool)
    inner[fixed] = False
    cl = gl[corners]
    cut = _annulus_cut(n, e, ln, inner, l0, l1)
    if cut is None:
        raise InputError("the end loops are not joined through the side region; choose other corners")
    theta = periodic_angle(x, tri, cut)
    ta, tb = theta[cl[:4]], theta[cl[4:]]
    d = wrap_half(tb - ta)
    twist = np.angle(np.mean(np.exp(2j * np.pi * d))) / (2 * np.pi)
    dk = twist + wrap_half(d - twist)
    s = 1.0 if wrap_half(ta[1] - ta[0]) > 0 else -1.0
    g0 = (s * (np.roll(ta, -1) - ta)) % 1.0  # gap between side edge k and k+1 at w = 0
    slope = s * (np.roll(dk, -1) - dk)
    if abs(g0.sum() - 1.0) > 1e-6 or np.any(g0 <= 0) or np.any(g0 + slope <= 0):
        raise InputError("the side edges e8–e11 would cross: corners 0–3 and 4–7 are twisted against each other; "
                         "choose other corners")
    out = list(paths)
    for k in range(4):
        a, b = cl[k], cl[k + 4]
        gk = wrap_half(theta - (ta[k] + w * dk[k]))
        gap = np.minimum(g0[k] + w * slope[k], g0[k - 1] + w * slope[k - 1])
        for bt in (beta, 0.45):
            allowed = inner & (np.abs(gk) <= bt * np.maximum(gap, 1e-12))
            allowed[[a, b]] = True
            pth = shortest_path(n, e, ln, a, b, allowed)
            if pth is not None:
                break
        else:
            raise InputError(f"side edge {edge_name(k + 8)} finds no path in its corridor; the mesh is too coarse "
                             "between the end loops or the corners are badly placed")
        out[k + 8] = loc[pth]
    return out


def edges_for_corners(v, f, corners, sides="auto", heat=None):
    """Table 3.1 geodesics; side edges geodesic, guided, or guided when the geodesic ones fail ("auto")."""
    paths, fallbacks = trace_edges(v, f, corners, heat)
    if sides == "guided":
        paths = guide_sides(v, f, corners, paths)
    try:
        check_paths(paths, corners, len(v))
        labels = label_patches(v, f, paths)
    except InputError as err:
        if sides != "auto":
            raise
        try:
            paths = guide_sides(v, f, corners, paths)
        except InputError:
            raise err from None
        check_paths(paths, corners, len(v))
        labels = label_patches(v, f, paths)
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
        conformal corridors (:func:`guide_sides`), or the geodesics unless
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
    v, f = closed_mesh(vertices, faces)
    c = check_corners(corners, len(v))
    paths, _, _ = edges_for_corners(v, f, c, sides)
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
    v, f = closed_mesh(vertices, faces)
    if len(paths) != 12:
        raise InputError(f"a hexahedron has 12 edges; got {len(paths)} paths")
    paths = [np.asarray(p, np.int64).ravel() for p in paths]
    if any(len(p) < 2 for p in paths):
        raise InputError("every path needs at least two vertices")
    corners = np.empty(8, np.int64)
    for k, (a, b) in enumerate(CUBE_EDGES):
        corners[a], corners[b] = paths[k][0], paths[k][-1]
    check_corners(corners, len(v))
    check_paths(paths, corners, len(v))
    return label_patches(v, f, paths)
