"""Removal of sliver tetrahedra by vertex relocation and boundary peeling.

A boundary-preserving Delaunay mesher bounds the radius–edge ratio but not
the dihedral angles: slivers (four nearly coplanar vertices, good radius–edge
ratio) remain, mostly next to the surface (Cheng, Dey & Shewchuk, *Delaunay
Mesh Generation*, CRC 2012, ch. 10). Two local operations remove most of
them:

* vertex relocation: each vertex of a bad tet is moved to the best of a set
  of candidate positions (the centroid of its neighbours and random
  perturbations of up to a third of the local edge length) if that raises the
  smallest dihedral angle of the tets around it and keeps them positive
  ("smart" smoothing, Freitag & Ollivier-Gooch, *Int. J. Numer. Meth. Engng.*
  40 (1997) 3979); surface vertices move only in their tangent plane (by at
  most a quarter of an edge: the volume check bounds what this costs) and
  vertices on the faces of a periodic cell do not move;
* peeling: a sliver whose four vertices lie on the surface and two of whose
  faces are boundary faces is removed (the surface flips across it), when the
  new boundary stays manifold and the tet is not on a periodic face.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["min_dihedral_per_tet", "repair_slivers"]

_FACE = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


@njit(cache=True, inline="always")
def _face_normal(p, i, j, k):
    """Cross product (p[j] - p[i]) × (p[k] - p[i]) as three scalars (no array allocated)."""
    ux, uy, uz = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
    wx, wy, wz = p[k, 0] - p[i, 0], p[k, 1] - p[i, 1], p[k, 2] - p[i, 2]
    return uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx


@njit(cache=True, inline="always")
def _angle(a, b):
    """The dihedral angle (radians) between two outward face normals ``a`` and ``b`` (tuples)."""
    na = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    nb = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    cs = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb)
    return np.pi - np.arccos(min(1.0, max(-1.0, cs)))


@njit(cache=True)
def _min_dihedral(p, t):
    """Smallest dihedral angle (radians) of tet t, or -1 if its volume is not positive.

    Allocation-free: it runs (trials + 1) times for every tet around every moved vertex.
    """
    t0, t1, t2, t3 = t[0], t[1], t[2], t[3]
    ax, ay, az = p[t1, 0] - p[t0, 0], p[t1, 1] - p[t0, 1], p[t1, 2] - p[t0, 2]
    bx, by, bz = p[t2, 0] - p[t0, 0], p[t2, 1] - p[t0, 1], p[t2, 2] - p[t0, 2]
    cx, cy, cz = p[t3, 0] - p[t0, 0], p[t3, 1] - p[t0, 1], p[t3, 2] - p[t0, 2]
    vol = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
    if vol <= 0:
        return -1.0
    n0 = _face_normal(p, t1, t2, t3)  # the faces of _FACE, outward
    n1 = _face_normal(p, t0, t3, t2)
    n2 = _face_normal(p, t0, t1, t3)
    n3 = _face_normal(p, t0, t2, t1)
    return min(_angle(n0, n1), _angle(n0, n2), _angle(n0, n3), _angle(n1, n2), _angle(n1, n3), _angle(n2, n3))


@njit(cache=True, parallel=True)
def _min_dihedral_all(p, t):
    """Smallest dihedral angle (degrees) of every tet; negative for tets of non-positive volume."""
    out = np.empty(len(t))
    for i in prange(len(t)):
        d = _min_dihedral(p, t[i])
        out[i] = d if d < 0 else np.degrees(d)
    return out


def min_dihedral_per_tet(points, tets) -> np.ndarray:
    """(T,) smallest dihedral angle of each tet in degrees (compiled, parallel); -1 for inverted or flat tets."""
    return _min_dihedral_all(np.ascontiguousarray(points, dtype=np.float64),
                             np.ascontiguousarray(tets, dtype=np.int64))


@njit(cache=True)
def _local_quality(p, tets, start, items, v):
    q = 10.0
    for s in range(start[v], start[v + 1]):
        d = _min_dihedral(p, tets[items[s]])
        if d < q:
            q = d
    return q


@njit(cache=True)
def _relocate(p, tets, start, items, mode, normals, verts, seed, trials, step):
    np.random.seed(seed)
    moved = 0
    for v in verts:
        if mode[v] == 0:
            continue
        q0 = _local_quality(p, tets, start, items, v)
        orig = p[v].copy()
        # neighbour centroid and local scale
        cen = np.zeros(3)
        cnt = 0
        for s in range(start[v], start[v + 1]):
            t = tets[items[s]]
            for k in range(4):
                if t[k] != v:
                    cen += p[t[k]]
                    cnt += 1
        cen /= max(cnt, 1)
        scale = 0.0
        for s in range(start[v], start[v + 1]):
            t = tets[items[s]]
            for k in range(4):
                if t[k] != v:
                    scale += np.sqrt(((p[t[k]] - orig) ** 2).sum())
        scale /= max(cnt, 1)
        best = q0
        bestp = orig.copy()
        for trial in range(trials + 1):
            if trial == 0:
                disp = cen - orig
            else:
                r = scale * (0.33 * np.random.random())
                disp = r * (2 * np.random.random(3) - 1)
            if mode[v] == 2:  # on the surface: tangential moves only, at most surface_step edges
                nv = normals[v]
                disp = disp - (disp * nv).sum() * nv
                ln = np.sqrt((disp ** 2).sum())
                if ln > step * scale:
                    disp *= step * scale / ln
            p[v] = orig + disp
            q = _local_quality(p, tets, start, items, v)
            if q > best:
                best = q
                bestp = p[v].copy()
        p[v] = bestp
        if best > q0:
            moved += 1
    return moved


def _vertex_normals(points, bfaces):
    n = np.zeros_like(points)
    fn = np.cross(points[bfaces[:, 1]] - points[bfaces[:, 0]], points[bfaces[:, 2]] - points[bfaces[:, 0]])
    for k in range(3):
        np.add.at(n, bfaces[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(ln > 0, n / np.where(ln > 0, ln, 1), 0.0)


def _boundary(tets):
    from porecad.volmesh import boundary_faces
    return np.asarray(boundary_faces(tets)[0], dtype=np.int64)


def _peel(tets, bad, frozen):
    """Remove bad tets with exactly two boundary faces (a surface edge flip), keeping the surface manifold."""
    bf = _boundary(tets)
    key = lambda a: np.sort(a, axis=1)  # noqa: E731
    bset = {tuple(r) for r in key(bf).tolist()}
    bedges = set()
    for r in bf.tolist():
        for i in range(3):
            bedges.add(tuple(sorted((r[i], r[(i + 1) % 3]))))
    remove = []
    for t in np.flatnonzero(bad):
        tt = tets[t]
        if frozen[tt].sum() >= 3:
            continue
        faces = [tuple(sorted(tt[_FACE[k]].tolist())) for k in range(4)]
        onb = [f in bset for f in faces]
        if sum(onb) != 2:
            continue
        ka, kb = [k for k in range(4) if onb[k]]
        # the boundary edge shared by the two faces is opposite... the new edge joins vertices ka and kb
        new_edge = tuple(sorted((int(tt[ka]), int(tt[kb]))))
        if new_edge in bedges:
            continue
        remove.append(t)
        bedges.add(new_edge)
    if not remove:
        return tets, 0
    keep = np.ones(len(tets), dtype=bool)
    keep[remove] = False
    return tets[keep], len(remove)


def repair_slivers(points, tets, frozen=None, target_deg: float = 15.0, rounds: int = 16, trials: int = 10,
                   peel: bool = True, seed: int = 1, surface_step: float = 0.25, peel_below: float | None = None):
    """Raise the smallest dihedral angles of a tet mesh by relocation and peeling.

    Parameters
    ----------
    points : (V, 3) float array
    tets : (T, 4) int array
        Positively oriented.
    frozen : (V,) bool, optional
        Vertices that must not move (e.g. on periodic faces); those tets are never peeled.
    target_deg : float
        Tets whose smallest dihedral angle is below this are worked on.
    rounds, trials : int
        Passes over the bad tets; candidate positions per vertex and pass.
    peel : bool
        Allow removing boundary slivers (changes the surface by the sliver's volume).
    seed : int
        Random seed (deterministic results).
    surface_step : float
        Largest tangential move of a surface vertex, in units of its mean edge length.
    peel_below : float, optional
        Peel boundary tets whose smallest dihedral angle is below this (degrees);
        default half of ``target_deg``.

    Returns
    -------
    points, tets : arrays
    info : dict
        ``min_dihedral_before_deg``, ``min_dihedral_deg``, ``moved``, ``peeled``.
    """
    p = np.array(points, dtype=np.float64)
    t = np.ascontiguousarray(tets, dtype=np.int64)
    frozen = np.zeros(len(p), bool) if frozen is None else np.asarray(frozen, bool)
    dmin = min_dihedral_per_tet(p, t)
    before = float(dmin.min())
    moved = peeled = 0
    history = []
    csr = bf = None  # recomputed only when the tets change (peeling)
    for r in range(rounds):
        bad = dmin < target_deg
        if not bad.any():
            break
        history.append((float(dmin.min()), int(bad.sum())))
        if r >= 3 and history[-1][0] <= history[-3][0] + 1e-3 and history[-1][1] >= history[-3][1]:
            break  # no progress on the worst tet nor on the count of bad ones over two rounds
        if bf is None:
            bf = _boundary(t)
            on_surface = np.zeros(len(p), bool)
            on_surface[bf.ravel()] = True
            mode = np.where(frozen, 0, np.where(on_surface, 2, 1)).astype(np.int64)
            order = np.argsort(t.ravel(), kind="stable")
            csr = (np.searchsorted(t.ravel()[order], np.arange(len(p) + 1)), (order // 4).astype(np.int64))
        normals = _vertex_normals(p, bf)
        verts = np.unique(t[bad].ravel())
        moved += int(_relocate(p, t, csr[0], csr[1], mode, normals, verts, seed + r, trials,
                               float(surface_step)))
        dmin = min_dihedral_per_tet(p, t)
        if peel and r >= 2:
            peel_bad = dmin < (0.5 * target_deg if peel_below is None else peel_below)
            if peel_bad.any():
                t, k = _peel(t, peel_bad, frozen)
                if k:
                    peeled += k
                    bf = None
                    dmin = min_dihedral_per_tet(p, t)
    used = np.unique(t)
    if len(used) < len(p):  # peeling may orphan a vertex
        remap = np.full(len(p), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        p, t = p[used], remap[t]
    after = float(min_dihedral_per_tet(p, t).min())
    return p, t, {"min_dihedral_before_deg": before, "min_dihedral_deg": after, "moved": moved, "peeled": peeled}
