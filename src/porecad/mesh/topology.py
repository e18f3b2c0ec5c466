"""Combinatorial topology of a triangle mesh: edge and vertex incidence counts.

Every face ``(a, b, c)`` contributes the directed half-edges ``a->b``,
``b->c``, ``c->a``. :func:`edge_topology` counts, from the vertex stars
(faces bucketed by vertex, each star examined once, in parallel), the
boundary, non-manifold and misoriented edges and the non-manifold vertices
of a mesh, and derives the ``closed`` / ``manifold`` / ``oriented`` verdicts
:mod:`porecad.mesh.validate` checks a solid by. The checks work on vertex
*indices*: coincident but unmerged vertices are different vertices.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from porecad.mesh.arrays import as_faces, narrow_faces

__all__ = ["edge_topology", "topology_of_checked"]


@njit(cache=True, nogil=True)
def _vertex_face_csr(faces, n_vertices):
    """Vertex -> incident faces in CSR form (counting sort, O(F)); int32 when it fits."""
    start = np.zeros(n_vertices + 1, np.int64)
    nf = faces.shape[0]
    for f in range(nf):
        for k in range(3):
            start[faces[f, k] + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    pos = start[:-1].copy()
    adj = np.empty(3 * nf, np.int32)
    for f in range(nf):
        for k in range(3):
            v = faces[f, k]
            adj[pos[v]] = f
            pos[v] += 1
    return start, adj


@njit(cache=True, nogil=True)
def _uf_find(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


_STAR_SMALL = 32  # vertex stars up to this valence use the scratch arrays
_STAR_CHUNK = 1024  # vertices per parallel task


@njit(cache=True, nogil=True)
def _star(faces, start, adj, v, w, local, nodes, n_out, n_in, parent):
    """Examine the star of vertex ``v``; returns (edges, boundary, non-manifold, misoriented, fans).

    Around ``v`` every incident face ``(v, w1, w2)`` (rotated so ``v`` comes
    first) has the outgoing half-edge ``v -> w1`` and the incoming one
    ``w2 -> v``. For each neighbour ``w > v`` (each undirected edge is counted
    at its smaller end) ``n_out`` = occurrences of ``w`` among the ``w1`` and
    ``n_in`` among the ``w2``: the edge has ``n_out + n_in`` faces (1:
    boundary, > 2: non-manifold) and is misoriented when ``n_out > 1`` or
    ``n_in > 1``. The *link* of ``v`` has the neighbours as nodes and the
    opposite edges ``(w1, w2)`` as edges; faces around ``v`` that share an
    edge through ``v`` share a link node, so the number of fans is the number
    of connected components of the link (union-find on local node ids).
    ``w`` .. ``parent`` are scratch arrays with room for the star.
    """
    s = start[v]
    deg = start[v + 1] - s
    for q in range(deg):
        f = adj[s + q]
        if faces[f, 0] == v:
            w[q, 0] = faces[f, 1]
            w[q, 1] = faces[f, 2]
        elif faces[f, 1] == v:
            w[q, 0] = faces[f, 2]
            w[q, 1] = faces[f, 0]
        else:
            w[q, 0] = faces[f, 0]
            w[q, 1] = faces[f, 1]
    # distinct neighbours -> local node ids: linear search for ordinary
    # valences, sorting for high ones (a pole must not cost deg**2)
    if deg <= _STAR_SMALL:
        n_nodes = 0
        for q in range(deg):
            for r in range(2):
                t = 0
                while t < n_nodes and nodes[t] != w[q, r]:
                    t += 1
                if t == n_nodes:
                    nodes[t] = w[q, r]
                    n_nodes += 1
                local[q, r] = t
    else:
        n_nodes = _sorted_unique(w, deg, nodes)
        for q in range(deg):
            for r in range(2):
                local[q, r] = _find_sorted(nodes, n_nodes, w[q, r])
    for t in range(n_nodes):
        n_out[t] = 0
        n_in[t] = 0
        parent[t] = t
    n_merged = 0
    for q in range(deg):
        n_out[local[q, 0]] += 1
        n_in[local[q, 1]] += 1
        r1 = _uf_find(parent, local[q, 0])
        r2 = _uf_find(parent, local[q, 1])
        if r1 != r2:
            parent[r1] = r2
            n_merged += 1
    ne = nb = nm = nmis = 0
    for t in range(n_nodes):
        if nodes[t] > v:
            k = n_out[t] + n_in[t]
            ne += 1
            if k == 1:
                nb += 1
            elif k > 2:
                nm += 1
            if n_out[t] > 1 or n_in[t] > 1:
                nmis += 1
    return ne, nb, nm, nmis, n_nodes - n_merged


@njit(cache=True, nogil=True)
def _sorted_unique(w, deg, out):
    """The distinct values of ``w[:deg]`` sorted into ``out`` (Shell sort, gaps 3k+1); returns their count.

    Hand-written instead of ``np.unique``: numba compiles its sort for seconds.
    """
    n = 2 * deg
    for q in range(deg):
        out[2 * q] = w[q, 0]
        out[2 * q + 1] = w[q, 1]
    gap = 1
    while gap < n // 3:
        gap = 3 * gap + 1
    while gap > 0:
        for i in range(gap, n):
            x = out[i]
            j = i
            while j >= gap and out[j - gap] > x:
                out[j] = out[j - gap]
                j -= gap
            out[j] = x
        gap //= 3
    m = 0
    for i in range(n):
        if m == 0 or out[i] != out[m - 1]:
            out[m] = out[i]
            m += 1
    return m


@njit(cache=True, nogil=True)
def _find_sorted(a, n, x):
    """Index of ``x`` in the sorted ``a[:n]`` (binary search; ``x`` is there)."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def _star_scratch(cap):
    """Scratch arrays of :func:`_star` for stars of up to ``cap`` faces."""
    return (np.empty((cap, 2), np.int64), np.empty((cap, 2), np.int64), np.empty(2 * cap, np.int64),
            np.empty(2 * cap, np.int32), np.empty(2 * cap, np.int32), np.empty(2 * cap, np.int64))


