"""Removal of sliver triangles from a closed surface: needle collapse and cap flips.

Marching cubes leaves triangles with angles far below 1° wherever the level
set passes close to a sample: *needles* (one edge much shorter than the other
two) and *caps* (one angle near 180°). A mesher that keeps the surface
(TetGen ``-Y``) turns each into a sliver tet that no vertex relocation can
repair. Each is removed by the local operation that fits its shape (the
classification of Botsch et al., *Polygon Mesh Processing*, AK Peters 2010,
§6.4 and §7.3; the operations of Hoppe et al., "Mesh optimization",
SIGGRAPH 1993):

* a needle's short edge is collapsed (the two vertices merged at one end or
  at the midpoint, whichever leaves the best triangles), when the link
  condition holds (Dey, Edelsbrunner, Guha & Nekhayev, "Topology preserving
  edge contraction", 1999), so the surface stays a closed 2-manifold of the
  same topology;
* a cap's longest edge is flipped when the two triangles on it are nearly
  coplanar, so the surface hardly moves.

Every operation must raise the smallest angle of the triangles it touches,
must not turn any sound triangle's normal by more than ``max_turn`` degrees,
and moves the surface by at most the length of the collapsed edge (or the
height of the flipped pair); vertices marked fixed never move. Operations in
one pass touch disjoint neighbourhoods, so each is checked against the mesh it
changes. The caller checks the result (closed, manifold, no
self-intersections, volume).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["remove_sliver_triangles"]


@njit(cache=True)
def _angles_kernel(p):
    out = np.empty((p.shape[0], 3))
    for t in range(p.shape[0]):
        for i in range(3):
            j, k = (i + 1) % 3, (i + 2) % 3
            uu = ww = uw = 0.0
            for d in range(3):
                u = p[t, j, d] - p[t, i, d]
                w = p[t, k, d] - p[t, i, d]
                uu += u * u
                ww += w * w
                uw += u * w
            den = np.sqrt(uu) * np.sqrt(ww)
            c = uw / den if den > 0.0 else 1.0
            if not np.isfinite(c):
                c = 1.0
            out[t, i] = np.degrees(np.arccos(min(max(c, -1.0), 1.0)))
    return out


def _angles(p):
    """(F, 3) corner angles (degrees) of triangles given as (F, 3, 3) points (a degenerate corner: 0)."""
    return _angles_kernel(np.ascontiguousarray(p, dtype=np.float64))


@njit(cache=True)
def _unit_normals_kernel(p):
    n = np.empty((p.shape[0], 3))
    ln = np.empty(p.shape[0])
    for t in range(p.shape[0]):
        ux, uy, uz = p[t, 1, 0] - p[t, 0, 0], p[t, 1, 1] - p[t, 0, 1], p[t, 1, 2] - p[t, 0, 2]
        wx, wy, wz = p[t, 2, 0] - p[t, 0, 0], p[t, 2, 1] - p[t, 0, 1], p[t, 2, 2] - p[t, 0, 2]
        cx, cy, cz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
        m = np.sqrt(cx * cx + cy * cy + cz * cz)
        ln[t] = m
        s = m if m > 0.0 else 1.0
        n[t, 0], n[t, 1], n[t, 2] = cx / s, cy / s, cz / s
    return n, ln


def _unit_normals(p):
    """Unit normals (F, 3) and twice the areas (F,) of triangles given as (F, 3, 3) points."""
    return _unit_normals_kernel(np.ascontiguousarray(p, dtype=np.float64))


@njit(cache=True)
def _min_fold_kernel(points, tris, sound):
    n_t = tris.shape[0]
    p = np.empty((n_t, 3, 3))
    for t in range(n_t):
        for c in range(3):
            p[t, c] = points[tris[t, c]]
    n, _ = _unit_normals_kernel(p)
    key = np.empty(3 * n_t, dtype=np.int64)
    big = points.shape[0] + 1
    for t in range(n_t):
        for c in range(3):
            a, b = tris[t, c], tris[t, (c + 1) % 3]
            key[3 * t + c] = min(a, b) * big + max(a, b)
    order = np.argsort(key, kind="mergesort")
    best = 1.0
    for k in range(len(order) - 1):
        e0, e1 = order[k], order[k + 1]
        if key[e0] != key[e1]:
            continue
        t0, t1 = e0 // 3, e1 // 3
        if not (sound[t0] and sound[t1]):
            continue
        c = n[t0, 0] * n[t1, 0] + n[t0, 1] * n[t1, 1] + n[t0, 2] * n[t1, 2]
        best = min(best, c)
    return best


def _min_fold(points, tris, sound=None):
    """Smallest cosine between the normals of two triangles of ``tris`` sharing an edge (1 if none).

    With ``sound`` (bool per triangle), only pairs of sound triangles count.
    """
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    sound = np.ones(len(tris), dtype=np.bool_) if sound is None else np.ascontiguousarray(sound, dtype=np.bool_)
    return float(_min_fold_kernel(np.ascontiguousarray(points, dtype=np.float64), tris, sound))


def _vertex_faces(faces, n):
    flat = faces.ravel()
    order = np.argsort(flat, kind="stable")
    start = np.searchsorted(flat[order], np.arange(n + 1))
    return start, (order // 3).astype(np.int64)


class _Pass:
    """One pass of independent operations on a mutable copy of the mesh."""

    def __init__(self, v, f, fixed, max_turn, sound_angle, max_move):
        self.v, self.f, self.fixed = v, f, fixed
        self.max_move = max_move
        self.start, self.items = _vertex_faces(f, len(v))
        self.alive = np.ones(len(f), dtype=bool)
        self.locked = np.zeros(len(v), dtype=bool)
        self.cos_turn = np.cos(np.radians(max_turn))
        self.sound_angle = sound_angle
        self.rejected = {}

    def no(self, why):
        self.rejected[why] = self.rejected.get(why, 0) + 1
        return False

    def ring(self, a):
        fs = self.items[self.start[a]:self.start[a + 1]]
        return fs[self.alive[fs]]

    def collapse(self, a, b, fa):
        """Collapse edge a-b (fa: the two faces on it); returns True if done."""
        v, f = self.v, self.f
        if self.fixed[a] and self.fixed[b]:
            return self.no("fixed")
        if np.linalg.norm(v[a] - v[b]) > self.max_move:
            return self.no("too-long")
        ra, rb = self.ring(a), self.ring(b)
        ring = np.union1d(ra, rb)
        verts = np.unique(f[ring])
        if self.locked[verts].any():
            return self.no("locked")
        na = set(f[ra].ravel().tolist()) - {a}
        nb = set(f[rb].ravel().tolist()) - {b}
        opp = [int(x) for x in np.setdiff1d(f[fa].ravel(), [a, b])]
        if len(opp) != 2 or na & nb != set(opp):  # link condition
            return self.no("link")
        for o in opp:  # the opposite vertices keep at least three neighbours
            if len(self.ring(o)) <= 3:
                return self.no("valence")
        keep = np.setdiff1d(ring, fa)
        region = np.unique(np.concatenate([self.ring(x) for x in verts.tolist()]))
        rest = np.setdiff1d(region, ring)
        reg_old = f[np.concatenate([ring, rest])]
        fold0 = min(_min_fold(v, reg_old, _angles(v[reg_old]).min(axis=1) >= 1.0), 0.0)
        old_p = v[f[ring]]
        n_old, _ = _unit_normals(v[f[keep]])
        sound = _angles(v[f[keep]]).min(axis=1) >= self.sound_angle
        new_f = np.where(f[keep] == b, a, f[keep])
        cands = [v[a]] if self.fixed[a] else [v[b]] if self.fixed[b] else [v[a], v[b], 0.5 * (v[a] + v[b])]
        a_old = _angles(old_p).min()
        best, best_q = None, a_old + 1e-9
        for c in cands:
            q = v[new_f]
            q[new_f == a] = c
            n_new, ln = _unit_normals(q)
            if (ln <= 0).any():
                continue
            if (np.einsum("ij,ij->i", n_old[sound], n_new[sound]) < self.cos_turn).any():
                continue
            if (np.einsum("ij,ij->i", n_old, n_new) < 0).any():  # nothing folds over
                continue
            qa = _angles(q).min()
            if qa > best_q:
                saved = v[a].copy()
                v[a] = c
                fold1 = _min_fold(v, np.concatenate([new_f, f[rest]]))
                v[a] = saved
                if fold1 < fold0 - 1e-9:
                    continue
                best, best_q = c, qa
        if best is None:
            return self.no("collapse-turn-or-worse")
        v[a] = best
        f[keep] = new_f
        self.alive[fa] = False
        self.locked[verts] = True
        # b's faces now belong to a: the adjacency of this pass is stale there, but those vertices are locked
        return True

    def flip(self, a, b, fa):
        """Flip edge a-b shared by faces fa = (f1, f2); returns True if done."""
        v, f = self.v, self.f
        f1, f2 = int(fa[0]), int(fa[1])
        t1 = f[f1].tolist()
        k = t1.index(a)
        if t1[(k + 1) % 3] != b:  # orient so that f1 = (a, b, c)
            a, b = b, a
            k = t1.index(a)
        c = t1[(k + 2) % 3]
        d = [x for x in f[f2].tolist() if x != a and x != b][0]
        verts = np.array([a, b, c, d])
        if self.locked[verts].any() or c == d:
            return self.no("locked")
        nc = set(f[self.ring(c)].ravel().tolist())
        if d in nc:  # edge c-d exists already
            return self.no("flip-edge-exists")
        if len(self.ring(a)) <= 3 or len(self.ring(b)) <= 3:
            return self.no("valence")
        new = np.array([[a, d, c], [b, c, d]])
        old_p = v[f[[f1, f2]]]
        new_p = v[new]
        if _angles(new_p).min() <= _angles(old_p).min() + 1e-9:
            return self.no("flip-worse")
        n_old, _ = _unit_normals(old_p)
        n_new, ln = _unit_normals(new_p)
        if (ln <= 0).any():
            return self.no("flip-degenerate")
        # the surface moves by the height of the tet a b c d over the new triangles
        vol6 = abs(np.dot(v[b] - v[a], np.cross(v[c] - v[a], v[d] - v[a])))
        if vol6 > self.max_move * ln.min():
            return self.no("flip-moves-too-far")
        sound = _angles(old_p).min(axis=1) >= self.sound_angle
        ref = n_old[sound] if sound.any() else n_old
        if (ref @ n_new.T < self.cos_turn).any():
            return self.no("flip-turn")
        region = np.unique(np.concatenate([self.ring(x) for x in (a, b, c, d)]))
        rest = np.setdiff1d(region, [f1, f2])
        reg_old = f[region]
        fold0 = min(_min_fold(v, reg_old, _angles(v[reg_old]).min(axis=1) >= 1.0), 0.0)
        if _min_fold(v, np.concatenate([new, f[rest]])) < fold0 - 1e-9:
            return self.no("flip-fold")
        f[f1], f[f2] = new[0], new[1]
        self.locked[verts] = True
        return True


def _edge_faces(f):
    """Unique edges (E, 2, sorted), their faces (E, 2; -1 for the second face of a border edge), and the
    number of faces on each edge (E,)."""
    e = np.sort(np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    face = np.repeat(np.arange(len(f)), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, face = e[order], face[order]
    start = np.flatnonzero(np.r_[True, np.any(e[1:] != e[:-1], axis=1)])
    count = np.diff(np.r_[start, len(e)])
    ef = np.stack([face[start], np.where(count > 1, face[np.minimum(start + 1, len(e) - 1)], -1)], axis=1)
    return e[start], ef, count


def _near(f, marked, rings):
    """``marked`` (bool per vertex) grown by ``rings`` rings of the triangles ``f``."""
    marked = marked.copy()
    for _ in range(rings):
        marked[f[marked[f].any(axis=1)]] = True
    return marked


def remove_sliver_triangles(vertices, faces, min_angle: float = 12.0, fixed=None, max_move: float | None = None,
                            max_turn: float = 30.0, sound_angle: float = 5.0, max_passes: int = 30, active=None):
    """Collapse needles and flip caps until no triangle has an angle below ``min_angle`` (or no move helps).

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        A closed, oriented 2-manifold.
    min_angle : float
        Triangles with a smaller angle (degrees) are worked on.
    fixed : (V,) bool array, optional
        Vertices that must not move (e.g. on the faces of a periodic cell).
    max_move : float, optional
        Largest distance the surface may move in one operation (the collapsed edge's length,
        the flipped pair's height); default half the mean edge length.
    max_turn : float
        Largest turn (degrees) of the normal of any triangle whose angles are all
        at least ``sound_angle`` (the normals of slivers themselves carry no information).
    sound_angle : float
    max_passes : int
        Bound on the passes over the bad triangles.
    active : (V,) bool array, optional
        Work only on triangles with all three vertices active (a local clean-up;
        default: every triangle).

    Returns
    -------
    vertices, faces : arrays
        Unused vertices dropped; faces keep their orientation.
    info : dict
        ``collapsed``, ``flipped``, ``passes``, ``min_angle_in_deg``, ``min_angle_deg``,
        ``below_min_angle`` (triangles still below ``min_angle``).
    """
    v = np.array(vertices, dtype=np.float64)
    f = np.array(faces, dtype=np.int64)
    fixed = np.zeros(len(v), dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool).copy()
    active = None if active is None else np.asarray(active, dtype=bool)
    ang = _angles(v[f])
    info = {"min_angle_in_deg": float(ang.min()), "collapsed": 0, "flipped": 0, "passes": 0}
    rejected = {}
    if max_move is None:
        max_move = 0.5 * float(np.linalg.norm(v[f[:, [1, 2, 0]]] - v[f], axis=2).mean())
    if (_edge_faces(f)[2] != 2).any():
        raise ValueError("remove_sliver_triangles needs a closed 2-manifold surface")
    # a local clean-up works on the triangles near the active ones: every ring an operation reads is there
    near = None if active is None else _near(f, active, 3)
    for it in range(int(max_passes)):
        sub = None if near is None else np.flatnonzero(near[f].any(axis=1))
        fs = f if sub is None else f[sub]
        ang = _angles(v[fs])
        bad = ang.min(axis=1) < min_angle
        if active is not None:
            bad &= active[fs].all(axis=1)
        bad = np.flatnonzero(bad)
        if len(bad) == 0:
            break
        info["passes"] = it + 1
        pas = _Pass(v, fs, fixed, max_turn, sound_angle, float(max_move))
        done = _sliver_pass(pas, ang, bad, info)
        alive = pas.alive
        if sub is not None:
            f[sub] = fs
            alive = np.ones(len(f), dtype=bool)
            alive[sub] = pas.alive
        f = f[alive]
        for k, n in pas.rejected.items():
            rejected[k] = rejected.get(k, 0) + n
        if done == 0:
            break
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    v, f = v[used], remap[f]
    ang = _angles(v[f]).min(axis=1)
    info.update({"min_angle_deg": float(ang.min()), "below_min_angle": int((ang < min_angle).sum()),
                 "rejected": rejected})
    return v, f, info


def _sliver_pass(pas, ang, bad, info):
    """One pass over the bad triangles, worst first: collapse needles, flip caps.

    Takes the :class:`_Pass` (whose vertices and faces it changes in place),
    the corner angles ``ang`` of every face, the indices ``bad`` of the
    faces to work on, and the ``info`` dict (``collapsed`` and ``flipped``
    counted up in place); returns the number of operations done. The faces
    may be a patch of a closed surface that holds every ring the operations read.
    """
    v, f = pas.v, pas.f
    edges, ef, _ = _edge_faces(f)
    # edge index of each face side (side i is opposite corner i)
    key = edges[:, 0] * len(v) + edges[:, 1]
    side = np.sort(np.stack([f[:, [1, 2]], f[:, [2, 0]], f[:, [0, 1]]], axis=1), axis=2)
    side_key = side[..., 0] * len(v) + side[..., 1]
    lens = np.linalg.norm(v[f[:, [2, 0, 1]]] - v[f[:, [1, 2, 0]]], axis=2)  # side i, opposite corner i
    done = 0
    for t in bad[np.argsort(ang[bad].min(axis=1))]:
        if not pas.alive[t] or pas.locked[f[t]].any():
            continue
        ls = lens[t]
        i_short, i_long = int(np.argmin(ls)), int(np.argmax(ls))
        mid = 3 - i_short - i_long
        if ls[i_short] < 0.5 * ls[mid]:  # a needle: collapse the short edge
            i = i_short
        else:  # a cap: flip the long edge
            i = i_long
        a, b = int(f[t, (i + 1) % 3]), int(f[t, (i + 2) % 3])
        e = int(np.searchsorted(key, side_key[t, i]))
        fa = ef[e]
        if i == i_short and ls[i_short] < 0.5 * ls[mid]:
            ok = pas.collapse(a, b, fa)
            if not ok:  # a needle that cannot collapse may still flip its long edge
                ok2 = pas.flip(int(f[t, (i_long + 1) % 3]), int(f[t, (i_long + 2) % 3]),
                               ef[int(np.searchsorted(key, side_key[t, i_long]))])
                info["flipped"] += int(ok2)
                done += int(ok2)
            else:
                info["collapsed"] += 1
                done += 1
        else:
            ok = pas.flip(a, b, fa)
            info["flipped"] += int(ok)
            done += int(ok)
    return done
