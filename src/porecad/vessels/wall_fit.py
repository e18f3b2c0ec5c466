"""Sub-voxel refinement of a centreline graph on the vessel's boundary points (step 5 of
:func:`porecad.vessels.skeleton.image_centreline`).

Each node of degree 2 is moved to the centre of a circle fitted to the wall points around it and
takes its radius (:func:`refine_on_boundary`, Kåsa's algebraic fit :func:`kasa_circle`); junction
nodes are then re-placed from the fitted branch axes (:func:`straighten_junctions`).
"""

from __future__ import annotations

import numpy as np

from .graph import CentrelineGraph


def kasa_circle(u, v):
    """Algebraic least-squares circle ``(cu, cv, r)`` through 2-D points (Kåsa 1976)."""
    A = np.stack([u, v, np.ones_like(u)], axis=1)
    b = -(u * u + v * v)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    cu, cv = -D / 2, -E / 2
    return cu, cv, float(np.sqrt(max(cu * cu + cv * cv - F, 0.0)))


def refine_on_boundary(g: CentrelineGraph, boundary: np.ndarray, passes: int = 2, min_points: int = 12,
                       hops: int = 2):
    """Move nodes and set radii from boundary points (step 5, in place); return the graph.

    Every boundary point is projected on the nearest centreline edge; points
    whose foot lies at an end node or within a radius of a junction are not
    used. For a node, the points assigned to it and its neighbours within
    ``hops`` edges are projected on its normal plane and fitted by a circle
    (Kåsa's algebraic fit, unbiased by the uneven point density on a bend);
    the node moves to the circle centre and takes its radius when the points
    surround it (largest angular gap < 90°). Other nodes get radii
    interpolated along their chain.
    """
    adj = g.adjacency()
    deg = g.degrees()
    junction_pts = g.points[deg >= 3]
    for _ in range(passes):
        P = g.points
        T = _node_tangents(P, adj, g.n_nodes)
        owner, interior = _wall_owners(g, P, adj, deg, boundary, junction_pts)
        newP, newR, fitted = _fit_node_circles(g, P, T, adj, deg, boundary, owner, interior, hops, min_points)
        _interpolate_radii(g, newP, newR, fitted)
        g.points, g.radii = newP, newR
    g.info["fitted"] = fitted
    return g


def _node_tangents(P, adj, n_nodes):
    """Unit tangent (n_nodes, 3) of every node at ``P``: along its two neighbours, from its one, else zero."""
    T = np.zeros_like(P)
    for v in range(n_nodes):
        nb = adj[v]
        t = (P[nb[1]] - P[nb[0]]) if len(nb) == 2 else (P[v] - P[nb[0]] if len(nb) == 1 else np.zeros(3))
        T[v] = t / max(np.linalg.norm(t), 1e-12)
    return T