def _vertex_topology(faces, start, adj):
    """Edge and fan counts of a mesh from its vertex stars (see :func:`_star`).

    Returns ``(used vertices, edges, boundary edges, non-manifold edges,
    misoriented edges, non-manifold vertices)``; O(F) work in chunks of
    ``_STAR_CHUNK`` vertices shared out over threads (a serial kernel each:
    :func:`porecad.kernel_threads.run_interleaved`), each with its own scratch arrays.
    """
    from ..kernel_threads import run_interleaved

    n_chunks = (start.shape[0] - 1 + _STAR_CHUNK - 1) // _STAR_CHUNK
    sums = np.zeros((n_chunks, 6), np.int64)
    run_interleaved(_star_chunks, n_chunks, faces, start, adj, sums, min_per_thread=1)
    return tuple(int(x) for x in sums.sum(axis=0))


@njit(cache=True, nogil=True)
def _star_chunks(faces, start, adj, sums, first, step):
    """``sums[ch]`` = the counts of :func:`_vertex_topology` over chunk ``ch`` (chunks ``first::step``)."""
    nv = start.shape[0] - 1
    n_chunks = sums.shape[0]
    cap = max(_STAR_SMALL, start[0])     # not the literal: one compiled _star_scratch, not two
    w, local, nodes, n_out, n_in, parent = _star_scratch(cap)
    for ch in range(first, n_chunks, step):
        for v in range(ch * _STAR_CHUNK, min(nv, (ch + 1) * _STAR_CHUNK)):
            deg = start[v + 1] - start[v]
            if deg == 0:
                continue
            if deg > cap:
                cap = deg
                w, local, nodes, n_out, n_in, parent = _star_scratch(cap)
            ne, nb, nm, nmis, fans = _star(faces, start, adj, v, w, local, nodes, n_out, n_in, parent)
            sums[ch, 0] += 1
            sums[ch, 1] += ne
            sums[ch, 2] += nb
            sums[ch, 3] += nm
            sums[ch, 4] += nmis
            if fans > 1:
                sums[ch, 5] += 1


