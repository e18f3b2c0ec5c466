"""Coarsening of a fine closed surface to the edge length of a volume mesh, kept free of self-intersections.

A marching-cubes surface sampled finely (an infill of a femur at 0.3–0.6 mm
has millions of triangles) is far finer than the tets of a useful volume mesh
(1–1.5 mm); meshing it as it is would give tens of millions of tets, and
isotropic remeshing of millions of triangles takes many minutes. It is
decimated instead by quadric edge collapse (Garland & Heckbert, "Surface
simplification using quadric error metrics", SIGGRAPH 1997; the
``fast-simplification`` implementation, MIT), to about the number of
triangles of an isotropic triangulation at the target edge length.

Quadric collapse does not look at the other side of a thin wall: where two
sheets of the surface come closer than an edge (the thin wedges where a
lattice is cut by a body at a grazing angle), coarse triangles cross the
other sheet, and a few collapses leave non-manifold edges or vertices. Those
places are found (self-intersecting pairs, non-manifold edges and vertices,
degenerate faces), the input triangles within ``1.5 h`` of them are frozen
(kept as they are: the surface is cut there and the rest is decimated with
its border preserved, then stitched back), and the decimation is repeated,
a few rounds at most. The result is checked closed, manifold, oriented,
free of self-intersections and within the volume tolerance, or refused.
"""

from __future__ import annotations

import numpy as np

from porecad.errors import MeshError

__all__ = ["coarsen_surface", "nonmanifold_vertex_ids", "coarsening_target"]


def coarsening_target(area: float, size: float) -> int:
    """Triangles of an isotropic triangulation of ``area`` at edge ``0.7 size`` (about 2.3 per edge²)."""
    return int(2.3 * float(area) / (0.7 * float(size)) ** 2)


