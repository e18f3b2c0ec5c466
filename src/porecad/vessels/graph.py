"""Centreline graphs with radii: validation and branch extraction.

A :class:`CentrelineGraph` holds node positions ``(N, 3)`` (mm), radii
``(N,)`` (mm, the maximum inscribed sphere radius of the lumen at the node)
and undirected edges ``(E, 2)``. :meth:`CentrelineGraph.validate` refuses,
with one-line :class:`~porecad.errors.InputError` messages:

* an empty graph, non-finite coordinates, edges with bad indices or loops;
* zero, negative or non-finite radii;
* a disconnected graph (more than one connected component);
* a **self-intersecting centreline**: two edges that share no node come closer
  than ``0.5 * min(radius)`` of their four end nodes while the shortest path
  between them along the centreline is longer than ``2 (r_a + r_b)`` (so
  the contact is not just the neighbourhood of a junction).
"""

from __future__ import annotations

from dataclasses import dataclass, field as dc_field

import numpy as np

from ..errors import InputError


@dataclass
class CentrelineGraph:
    points: np.ndarray
    radii: np.ndarray
    edges: np.ndarray
    source: str = ""
    info: dict = dc_field(default_factory=dict)

    def __post_init__(self):
        self.points = np.asarray(self.points, dtype=np.float64).reshape(-1, 3) if np.size(self.points) else \
            np.zeros((0, 3))
        self.radii = np.asarray(self.radii, dtype=np.float64).reshape(-1)
        self.edges = np.asarray(self.edges, dtype=np.int64).reshape(-1, 2) if np.size(self.edges) else \
            np.zeros((0, 2), dtype=np.int64)

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    def degrees(self) -> np.ndarray:
        return np.bincount(self.edges.ravel(), minlength=self.n_nodes)

    def adjacency(self) -> list[list[int]]:
        adj = [[] for _ in range(self.n_nodes)]
        for a, b in self.edges:
            adj[a].append(int(b))
            adj[b].append(int(a))
        return adj

    # ------------------------------------------------------------------
    def validate(self, check_self_intersection: bool = True) -> "CentrelineGraph":
        """Check the graph (see the module docstring); return self."""
        what = f"{self.source}: " if self.source else ""
        n = self.n_nodes
        if n < 2 or len(self.edges) == 0:
            raise InputError(f"{what}the centreline graph is empty (needs at least 2 nodes and 1 edge)")
        if self.radii.shape != (n,):
            raise InputError(f"{what}{n} centreline points but {self.radii.size} radii")
        if not np.all(np.isfinite(self.points)):
            raise InputError(f"{what}centreline coordinates must be finite")
        bad = np.flatnonzero(~np.isfinite(self.radii) | (self.radii <= 0))
        if len(bad):
            raise InputError(f"{what}radius must be positive: node {int(bad[0])} has radius "
                             f"{self.radii[bad[0]]:g} ({len(bad)} bad radii)")
        if np.any(self.edges < 0) or np.any(self.edges >= n):
            raise InputError(f"{what}an edge refers to a node that does not exist")
        if np.any(self.edges[:, 0] == self.edges[:, 1]):
            raise InputError(f"{what}an edge joins a node to itself")
        seg = np.linalg.norm(self.points[self.edges[:, 0]] - self.points[self.edges[:, 1]], axis=1)
        if np.any(seg <= 0):
            i = int(np.flatnonzero(seg <= 0)[0])
            raise InputError(f"{what}edge {i} joins two nodes at the same position")
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        m = coo_matrix((np.ones(len(self.edges)), (self.edges[:, 0], self.edges[:, 1])), shape=(n, n))
        ncomp, labels = connected_components(m, directed=False)
        if ncomp > 1:
            sizes = np.bincount(labels)
            raise InputError(f"{what}the centreline graph is disconnected: {ncomp} separate parts "
                             f"(sizes {', '.join(str(int(s)) for s in sorted(sizes, reverse=True)[:5])})")
        if check_self_intersection:
            hit = self.self_intersection()
            if hit is not None:
                i, j, d = hit
                raise InputError(f"{what}the centreline intersects itself: edges {i} and {j} come "
                                 f"{d:.3g} mm apart, far apart along the centreline")
        return self

    def self_intersection(self):
        """First offending edge pair ``(i, j, distance)`` or None (definition: module docstring)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra
        from scipy.spatial import cKDTree
        P, E, R = self.points, self.edges, self.radii
        a, b = P[E[:, 0]], P[E[:, 1]]
        mid = 0.5 * (a + b)
        half = 0.5 * np.linalg.norm(b - a, axis=1)
        reach = 2 * float(half.max()) + float(R.max())
        pairs = cKDTree(mid).query_pairs(reach, output_type="ndarray")
        if len(pairs) == 0:
            return None
        i, j = pairs[:, 0], pairs[:, 1]
        share = ((E[i, 0] == E[j, 0]) | (E[i, 0] == E[j, 1]) | (E[i, 1] == E[j, 0]) | (E[i, 1] == E[j, 1]))
        i, j = i[~share], j[~share]
        if len(i) == 0:
            return None
        d = segment_distance(a[i], b[i], a[j], b[j])
        rmin = np.minimum(np.minimum(R[E[i, 0]], R[E[i, 1]]), np.minimum(R[E[j, 0]], R[E[j, 1]]))
        close = d < 0.5 * rmin
        if not np.any(close):
            return None
        lengths = np.linalg.norm(b - a, axis=1)
        n = self.n_nodes
        g = coo_matrix((np.r_[lengths, lengths], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])),
                       shape=(n, n)).tocsr()
        for ii, jj, dd in zip(i[close], j[close], d[close]):
            rmax = max(R[E[ii]].max(), R[E[jj]].max())
            limit = 2.0 * 2.0 * rmax
            dist = dijkstra(g, indices=E[ii], limit=limit + lengths[ii] + lengths[jj])
            geo = float(np.min(dist[:, E[jj]]))
            if not np.isfinite(geo) or geo > limit:
                return int(ii), int(jj), float(dd)
        return None

    def branches(self) -> list[np.ndarray]:
        """Node chains between junctions/ends (nodes of degree != 2); cycles become one chain."""
        deg = self.degrees()
        adj = self.adjacency()
        used = set()
        out = []
        key = lambda u, v: (min(u, v), max(u, v))  # noqa: E731

        def walk(a, b, more):
            """The chain a, b, ... followed through unused edges while ``more(chain)``."""
            chain = [a, b]
            used.add(key(a, b))
            while more(chain):
                u = chain[-1]
                nxt = [w for w in adj[u] if key(u, w) not in used]
                if not nxt:
                    break
                used.add(key(u, nxt[0]))
                chain.append(nxt[0])
            return np.asarray(chain, dtype=np.int64)

        for s in range(self.n_nodes):
            if deg[s] == 2:
                continue
            for nb in adj[s]:
                if key(s, nb) not in used:
                    out.append(walk(s, nb, lambda c: deg[c[-1]] == 2))
        for a, b in self.edges:  # pure cycles (all degree 2)
            if key(a, b) not in used:
                out.append(walk(int(a), int(b), lambda c: c[-1] != c[0]))
        return out

    def ends(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Open ends: ``(position, outward unit tangent, radius)`` of every degree-1 node."""
        deg = self.degrees()
        adj = self.adjacency()
        out = []
        for v in np.flatnonzero(deg == 1):
            # tangent over about one radius of arc length for robustness
            chain = [int(v)]
            L = 0.0
            while L < self.radii[v] and len(adj[chain[-1]]) <= 2:
                nxt = [w for w in adj[chain[-1]] if w not in chain]
                if not nxt:
                    break
                L += float(np.linalg.norm(self.points[nxt[0]] - self.points[chain[-1]]))
                chain.append(nxt[0])
            t = self.points[v] - self.points[chain[-1]]
            t = t / np.linalg.norm(t)
            out.append((self.points[v].copy(), t, float(self.radii[v])))
        return out

    def bounds(self):
        lo = (self.points - self.radii[:, None]).min(axis=0)
        hi = (self.points + self.radii[:, None]).max(axis=0)
        return lo, hi