def _incidence_counts(f) -> dict:
    """The counts of :func:`edge_topology`, without its verdicts.

    Takes the faces ``(F, 3)`` as :func:`~porecad.mesh.arrays.narrow_faces`
    leaves them; returns a dict of ``n_faces``, ``n_vertices``, ``n_edges``,
    ``euler``, ``degenerate_faces``, ``boundary_edges``,
    ``nonmanifold_edges``, ``nonmanifold_vertices`` and
    ``misoriented_edges``, in that order (degenerate faces left out of all
    but their own count; all zero without other faces).
    """
    nf = len(f)
    degenerate = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    n_degenerate = int(np.count_nonzero(degenerate))
    g = f[~degenerate] if n_degenerate else f
    out = dict(
        n_faces=nf,
        n_vertices=0,
        n_edges=0,
        euler=0,
        degenerate_faces=n_degenerate,
        boundary_edges=0,
        nonmanifold_edges=0,
        nonmanifold_vertices=0,
        misoriented_edges=0,
    )
    if len(g):
        n = int(g.max()) + 1
        start, adj = _vertex_face_csr(g, n)
        n_used, n_edges, n_boundary, n_nonmanifold, n_mis, n_bad = _vertex_topology(g, start, adj)
        del start, adj
        out.update(
            n_vertices=int(n_used),
            n_edges=int(n_edges),
            euler=int(n_used) - int(n_edges) + len(g),
            boundary_edges=int(n_boundary),
            nonmanifold_edges=int(n_nonmanifold),
            nonmanifold_vertices=int(n_bad),
            misoriented_edges=int(n_mis),
        )
    return out


def _with_verdicts(out: dict) -> dict:
    """The counts of :func:`_incidence_counts` with ``closed``, ``manifold`` and ``oriented`` added (in place)."""
    out["closed"] = out["boundary_edges"] == 0
    out["manifold"] = (
        out["boundary_edges"] == 0
        and out["nonmanifold_edges"] == 0
        and out["nonmanifold_vertices"] == 0
        and out["degenerate_faces"] == 0
    )
    out["oriented"] = out["misoriented_edges"] == 0
    return out


def edge_topology(faces):
    """Edge and vertex incidence counts of a triangle mesh.

    Every face ``(a, b, c)`` contributes the directed half-edges ``a->b``,
    ``b->c``, ``c->a``.  Faces are bucketed by vertex (counting sort) and
    every vertex star is examined once, in parallel: the half-edges leaving
    and entering the vertex give the face count and the directions of each
    edge, and a union-find over the link gives the number of fans (see
    :func:`_vertex_topology`).

    Parameters
    ----------
    faces : (F, 3) int array
        Vertex indices per face.

    Returns
    -------
    dict
        ``n_faces``
            number of faces ``F``.
        ``n_vertices``
            number of distinct vertices referenced by the faces.
        ``n_edges``
            number of distinct undirected edges ``E``.
        ``euler``
            Euler characteristic ``chi = V - E + F`` of the referenced part
            (``2 - 2g`` per closed component of genus ``g``).
        ``degenerate_faces``
            faces with a repeated vertex index; they are left out of every
            other count.
        ``boundary_edges``
            edges used by exactly one face.
        ``nonmanifold_edges``
            edges used by more than two faces.
        ``nonmanifold_vertices``
            vertices whose incident faces form more than one edge-connected
            fan (e.g. the shared apex of two cones, a "bowtie").
        ``misoriented_edges``
            undirected edges traversed at least twice in the same direction.
        ``closed`` : bool
            ``boundary_edges == 0``.
        ``manifold`` : bool
            every edge used by exactly two faces, every vertex a single fan,
            no degenerate face.
        ``oriented`` : bool
            ``misoriented_edges == 0``: no directed half-edge occurs twice, so
            each interior edge is traversed once in each direction.  For a
            manifold closed mesh this is "each directed edge appears once and
            its reverse once".  An open mesh can be oriented.

    Notes
    -----
    Runs in ``O(F)`` time (no sorting) and ``O(F)`` extra memory: about
    0.1 s for two million faces on two cores.
    """
    return topology_of_checked(as_faces(faces))


def topology_of_checked(faces) -> dict:
    """:func:`edge_topology` of faces already checked (:func:`~porecad.mesh.arrays.as_faces`: ``(F, 3)``,
    C-contiguous, int32 or int64, no negative index), without checking them again."""
    f = narrow_faces(faces)   # one compiled specialisation of the kernels
    return _with_verdicts(_incidence_counts(f))
