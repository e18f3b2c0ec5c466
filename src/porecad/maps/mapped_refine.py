"""Local refinement of a mapped triangle mesh where its flat triangles cross (issue 20).

A scaffold built in a parameter domain and mapped vertex by vertex through a
smooth map ``P`` (a TBSS, 001 §3.3) is a piecewise-linear interpolant of the
mapped surface ``P(S)``: each flat triangle is a chord of a curved patch,
off it by about ``h² |D²P| / 8`` for a parametric edge ``h``. Where ``P`` is
strongly anisotropic (scaled Jacobian of a few hundredths near the edges of
a cube map fitted to a smooth body), two triangles that are a fraction of a
sample apart in the parameter domain can come closer than that in space, and
their chords cross although ``P(S)`` itself does not (the parametric mesh is
free of intersections and ``P`` is one-to-one). Measured on the Stanford
bunny's hex fit: every crossing pair without a shared vertex was gone once
both triangles were cut into 16 mapped ones; a uniform 1→4 split of the
whole mesh removed 15 % of them. So the triangles of the crossing pairs (and
a ring of their neighbours) are split in the parameter domain, the new
vertices mapped exactly, until none cross: the surface stays the exact image
of the parametric mesh's refinement, closed and conforming.

The split is red-green refinement (Bank, Sherman & Weiser 1983; Verfürth,
*A Review of A Posteriori Error Estimation and Adaptive Mesh-Refinement
Techniques*, 1996, §4.1): the marked triangles are cut into four at their
edge midpoints, a triangle with one cut edge is bisected from the opposite
corner, one with two cut edges gets its third cut as well (repeated to a
fixed point), so no hanging vertex is left.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["clean_slivers", "refine_mapped_crossings", "split_faces"]


def _edges(faces):
    """Unique edges ``(E, 2)`` and, per face, the index of its edges ``(a, b), (b, c), (c, a)`` ``(m, 3)``."""
    e = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1).reshape(-1, 2)
    key = np.sort(e, axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    return uniq, inv.reshape(-1, 3)


def split_faces(params, faces, marked, periodic=(False, False, False)):
    """Red-green refinement of the ``marked`` faces of a closed triangle mesh in its parameter domain.

    Parameters
    ----------
    params : (n, 3) float
        Vertex parameters (in ``[0, 1]^3``).
    faces : (m, 3) int
        Triangles (orientation kept by every child).
    marked : (m,) bool or int indices
        Faces to cut into four.
    periodic : 3 bools
        Axes along which the parameter wraps at 1 (a welded seam): the
        midpoint of an edge across the seam is taken the short way round.

    Returns
    -------
    params : (n + k, 3) float
        The old vertices first, then the ``k`` edge midpoints.
    faces : (m', 3) int64
    """
    p = np.asarray(params, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    uniq, inv = _edges(f)
    mark = np.zeros(len(uniq), dtype=bool)
    sel = np.zeros(len(f), dtype=bool)
    sel[np.asarray(marked)] = True
    mark[inv[sel].ravel()] = True
    while True:  # green closure: a face with two cut edges gets its third cut too
        cnt = mark[inv].sum(axis=1)
        two = cnt == 2
        if not two.any():
            break
        mark[inv[two].ravel()] = True
    cut = np.flatnonzero(mark)
    a, b = p[uniq[cut, 0]], p[uniq[cut, 1]]
    d = b - a
    for ax in range(3):
        if periodic[ax]:
            d[:, ax] -= np.round(d[:, ax])
    mid = a + 0.5 * d
    for ax in range(3):
        if periodic[ax]:
            mid[:, ax] = np.mod(mid[:, ax], 1.0)
    new_id = np.full(len(uniq), -1, dtype=np.int64)
    new_id[cut] = len(p) + np.arange(len(cut))
    m = new_id[inv]                                  # (faces, 3) midpoint of edge k or -1
    cnt = (m >= 0).sum(axis=1)
    out = [f[cnt == 0]]
    r = cnt == 3
    if r.any():
        fa, ma = f[r], m[r]
        out += [np.stack([fa[:, 0], ma[:, 0], ma[:, 2]], 1), np.stack([fa[:, 1], ma[:, 1], ma[:, 0]], 1),
                np.stack([fa[:, 2], ma[:, 2], ma[:, 1]], 1), ma[:, [0, 1, 2]]]
    g = np.flatnonzero(cnt == 1)
    if g.size:
        k = np.argmax(m[g] >= 0, axis=1)            # the cut edge (F[k], F[k+1]); the opposite corner F[k+2]
        fg = f[g]
        ar = np.arange(len(g))
        s0, s1, o = fg[ar, k], fg[ar, (k + 1) % 3], fg[ar, (k + 2) % 3]
        mm = m[g, k]
        out += [np.stack([s0, mm, o], 1), np.stack([mm, s1, o], 1)]
    return np.concatenate([p, mid]), np.concatenate(out).astype(np.int64)


def _ring(faces, face_ids, n_vertices, rings):
    """The faces sharing a vertex with ``face_ids``, ``rings`` times over (a boolean face mask)."""
    sel = np.zeros(len(faces), dtype=bool)
    sel[face_ids] = True
    for _ in range(int(rings)):
        touched = np.zeros(n_vertices, dtype=bool)
        touched[faces[sel].ravel()] = True
        sel |= touched[faces].any(axis=1)
    return sel


def _metric_scale(map_jacobian, params):
    """Per-axis lengths (median column norms of the map's Jacobian at ``params``): a parameter metric near them."""
    J = np.asarray(map_jacobian(params[:, 0], params[:, 1], params[:, 2]))
    return np.maximum(np.median(np.linalg.norm(J, axis=1), axis=0), 1e-300)


def clean_slivers(vertices, params, faces, map_points, map_jacobian, face_ids, rings: int = 2,
                  min_angle: float = 10.0):
    """Collapse needles and flip caps among the faces near ``face_ids``, in the parameter domain.

    Marching cubes leaves slivers (angles far below 1°) where the level set
    passes close to a sample; halving a sliver's edges keeps its shape, so a
    mapped sliver whose chord crosses a neighbour keeps crossing however often
    it is split. Near the crossing faces (``rings`` rings), with the parameter
    axes scaled by the map's local stretch (the median column norms of its
    Jacobian there, so that angles are about those of the mapped mesh),
    needles are collapsed and caps flipped
    (:func:`porecad.simulate.surface_slivers.remove_sliver_triangles`); the
    vertices on the parameter cube's faces stay fixed, so caps stay on the
    faces and seams stay welded. Moved vertices are mapped again: the surface
    stays the exact image of a closed parametric mesh.

    Returns ``vertices, params, faces, info``.
    """
    from ..simulate.surface_slivers import remove_sliver_triangles
    p = np.asarray(params, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    region_f = _ring(f, face_ids, len(p), rings)
    region = np.zeros(len(p), dtype=bool)
    region[f[region_f].ravel()] = True
    scale = _metric_scale(map_jacobian, p[region])
    on_face = np.any((p <= 1e-12) | (p >= 1.0 - 1e-12), axis=1)
    q, f2, info = remove_sliver_triangles(p * scale, f, min_angle=min_angle, fixed=on_face | ~region,
                                          active=region)
    p2 = q / scale
    p2[np.abs(p2) <= 1e-12] = 0.0
    p2[np.abs(p2 - 1.0) <= 1e-12] = 1.0
    p2 = np.clip(p2, 0.0, 1.0)
    info = {k: info[k] for k in ("collapsed", "flipped", "passes")}
    return np.asarray(map_points(p2), dtype=np.float64), p2, f2, info


def refine_mapped_crossings(vertices, params, faces, map_points, map_jacobian=None, periodic=(False, False, False),
                            max_rounds: int = 6, rings: int = 1, max_faces: int = 20_000_000, pairs=None,
                            clean_from: int = 2, give_up: float | None = None):
    """Split the crossing triangles of a mapped mesh in its parameter domain until none cross.

    Parameters
    ----------
    vertices : (n, 3) float
        ``map_points(params)``, the mapped vertices.
    params : (n, 3) float
        Their parameters; the parametric mesh ``(params, faces)`` must be free
        of intersections (e.g. marching cubes with caps).
    faces : (m, 3) int
    map_points : callable
        ``(k, 3)`` parameters → ``(k, 3)`` points (e.g. :meth:`porecad.splines.TBSS.map_points`).
    map_jacobian : callable, optional
        ``(u, v, w)`` → ``(k, 3, 3)`` Jacobians (:meth:`porecad.splines.TBSS.jacobian`);
        with it, rounds from ``clean_from`` on first clean the slivers near
        the crossings (:func:`clean_slivers`).
    periodic : 3 bools
        Seams of the parameter domain (see :func:`split_faces`).
    max_rounds : int
        Refinement rounds at most (each cuts the marked triangles' edges in two).
    rings : int
        Rings of neighbouring faces refined with each crossing face.
    max_faces : int
        Stop before a round that could exceed this many faces (bounds memory).
    pairs : (k, 2) int, optional
        The crossing pairs of the input when already known.
    give_up : float, optional
        Stop when a round leaves more than this many times the crossings the
        input had (at least 32): splitting is not separating them (without the
        sliver cleaning of ``map_jacobian``, the hex job's case).

    Returns
    -------
    vertices, params, faces
        The refined mesh (unchanged when nothing crossed), its vertices rounded
        as mesh files store them (:func:`~porecad.mesh.validate.stored_coordinates`).
    info : dict
        ``pairs_before``, ``pairs_after`` (exact count on the returned mesh, as stored),
        ``rounds``, ``faces_before``, ``faces_after``, ``slivers``
        (needles collapsed and caps flipped); ``stopped`` says why refinement
        ended early.
    """
    from ..mesh.validate import stored_coordinates
    v, p, f, pairs, total = _crossing_start(vertices, params, faces, pairs)

    def mapped(q):  # the map's points as they will be stored
        return stored_coordinates(map_points(q))

    info = {"pairs_before": int(total), "pairs_after": int(total), "rounds": 0, "faces_before": int(len(f)),
            "faces_after": int(len(f)), "slivers": 0}
    for rnd in range(int(max_rounds)):
        if total == 0:
            break
        info["rounds"] = rnd + 1
        jac = map_jacobian if rnd >= clean_from else None
        v, p, f, pairs, total = _refine_round(v, p, f, pairs, total, mapped, jac, rings, max_faces, periodic,
                                              give_up, info)
        if "stopped" in info:
            break
    info["pairs_after"] = int(total)
    info["faces_after"] = int(len(f))
    return v, p, f, info


def _crossing_start(vertices, params, faces, pairs):
    """The input mesh as stored, checked, with its crossing pairs.

    Takes the vertices, parameters, faces and the known pairs (or None); returns ``v`` (stored
    coordinates), ``p``, ``f``, the pairs ``(k, 2)`` and their total count. Raises InputError when
    vertices and parameters differ in shape.
    """
    from ..mesh.intersections import self_intersections
    from ..mesh.validate import stored_with
    v, pairs = stored_with(vertices, pairs)
    v = np.asarray(v, dtype=np.float64)
    p = np.asarray(params, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.shape != p.shape:
        raise InputError(f"vertices {v.shape} and parameters {p.shape} differ in shape")
    if pairs is None:
        pairs, total = self_intersections(v, f, max_report=1 << 20)
    else:
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        total = len(pairs)
    return v, p, f, pairs, total


def _refine_round(v, p, f, pairs, total, mapped, map_jacobian, rings, max_faces, periodic, give_up, info):
    """One refinement round of :func:`refine_mapped_crossings` on the mesh ``(v, p, f)`` crossing at ``pairs``
    (``total`` of them, counted).

    With ``map_jacobian`` (None: no cleaning this round) the slivers near the crossings are cleaned first
    (``info["slivers"]`` counts them); then the crossing faces and ``rings`` of neighbours are split in the
    parameter domain and the new vertices mapped by ``mapped``. Sets ``info["stopped"]`` when the round
    would pass ``max_faces`` (nothing split) or multiplied the crossings past ``give_up``. Returns the new
    ``v, p, f``, the pairs and their total.
    """
    from ..mesh.intersections import self_intersections
    if map_jacobian is not None:
        v, p, f, cl = clean_slivers(v, p, f, mapped, map_jacobian, np.unique(pairs.ravel()))
        info["slivers"] += cl["collapsed"] + cl["flipped"]
        pairs, total = self_intersections(v, f, max_report=1 << 20)
        if total == 0:
            return v, p, f, pairs, total
    sel = _ring(f, np.unique(pairs.ravel()), len(p), rings)
    if len(f) + 3 * 3 * int(sel.sum()) > max_faces:  # closure can cut a few neighbours more
        info["stopped"] = f"the next round would pass {max_faces:,} faces"
        return v, p, f, pairs, total
    n_old = len(p)
    p, f = split_faces(p, f, sel, periodic)
    v = np.concatenate([v, mapped(np.clip(p[n_old:], 0.0, 1.0))])
    pairs, total = self_intersections(v, f, max_report=1 << 20)
    if give_up is not None and total > give_up * max(info["pairs_before"], 32):
        # measured: the femur's 5x7x20 D hex scaffold 12 -> 45 -> 190 -> ... -> 45,826 pairs in six rounds
        # (53 s), the segmented body's hex20 21 -> 24 -> 24 -> 63 -> 106 -> ... -> 5,880; but the femur's
        # 5x7x20 G 3 -> 10 -> 17 -> 0 and the bone's hex20 29 -> 22 -> 8 -> 0
        info["stopped"] = f"splitting multiplied the crossings ({info['pairs_before']} -> {total})"
    return v, p, f, pairs, total
