"""Heat-method geodesics on closed triangle meshes (000 §3.1–3.2; Crane, Weischedel & Wardetzky 2013).

Discrete operators (000 §3.1 with the erratum of the notes: the *standard*
cotangent Laplacian, not the text's ``−0.5(cot α + cot β)`` normalised to 1):

* cotangent Laplacian (integrated, negative semi-definite)
  ``(L u)_i = Σ_{j∈N(i)} ½ (cot α_ij + cot β_ij) (u_j − u_i)`` (000 eq. 3.1.2),
  ``α_ij, β_ij`` the two angles opposite edge ``ij``, and lumped (barycentric)
  mass ``A_i = ⅓ Σ_{f∋i} |f|``: :mod:`porecad.mesh.operators`;
* face gradient ``∇u|_f = Σ_{i=0..2} u_i (n × e_i) / (2 |f|)`` (000 eq. 3.1.3),
  ``e_i`` the counter-clockwise edge opposite corner ``i``;
* integrated vertex divergence of a face field ``X``
  ``(∇·X)_i = ½ Σ_{f∋i} [cot θ₁ (e₁·X_f) + cot θ₂ (e₂·X_f)]``, ``e₁, e₂`` the
  edges of ``f`` leaving ``i`` and ``θ₁, θ₂`` the angles opposite them.

Heat method (Crane et al. 2013, Algorithm 1):

1. one backward-Euler heat step ``(A − t L) u = δ_S`` (000 eqs. 3.1.5–3.1.6)
   with ``t = h²``, ``h`` the mean edge length;
2. ``X = −∇u / |∇u|`` per face;
3. Poisson ``L φ = ∇·X``, shifted so that ``φ = 0`` on the source.

Both matrices are factorised once (:func:`scipy.sparse.linalg.factorized`,
SuperLU) by :class:`HeatGeodesics` and reused for every source. The Poisson
matrix is singular (constants); one vertex is pinned, which is consistent
because the divergence of a face field sums to zero on a closed mesh.

A geodesic *edge path* (the cube edges of 000 §3.3 run along mesh edges) is
traced from a destination vertex down to the source by descending ``φ``
(:func:`descent_path`), with Dijkstra on the edge graph
(:func:`scipy.sparse.csgraph.dijkstra`) as the fallback when the descent
stalls.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse.linalg import factorized

from ..errors import InputError
from ..mesh.operators import corner_cotangents, cotangent_laplacian, mass_matrix, triangle_mesh

__all__ = [
    "HeatGeodesics",
    "descent_path",
    "dijkstra_path",
    "edge_graph",
    "face_gradient",
    "vertex_divergence",
]


def face_gradient(vertices, faces, u) -> np.ndarray:
    """Per-face gradient ``∇u = Σ_i u_i (n × e_i) / (2|f|)`` (000 eq. 3.1.3), (F, 3)."""
    v, f = triangle_mesh(vertices, faces)
    p = v[f]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    dbl = np.linalg.norm(nrm, axis=1)  # 2|f|
    n = nrm / np.maximum(dbl, 1e-300)[:, None]
    uf = np.asarray(u, float)[f]
    g = np.zeros((len(f), 3))
    for c in range(3):
        e = p[:, (c + 2) % 3] - p[:, (c + 1) % 3]  # counter-clockwise edge opposite corner c
        g += uf[:, c, None] * np.cross(n, e)
    return g / np.maximum(dbl, 1e-300)[:, None]


def vertex_divergence(vertices, faces, X) -> np.ndarray:
    """Integrated divergence ``½ Σ_f [cot θ₁ (e₁·X) + cot θ₂ (e₂·X)]`` of a face field, (V,)."""
    v, f = triangle_mesh(vertices, faces)
    cots = corner_cotangents(v, f)
    X = np.asarray(X, float)
    div = np.zeros(len(v))
    for c in range(3):
        a, b = (c + 1) % 3, (c + 2) % 3
        xi = v[f[:, c]]
        e1 = v[f[:, a]] - xi  # opposite corner b
        e2 = v[f[:, b]] - xi  # opposite corner a
        contrib = 0.5 * (cots[:, b] * np.einsum("ij,ij->i", e1, X) + cots[:, a] * np.einsum("ij,ij->i", e2, X))
        div += np.bincount(f[:, c], weights=contrib, minlength=len(v))
    return div


def edge_graph(vertices, faces) -> sp.csr_matrix:
    """Symmetric sparse graph of the mesh edges weighted by their lengths, (V, V)."""
    v, f = triangle_mesh(vertices, faces)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    ln = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    ln = np.maximum(ln, 1e-12 * max(float(ln.max(initial=0.0)), 1.0))  # keep zero-length edges in the graph
    n = len(v)
    g = sp.coo_matrix((ln, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    return (g + g.T).tocsr()


class HeatGeodesics:
    """Heat-method distance with both factorisations kept for many sources.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
        A closed (or at least connected) triangle mesh.
    t : float, optional
        Heat time; default ``h²`` with ``h`` the mean edge length (Crane et al. 2013, §3.2.4).

    Notes
    -----
    Factorises ``A − tL`` and ``−L`` with the pinned vertex 0 removed, once.
    """

    def __init__(self, vertices, faces, t: float | None = None):
        v, f = triangle_mesh(vertices, faces)
        self.vertices, self.faces = v, f
        self.graph = edge_graph(v, f)
        ncomp, _ = connected_components(self.graph, directed=False)
        used = np.zeros(len(v), bool)
        used[f.ravel()] = True
        if ncomp - int(np.sum(~used)) != 1:
            raise InputError(f"the mesh has {ncomp - int(np.sum(~used))} connected parts; "
                             "geodesics need one connected surface")
        gc = self.graph.tocoo()
        self.h = float(gc.data.mean())
        self.t = float(self.h ** 2 if t is None else t)
        self.L = cotangent_laplacian(v, f)
        self.A = mass_matrix(v, f)
        self._used = used
        self._heat = factorized((sp.diags(self.A) - self.t * self.L).tocsc())
        self._pin = int(np.flatnonzero(used)[0])
        keep = np.ones(len(v), bool)
        keep[self._pin] = False
        keep &= used
        self._keep = np.flatnonzero(keep)
        self._poisson = factorized((-self.L)[self._keep][:, self._keep].tocsc())

    def distance(self, sources) -> np.ndarray:
        """Geodesic distance from the source vertex set, (V,); 0 on the sources."""
        src = np.atleast_1d(np.asarray(sources, np.int64))
        if src.size == 0 or src.min() < 0 or src.max() >= len(self.vertices):
            raise InputError(f"source vertices must lie in 0..{len(self.vertices) - 1}")
        delta = np.zeros(len(self.vertices))
        delta[src] = 1.0
        u = self._heat(delta)
        g = face_gradient(self.vertices, self.faces, u)
        gn = np.linalg.norm(g, axis=1)
        X = -g / np.maximum(gn, 1e-300)[:, None]
        X[gn <= 1e-300] = 0.0
        div = vertex_divergence(self.vertices, self.faces, X)
        phi = np.zeros(len(self.vertices))
        phi[self._keep] = self._poisson(-div[self._keep])
        phi -= phi[src].mean()
        phi[~self._used] = np.inf
        return phi


def dijkstra_path(graph, dest: int, source: int) -> np.ndarray:
    """Shortest edge path ``dest → source`` on a length-weighted edge graph (Dijkstra)."""
    _, pred = dijkstra(graph, directed=False, indices=int(source), return_predecessors=True)
    path = [int(dest)]
    while path[-1] != source:
        p = int(pred[path[-1]])
        if p < 0:
            raise InputError(f"vertex {dest} cannot be reached from vertex {source} along mesh edges")
        path.append(p)
    return np.asarray(path, np.int64)


def descent_path(distance, graph, dest: int, source: int, return_fallback: bool = False,
                 step: str = "smallest"):
    """Edge path from ``dest`` down to ``source`` by descending a distance field.

    Each step moves to the neighbour with the smallest distance
    (``step="smallest"``, the default) or with the steepest descent
    ``(φ_i − φ_j) / |x_i − x_j|`` (``step="steepest"``), which must be
    strictly smaller than the current one; a vertex adjacent to the source
    steps onto it (the heat distance is smoothed within about ``√t = h`` of
    the source). If the descent stalls in a local minimum, the Dijkstra
    shortest edge path is returned instead.

    Parameters
    ----------
    distance : (V,) float
        E.g. :meth:`HeatGeodesics.distance` of ``source``.
    graph : (V, V) sparse
        The edge graph (:func:`edge_graph`).
    dest, source : int

    Returns
    -------
    path : (n,) int64
        Vertex indices, ``path[0] == dest`` and ``path[-1] == source``.
    fallback : bool
        Only with ``return_fallback``: whether Dijkstra was used.
    """
    if step not in ("smallest", "steepest"):
        raise InputError(f"step must be 'smallest' or 'steepest'; got {step!r}")
    g = graph.tocsr()
    ip, ix, ln = g.indptr, g.indices, g.data
    d = np.asarray(distance, float)
    cur, path, ok = int(dest), [int(dest)], True
    while cur != source:
        nb = ix[ip[cur]:ip[cur + 1]]
        if source in nb:
            nxt = int(source)
        else:
            if not len(nb):
                nxt = cur
            elif step == "smallest":
                nxt = int(nb[np.argmin(d[nb])])
            else:
                nxt = int(nb[np.argmax((d[cur] - d[nb]) / ln[ip[cur]:ip[cur + 1]])])
            if not d[nxt] < d[cur]:
                ok = False
                break
        path.append(nxt)
        cur = nxt
    out = np.asarray(path, np.int64) if ok else dijkstra_path(g, dest, source)
    return (out, not ok) if return_fallback else out