def _wall_owners(g, P, adj, deg, boundary, junction_pts):
    """The node each boundary point belongs to, and whether it is a wall point (usable for a fit).

    Takes the graph, its node positions ``P``, adjacency and degrees, the boundary points and the junction
    points; projects every point on the nearest node's edges. Returns ``owner`` (the edge end nearer the
    best foot) and ``interior`` (False for a foot at an end node's tip or within 1.5 radii of a junction).
    """
    from scipy.spatial import cKDTree
    _, near = cKDTree(P).query(boundary)
    # best foot over the nearest node's edges
    best_d = np.full(len(boundary), np.inf)
    owner = near.copy()
    interior = np.zeros(len(boundary), bool)
    maxdeg = max(len(a) for a in adj)
    for k in range(maxdeg):
        has = np.array([len(adj[v]) > k for v in near])
        if not has.any():
            continue
        a = near[has]
        b = np.array([adj[v][k] for v in a])
        q = boundary[has]
        ab = P[b] - P[a]
        t = np.clip(np.einsum("ij,ij->i", q - P[a], ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        foot = P[a] + t[:, None] * ab
        d = np.linalg.norm(q - foot, axis=1)
        # a foot at an end node's tip (t = 0 at a degree-1 node) is on the cap, not the wall
        ok_foot = ~((t <= 1e-9) & (deg[a] == 1)) & ~((t >= 1 - 1e-9) & (deg[b] == 1))
        idx = np.flatnonzero(has)
        better = d < best_d[idx]
        best_d[idx[better]] = d[better]
        owner[idx[better]] = np.where(t[better] < 0.5, a[better], b[better])
        interior[idx[better]] = ok_foot[better]
    if len(junction_pts):
        dj, _ = cKDTree(junction_pts).query(boundary)
        interior &= dj > 1.5 * g.radii[owner]
    return owner, interior


def _fit_node_circles(g, P, T, adj, deg, boundary, owner, interior, hops, min_points):
    """Circle fits of the degree-2 nodes to the wall points of their ``hops`` neighbourhood.

    Takes the graph, node positions ``P`` and tangents ``T``, adjacency, degrees, the boundary points with
    their ``owner`` and ``interior`` mask (:func:`_wall_owners`), ``hops`` and ``min_points``. Returns the new
    positions and radii (copies; a node moves to its circle's centre and takes its radius when at least
    ``min_points`` points surround it with no angular gap over 90°) and the ``fitted`` mask.
    """
    order = np.argsort(owner[interior])
    own = owner[interior][order]
    pts = boundary[interior][order]
    starts = np.searchsorted(own, np.arange(g.n_nodes))
    ends = np.searchsorted(own, np.arange(g.n_nodes), side="right")
    newP, newR = P.copy(), g.radii.copy()
    fitted = np.zeros(g.n_nodes, bool)
    for v in range(g.n_nodes):
        if deg[v] != 2:
            continue
        group, frontier = {v}, {v}
        for _h in range(hops):
            frontier = {w for u in frontier for w in adj[u] if w not in group}
            group |= frontier
        q = np.concatenate([pts[starts[u]:ends[u]] for u in group])
        if len(q) < min_points:
            continue
        tv = T[v]
        e1 = np.cross(tv, [1.0, 0, 0] if abs(tv[0]) < 0.9 else [0, 1.0, 0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(tv, e1)
        w = q - P[v]
        u_, v_ = w @ e1, w @ e2
        ang = np.sort(np.arctan2(v_, u_))
        gap = np.max(np.diff(np.r_[ang, ang[0] + 2 * np.pi]))
        if gap > np.pi / 2:
            continue
        cu, cv, r = kasa_circle(u_, v_)
        newP[v] = P[v] + cu * e1 + cv * e2
        newR[v] = r
        fitted[v] = True
    return newP, newR, fitted


def _interpolate_radii(g, newP, newR, fitted):
    """Radii of nodes without a fit, in place in ``newR``: interpolated by arc length (at ``newP``) along their
    chain of ``g`` from its fitted nodes."""
    for chain in g.branches():
        f = fitted[chain]
        if f.any() and not f.all():
            s = np.r_[0, np.cumsum(np.linalg.norm(np.diff(newP[chain], axis=0), axis=1))]
            newR[chain[~f]] = np.interp(s[~f], s[f], newR[chain][f])


def straighten_junctions(g: CentrelineGraph, near: float = 1.5, far: float = 4.0,
                         move_limit: float = 4.0) -> CentrelineGraph:
    """Re-place junction nodes and their unfitted neighbourhoods from the fitted branch axes.

    For each junction, every incident chain's circle-fitted nodes at arc
    distance ``near .. far`` radii from the junction (plus the junction's
    radius less the chain's, where a thin branch leaves a thick one) are
    fitted by a line (principal axis); the junction moves to the point
    nearest to all these lines in the least-squares sense (unless that point
    lies more than ``move_limit`` junction radii away), and the chain's nodes between the
    junction and its first fitted node are spaced evenly on the segment
    between them (the medial axis of a bifurcation bends into the crotch,
    so the skeleton's own junction is biased).
    """
    fitted = g.info.get("fitted")
    if fitted is None:
        return g
    deg = g.degrees()
    P = g.points.copy()
    chains = g.branches()
    for j in np.flatnonzero(deg >= 3):
        lines, fills = [], []
        for c in chains:
            if c[0] == j:
                cc = c
            elif c[-1] == j:
                cc = c[::-1]
            else:
                continue
            s = np.r_[0, np.cumsum(np.linalg.norm(np.diff(P[cc], axis=0), axis=1))]
            r = float(np.median(g.radii[cc][fitted[cc]])) if fitted[cc].any() else float(g.radii[j])
            # a thin branch leaves a thick one about the thick one's radius from the junction: its axis
            # starts there (inside the thick lumen the skeleton bends towards the thick axis)
            off = max(float(g.radii[j]) - r, 0.0)
            sel = fitted[cc] & (s >= off + near * r) & (s <= off + far * r)
            if sel.sum() < 3:
                continue
            Q = P[cc][sel]
            m = Q.mean(axis=0)
            u = np.linalg.svd(Q - m)[2][0]
            lines.append((m, u))
            k = int(np.flatnonzero(fitted[cc] & (s >= off + near * r))[0])
            fills.append(cc[:k + 1])
        if len(lines) < 2:
            continue
        A = np.zeros((3, 3))
        b = np.zeros(3)
        for m, u in lines:
            M = np.eye(3) - np.outer(u, u)
            A += M
            b += M @ m
        J = np.linalg.solve(A, b)
        if not np.all(np.isfinite(J)) or np.linalg.norm(J - P[j]) > move_limit * float(g.radii[j]):
            continue  # nearly parallel axes: the least-squares point is ill-posed; keep the skeleton's
        P[j] = J
        for cc in fills:
            end = P[cc[-1]]
            for i, v in enumerate(cc[1:-1], start=1):
                P[v] = J + (end - J) * i / (len(cc) - 1)
    g.points = P
    return g
