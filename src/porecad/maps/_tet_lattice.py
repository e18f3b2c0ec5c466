"""Numba kernels of :mod:`porecad.maps.tis_mesh`: the barycentric lattice of a tet mesh.

Every tetrahedron is split into ``n³`` small tetrahedra by the Freudenthal
(Kuhn) subdivision of its barycentric lattice ``{w ∈ ℕ⁴ : Σ w = n}``, taken in
the order of the tetrahedron's global vertex ids. A lattice point is written
in cumulative coordinates ``x = (w1 + w2 + w3, w2 + w3, w3)``,
``n ≥ x1 ≥ x2 ≥ x3 ≥ 0``; the small tetrahedra are ``c, c + e_a, c + e_a + e_b,
c + (1, 1, 1)`` for each permutation (a, b, c) of the axes. Because the order
is the global id order, the subdivision restricted to a face is the face's own
Freudenthal subdivision in the order of its ids: two tetrahedra sharing a
face cut it into the same small triangles, so marching tetrahedra produces the
same vertices on it from both sides (consistent face sampling).

Global lattice ids: the mesh vertices first, then ``n − 1`` points per edge,
``(n − 1)(n − 2)/2`` per face and ``(n − 1)(n − 2)(n − 3)/6`` per tetrahedron.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..fields.tis import tis_scalar

TAU = 2.0 * np.pi

# local edge index of the sorted vertex pair (p, q), p < q
_PAIR = np.array([[-1, 0, 1, 2], [0, -1, 3, 4], [1, 3, -1, 5], [2, 4, 5, -1]], np.int64)
# axis permutations of the Freudenthal subdivision and their signs
_PERMS = np.array([[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]], np.int64)
_PERM_SIGN = np.array([1, -1, -1, 1, 1, -1], np.int64)


def _case_table():
    """Marching-tetrahedra triangles per case (bit k: vertex k is material).

    For a positively oriented tetrahedron (0, 1, 2, 3) and an even permutation
    (i, j, k, l) of it, the triangle on the edges (i, j), (i, k), (i, l) faces
    away from vertex i; the quad on (i, k), (i, l), (j, l), (j, k) faces from
    {i, j} towards {k, l}. Triangles are oriented out of the material.
    """
    import itertools

    even = [p for p in itertools.permutations(range(4))
            if sum(1 for a in range(4) for b in range(a + 1, 4) if p[a] > p[b]) % 2 == 0]
    ntri = np.zeros(16, np.int64)
    edges = np.zeros((16, 2, 3, 2), np.int64)
    for mask in range(16):
        solid = [v for v in range(4) if mask >> v & 1]
        if len(solid) in (0, 4):
            continue
        if len(solid) in (1, 3):
            lone = solid[0] if len(solid) == 1 else [v for v in range(4) if v not in solid][0]
            i, j, k, l = next(p for p in even if p[0] == lone)
            tri = [(i, j), (i, k), (i, l)] if len(solid) == 1 else [(i, j), (i, l), (i, k)]
            ntri[mask] = 1
            edges[mask, 0] = tri
        else:
            i, j, k, l = next(p for p in even if set(p[:2]) == set(solid))
            ntri[mask] = 2
            edges[mask, 0] = [(i, k), (i, l), (j, l)]
            edges[mask, 1] = [(i, k), (j, l), (j, k)]
    return ntri, edges


CASE_NTRI, CASE_EDGES = _case_table()


@njit(cache=True)
def lattice_counts(n, V, E, F):
    """(edge base, face base, interior base, points per face, per tet interior)."""
    nf = (n - 1) * (n - 2) // 2
    ni = (n - 1) * (n - 2) * (n - 3) // 6
    eb = V
    fb = V + E * (n - 1)
    ib = fb + F * nf
    return eb, fb, ib, nf, ni


@njit(cache=True)
def lattice_gid(w0, w1, w2, w3, t, tv, edge_ids, face_ids, n, eb, fb, ib, nf, ni):
    """Global id of the lattice point with integer weights w (sorted local order) of tet t."""
    w = (w0, w1, w2, w3)
    nz = (w0 > 0) + (w1 > 0) + (w2 > 0) + (w3 > 0)
    if nz == 1:
        for i in range(4):
            if w[i] > 0:
                return tv[t, i]
    if nz == 2:
        p = -1
        q = -1
        for i in range(4):
            if w[i] > 0:
                if p < 0:
                    p = i
                else:
                    q = i
        e = edge_ids[t, _PAIR[p, q]]
        return eb + e * (n - 1) + w[q] - 1
    if nz == 3:
        k = 0
        for i in range(4):
            if w[i] == 0:
                k = i
        # the two larger-order vertices of the face
        qq = -1
        rr = -1
        first = True
        for i in range(4):
            if i != k:
                if first:
                    first = False
                elif qq < 0:
                    qq = i
                else:
                    rr = i
        P = w[qq] - 1
        Q = w[rr] - 1
        m = n - 3
        idx = P * (m + 1) - P * (P - 1) // 2 + Q
        return fb + face_ids[t, k] * nf + idx
    y1 = w1 + w2 + w3 - 3
    y2 = w2 + w3 - 2
    y3 = w3 - 1
    idx = y1 * (y1 + 1) * (y1 + 2) // 6 + y2 * (y2 + 1) // 2 + y3
    return ib + t * ni + idx


@njit(cache=True, parallel=True)
def lattice_tables(tv, edge_ids, face_ids, n, V, E, F):
    """Global lattice id of every local lattice point of every tet, (T, L) with L = C(n+3, 3)."""
    eb, fb, ib, nf, ni = lattice_counts(n, V, E, F)
    T = tv.shape[0]
    L = (n + 1) * (n + 2) * (n + 3) // 6
    tables = np.empty((T, L), np.int64)
    for item in prange(T * (n + 1)):
        t = item // (n + 1)
        x1 = item % (n + 1)
        for x2 in range(x1 + 1):
            for x3 in range(x2 + 1):
                tables[t, _li(x1, x2, x3)] = lattice_gid(n - x1, x1 - x2, x2 - x3, x3, t, tv, edge_ids, face_ids,
                                                         n, eb, fb, ib, nf, ni)
    return tables


@njit(cache=True, parallel=True)
def lattice_values(points, tv, slots, lam, tables, n, code, owner, vals, pos):
    """TIS value and position of every lattice point, computed in its owner tet.

    ``slots[t, i]``: the TIS coordinate (0..3 = α..δ) of sorted vertex i of tet t;
    ``lam[t, i]``: its λ; ``owner[g]``: the tet whose coordinates give point g its value.
    """
    T = tv.shape[0]
    for item in prange(T * (n + 1)):
        t = item // (n + 1)
        x1 = item % (n + 1)
        theta = np.empty(4)
        for x2 in range(x1 + 1):
            for x3 in range(x2 + 1):
                g = tables[t, _li(x1, x2, x3)]
                if owner[g] != t:
                    continue
                w0 = n - x1
                w1 = x1 - x2
                w2 = x2 - x3
                w3 = x3
                for a in range(3):
                    pos[g, a] = (w0 * points[tv[t, 0], a] + w1 * points[tv[t, 1], a]
                                 + w2 * points[tv[t, 2], a] + w3 * points[tv[t, 3], a]) / n
                theta[slots[t, 0]] = TAU * lam[t, 0] * w0 / n
                theta[slots[t, 1]] = TAU * lam[t, 1] * w1 / n
                theta[slots[t, 2]] = TAU * lam[t, 2] * w2 / n
                theta[slots[t, 3]] = TAU * lam[t, 3] * w3 / n
                vals[g] = tis_scalar(code, theta[0], theta[1], theta[2], theta[3])


@njit(cache=True, inline="always")
def _li(x1, x2, x3):
    return x1 * (x1 + 1) * (x1 + 2) // 6 + x2 * (x2 + 1) // 2 + x3


@njit(cache=True)
def _march_slice(t, c1, tables, tet_sign, vals, level, ntri, cedges, out, start, write):
    """Marching tetrahedra over the small tets of tet t with base x1 = c1; returns the triangle count."""
    cnt = 0
    g = np.empty(4, np.int64)
    x = np.empty((4, 3), np.int64)
    for c2 in range(c1 + 1):
        for c3 in range(c2 + 1):
            # skip cubes whose lattice corners all lie on one side of the level
            n_in = 0
            n_valid = 0
            for d in range(8):
                y1 = c1 + (d & 1)
                y2 = c2 + (d >> 1 & 1)
                y3 = c3 + (d >> 2 & 1)
                if y1 >= y2 and y2 >= y3:
                    n_valid += 1
                    if vals[tables[t, _li(y1, y2, y3)]] >= level:
                        n_in += 1
            if n_in == 0 or n_in == n_valid:
                continue
            for p in range(6):
                a = _PERMS[p, 0]
                b = _PERMS[p, 1]
                x[0, 0] = c1
                x[0, 1] = c2
                x[0, 2] = c3
                for k in range(3):
                    x[1, k] = x[0, k]
                x[1, a] += 1
                for k in range(3):
                    x[2, k] = x[1, k]
                x[2, b] += 1
                for k in range(3):
                    x[3, k] = x[0, k] + 1
                if x[1, 0] < x[1, 1] or x[1, 1] < x[1, 2] or x[2, 0] < x[2, 1] or x[2, 1] < x[2, 2]:
                    continue
                for v in range(4):
                    g[v] = tables[t, _li(x[v, 0], x[v, 1], x[v, 2])]
                if _PERM_SIGN[p] * tet_sign[t] < 0:
                    tmp = g[2]
                    g[2] = g[3]
                    g[3] = tmp
                mask = 0
                for v in range(4):
                    if vals[g[v]] >= level:
                        mask |= 1 << v
                m = ntri[mask]
                if m == 0:
                    continue
                if write:
                    for r in range(m):
                        row = start + cnt + r
                        for s in range(3):
                            ga = g[cedges[mask, r, s, 0]]
                            gb = g[cedges[mask, r, s, 1]]
                            if ga > gb:
                                ga, gb = gb, ga
                            out[row, s, 0] = ga
                            out[row, s, 1] = gb
                cnt += m
    return cnt


@njit(cache=True, parallel=True)
def march_tets(tables, n, tet_sign, vals, level, ntri, cedges):
    """Marching tetrahedra over every tet; triangles as (M, 3, 2) lattice-edge keys.

    Work items are (tet, x1) slices, so one big tetrahedron also runs in parallel.
    """
    T = tables.shape[0]
    items = T * n
    counts = np.zeros(items, np.int64)
    dummy = np.zeros((1, 3, 2), np.int64)
    for it in prange(items):
        counts[it] = _march_slice(it // n, it % n, tables, tet_sign, vals, level, ntri, cedges, dummy, 0, False)
    starts = np.zeros(items + 1, np.int64)
    for it in range(items):
        starts[it + 1] = starts[it] + counts[it]
    out = np.empty((starts[items], 3, 2), np.int64)
    for it in prange(items):
        _march_slice(it // n, it % n, tables, tet_sign, vals, level, ntri, cedges, out, starts[it], True)
    return out


@njit(cache=True)
def cap_faces(points, tv, edge_ids, face_ids, n, V, E, F, bface_tet, bface_local, vals, level):
    """Close the material on the boundary faces of the tet mesh (marching triangles).

    Returns (M, 3, 2) keys: (g, g) for a lattice point, (a, b) for the level
    crossing on lattice edge (a, b). Oriented out of the mesh.
    """
    eb, fb, ib, nf, ni = lattice_counts(n, V, E, F)
    nb = bface_tet.shape[0]
    cap = nb * n * n * 2 + 1
    out = np.empty((cap, 3, 2), np.int64)
    cnt = 0
    poly = np.empty((4, 2), np.int64)
    gg = np.empty(3, np.int64)
    w = np.zeros(4, np.int64)
    for f in range(nb):
        t = bface_tet[f]
        k = bface_local[f]
        loc = np.empty(3, np.int64)
        j = 0
        for i in range(4):
            if i != k:
                loc[j] = i
                j += 1
        X0 = points[tv[t, loc[0]]]
        X1 = points[tv[t, loc[1]]]
        X2 = points[tv[t, loc[2]]]
        Xk = points[tv[t, k]]
        u = X1 - X0
        v = X2 - X1
        nrm = np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])
        sf = 1 if (nrm[0] * (X0[0] - Xk[0]) + nrm[1] * (X0[1] - Xk[1]) + nrm[2] * (X0[2] - Xk[2])) > 0 else -1
        for c1 in range(n):
            for c2 in range(c1 + 1):
                for p in range(2):
                    # vertices c, c + e_a, c + (1, 1) in (y1, y2)
                    if p == 1 and c1 < c2 + 1:
                        continue
                    sig = 1 if p == 0 else -1
                    for r in range(3):
                        if r == 0:
                            y1 = c1
                            y2 = c2
                        elif r == 1:
                            y1 = c1 + 1 if p == 0 else c1
                            y2 = c2 if p == 0 else c2 + 1
                        else:
                            y1 = c1 + 1
                            y2 = c2 + 1
                        w[:] = 0
                        w[loc[0]] = n - y1
                        w[loc[1]] = y1 - y2
                        w[loc[2]] = y2
                        gg[r] = lattice_gid(w[0], w[1], w[2], w[3], t, tv, edge_ids, face_ids, n, eb, fb, ib,
                                            nf, ni)
                    if sig * sf < 0:
                        tmp = gg[1]
                        gg[1] = gg[2]
                        gg[2] = tmp
                    m = 0
                    for r in range(3):
                        a = gg[r]
                        b = gg[(r + 1) % 3]
                        sa = vals[a] >= level
                        sb = vals[b] >= level
                        if sa:
                            poly[m, 0] = a
                            poly[m, 1] = a
                            m += 1
                        if sa != sb:
                            poly[m, 0] = min(a, b)
                            poly[m, 1] = max(a, b)
                            m += 1
                    for r in range(1, m - 1):
                        out[cnt, 0, 0] = poly[0, 0]
                        out[cnt, 0, 1] = poly[0, 1]
                        out[cnt, 1, 0] = poly[r, 0]
                        out[cnt, 1, 1] = poly[r, 1]
                        out[cnt, 2, 0] = poly[r + 1, 0]
                        out[cnt, 2, 1] = poly[r + 1, 1]
                        cnt += 1
    return out[:cnt]