def nonmanifold_vertex_ids(faces, n_vertices: int) -> np.ndarray:
    """Vertices whose incident faces form more than one edge-connected fan (bowties).

    The corners of the faces around a vertex are joined when their faces
    share an edge at that vertex; a manifold vertex has one component.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    g = np.asarray(faces, dtype=np.int64)
    n = int(n_vertices)
    corner = np.arange(3 * len(g))
    a = g.ravel()
    b = g[:, [1, 2, 0]].ravel()
    c = g[:, [2, 0, 1]].ravel()
    key = np.concatenate([a * n + b, a * n + c])
    cid = np.concatenate([corner, corner])
    order = np.argsort(key, kind="stable")
    key, cid = key[order], cid[order]
    i = np.flatnonzero(key[1:] == key[:-1])
    m = sp.coo_matrix((np.ones(len(i)), (cid[i], cid[i + 1])), shape=(3 * len(g), 3 * len(g)))
    _, label = connected_components(m, directed=False)
    pairs = np.unique(np.stack([a, label], axis=1), axis=0)
    return np.flatnonzero(np.bincount(pairs[:, 0], minlength=n) > 1)


def _defect_points(v, f):
    """Points at the defects of a surface: self-intersections, non-manifold edges/vertices, degenerate faces."""
    from porecad.mesh.intersections import self_intersections

    pairs, n_si = self_intersections(v, f, max_report=1_000_000)
    pts = [v[f[pairs.ravel()]].mean(axis=1)] if len(pairs) else []
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uq, cnt = np.unique(e, axis=0, return_counts=True)
    bad_e = uq[cnt != 2]
    if len(bad_e):
        pts.append(v[bad_e].mean(axis=1))
    bad_v = nonmanifold_vertex_ids(f, len(v))
    if len(bad_v):
        pts.append(v[bad_v])
    deg = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    if deg.any():
        pts.append(v[f[deg]].mean(axis=1))
    counts = {"self_intersections": int(n_si), "nonmanifold_edges": int(len(bad_e)),
              "nonmanifold_vertices": int(len(bad_v)), "degenerate_faces": int(deg.sum())}
    return (np.concatenate(pts) if pts else np.zeros((0, 3))), counts


def _decimate_unfrozen(v, f, frozen, target):
    """Decimate the faces not frozen (their border kept), stitch the frozen ones back."""
    import fast_simplification

    free = f[~frozen]
    used = np.unique(free)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    u, g = fast_simplification.simplify(v[used], remap[free].astype(np.int32),
                                        target_count=max(int(target) - int(frozen.sum()), 4),
                                        preserve_border=True)
    u = np.asarray(u, dtype=np.float64)
    g = np.asarray(g, dtype=np.int64)
    if not frozen.any():
        return u, g
    fz = f[frozen]
    used2 = np.unique(fz)
    remap2 = np.full(len(v), -1, dtype=np.int64)
    remap2[used2] = np.arange(len(used2))
    p = np.concatenate([u, v[used2]])
    t = np.concatenate([g, len(u) + remap2[fz]])
    # the border vertices were not moved by the decimation: identical coordinates join the two parts
    p, inv = np.unique(p, axis=0, return_inverse=True)
    return p, inv.ravel()[t]


def coarsen_surface(vertices, faces, size: float, volume_tolerance: float = 0.005, rounds: int = 5,
                    freeze_radius: float = 1.5, progress=None):
    """Decimate a closed surface to about the triangle count of edge length ``0.7 size``, without defects.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        Closed, manifold, oriented, free of self-intersections (the caller checks).
    size : float
        Target element edge length (mm).
    volume_tolerance : float
        Largest relative volume change accepted.
    rounds : int
        Bound on the decimate–find defects–freeze rounds.
    freeze_radius : float
        Input triangles whose centroid lies within this many ``size`` of a
        defect are frozen in the next round.
    progress : callable, optional
        ``progress(stage, done, total)`` once per round.

    Returns
    -------
    vertices, faces : arrays
    info : dict
        ``coarsened`` True, ``triangles_in``, ``triangles``, ``rounds``,
        ``frozen_triangles``, ``volume_change``, ``defects`` (per round).

    Raises
    ------
    MeshError
        No defect-free coarse surface within ``rounds`` rounds, or the volume
        moved by more than the tolerance.
    """
    from scipy.spatial import cKDTree

    from porecad.mesh.topology import edge_topology
    from porecad.mesh.validate import signed_volume, surface_area

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    vol = float(signed_volume(v, f))
    target = coarsening_target(float(surface_area(v, f)), size)
    frozen = np.zeros(len(f), dtype=bool)
    centroids = None
    history = []
    for r in range(int(rounds)):
        if progress:
            progress("coarsen surface", r, int(rounds))
        p, t = _decimate_unfrozen(v, f, frozen, target)
        spots, counts = _defect_points(p, t)
        topo = edge_topology(t)
        history.append(counts)
        if not len(spots) and topo["closed"] and topo["manifold"] and topo["oriented"]:
            change = float(signed_volume(p, t)) / vol - 1
            if abs(change) > volume_tolerance:
                raise MeshError(f"coarsening the surface to {size:g} mm elements changes its volume by "
                                f"{100 * change:.2f} %: use a smaller element size")
            if progress:
                progress("coarsen surface", int(rounds), int(rounds))
            return p, t, {"coarsened": True, "triangles_in": int(len(f)), "triangles": int(len(t)),
                          "rounds": r + 1, "frozen_triangles": int(frozen.sum()), "volume_change": change,
                          "defects": history}
        if not len(spots):  # open or misoriented without a located defect: nothing to freeze
            break
        if centroids is None:
            centroids = v[f].mean(axis=1)
            tree = cKDTree(centroids)
        for near in tree.query_ball_point(spots, r=float(freeze_radius) * float(size)):
            frozen[near] = True
    raise MeshError(f"the surface could not be coarsened to {size:g} mm elements without self-intersections "
                    f"({history[-1]}); use a smaller element size")