def segment_distance(a, b, c, d) -> np.ndarray:
    """Closest distance between segments ``ab`` and ``cd`` (arrays of shape (M, 3))."""
    a, b, c, d = (np.asarray(x, dtype=np.float64).reshape(-1, 3) for x in (a, b, c, d))
    u, v, w = b - a, d - c, a - c
    A = np.einsum("ij,ij->i", u, u)
    B = np.einsum("ij,ij->i", u, v)
    C = np.einsum("ij,ij->i", v, v)
    D = np.einsum("ij,ij->i", u, w)
    E = np.einsum("ij,ij->i", v, w)
    den = A * C - B * B
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-14 * A * C, (B * E - C * D) / den, 0.0)
    s = np.clip(s, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(C > 0, (B * s + E) / C, 0.0)
    t = np.clip(t, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(A > 0, np.clip((B * t - D) / A, 0.0, 1.0), 0.0)
    return np.linalg.norm(w + s[:, None] * u - t[:, None] * v, axis=1)


def from_polylines(polylines, radii_list, merge_tol: float | None = None, source: str = "") -> CentrelineGraph:
    """Graph from polylines ``[(M_k, 3)]`` with radii ``[(M_k,)]``; coincident points are merged.

    Points closer than ``merge_tol`` (default ``1e-6`` × the bounding-box
    diagonal) become one node, so polylines that share end points join.
    """
    pts = np.concatenate([np.asarray(p, dtype=float).reshape(-1, 3) for p in polylines])
    rad = np.concatenate([np.asarray(r, dtype=float).reshape(-1) for r in radii_list])
    if merge_tol is None:
        diag = float(np.linalg.norm(pts.max(0) - pts.min(0))) if len(pts) else 1.0
        merge_tol = 1e-6 * max(diag, 1e-12)
    from scipy.spatial import cKDTree
    pairs = cKDTree(pts).query_pairs(merge_tol, output_type="ndarray") if len(pts) > 1 else np.zeros((0, 2), int)
    parent = np.arange(len(pts))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    for i, j in pairs:
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([find(i) for i in range(len(pts))])
    uniq, inv = np.unique(roots, return_inverse=True)
    P = pts[uniq]
    Rr = np.zeros(len(uniq))
    np.maximum.at(Rr, inv, rad)  # a merged node keeps the largest radius
    Rr[Rr == 0] = rad[uniq][Rr == 0]
    bad = np.flatnonzero(~(rad > 0))
    if len(bad):
        Rr[inv[bad]] = rad[bad]  # keep a zero/negative radius visible to validate()
    edges = []
    off = 0
    for p in polylines:
        m = len(p)
        ids = inv[off:off + m]
        for k in range(m - 1):
            if ids[k] != ids[k + 1]:
                edges.append((ids[k], ids[k + 1]))
        off += m
    E = np.unique(np.sort(np.asarray(edges, dtype=np.int64).reshape(-1, 2), axis=1), axis=0)
    return CentrelineGraph(P, Rr, E, source=source)
