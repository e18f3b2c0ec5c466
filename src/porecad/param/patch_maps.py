"""Surface and volume nodes of the hexahedral parameterisation: per-patch harmonic maps, Laplace interior (000 §3.5–3.6).

Every face patch gets its own harmonic map to the unit square (cotangent
weights clipped to be positive, falling back to mean-value weights, Floater
2003, when a triangle flips), with its four boundary paths laid on the
square's sides by arc length; the patch grid nodes ``(i/n_s, j/n_t)`` are
located in the mapped triangulation (:class:`PatchLocator`) and interpolated
back barycentrically (:func:`surface_grid`). Interior nodes solve the
discrete Laplace equation 000 eq. 3.2.3 (:func:`laplace_volume`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.linalg import splu

from ..errors import InputError
from ..mesh.operators import edge_cotangent_weights
from .cube import CUBE, CUBE_EDGES, FACE_EDGES, FRAMES, face_name

__all__ = ["PatchLocator", "axis_spacing", "harmonic_map", "laplace_volume", "surface_grid", "surface_points",
           "vertex_stretch"]


def _arc_param(v, path):
    """Normalised arc-length parameter τ ∈ [0, 1] of each path vertex."""
    seg = np.linalg.norm(np.diff(v[path], axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(path))


def _mean_value_weights(x, tri):
    """Directed mean-value weights ``w_ij = (tan(γ/2) + tan(δ/2)) / |x_i − x_j|`` (Floater 2003)."""
    rows, cols, vals = [], [], []
    for c in range(3):
        i, j, k = tri[:, c], tri[:, (c + 1) % 3], tri[:, (c + 2) % 3]
        e1, e2 = x[j] - x[i], x[k] - x[i]
        l1, l2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
        th = np.arccos(np.clip(np.einsum("ij,ij->i", e1, e2) / np.maximum(l1 * l2, 1e-300), -1.0, 1.0))
        t = np.tan(0.5 * th)
        rows += [i, i]
        cols += [j, k]
        vals += [t / np.maximum(l1, 1e-300), t / np.maximum(l2, 1e-300)]
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def _cot_weights(x, tri):
    """Symmetric cotangent weights ``½ (cot α + cot β)`` clipped to a small positive floor."""
    a, b, ws = edge_cotangent_weights(x, tri)
    ws = np.maximum(ws, 1e-3 * float(np.mean(np.abs(ws))))
    return np.concatenate([a, b]), np.concatenate([b, a]), np.concatenate([ws, ws])


#: most stretch-balancing rounds of a patch map (:func:`harmonic_map`)
MAX_BALANCE = 10


def _solve_map(n, rows, cols, vals, bnd, bnd_val):
    """``Σ_j w_ij (u_j − u_i) = 0`` at the free vertices, ``u = bnd_val`` on ``bnd`` (one sparse factorisation)."""
    W = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    Lm = (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()
    bnd_val = np.asarray(bnd_val, float).reshape(len(bnd), -1)
    u = np.zeros((n, bnd_val.shape[1]))
    u[bnd] = bnd_val
    free = np.ones(n, bool)
    free[bnd] = False
    ii = np.flatnonzero(free)
    if ii.size:
        rhs = -(Lm[ii][:, bnd] @ bnd_val)
        u[ii] = splu(Lm[ii][:, ii].tocsc()).solve(np.ascontiguousarray(rhs))
    return u


def vertex_stretch(x, tri, uv):
    """Each vertex's area stretch of the map ``uv -> x``, normalised to 1 for a map of uniform scale.

    Per triangle ``ρ_T = sqrt(A_T / a_T) / sqrt(ΣA / Σa)`` (3-D area over
    map area); per vertex the area-weighted root mean square of ``ρ_T`` over
    its triangles, ``σ_i = sqrt(Σ_T A_T ρ_T² / Σ_T A_T)`` (Yoshizawa, Belyaev
    & Seidel 2004, with the area ratio for Sander's L2 stretch).
    """
    n = len(x)
    A3 = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
    a2 = np.abs(_signed_areas(uv, tri))
    scale = A3.sum() / max(a2.sum(), 1e-300)
    rho2 = np.maximum(A3, 1e-300) / np.maximum(a2, 1e-300) / scale
    num = np.bincount(tri.ravel(), weights=np.repeat(A3 * rho2, 3), minlength=n)
    den = np.bincount(tri.ravel(), weights=np.repeat(A3, 3), minlength=n)
    return np.sqrt(num / np.maximum(den, 1e-300))


def harmonic_map(x, tri, bnd, bnd_val, kind, balance: int = 0):
    """Discrete harmonic extension: ``Σ_j w_ij (u_j − u_i) = 0`` at the free vertices, ``u = bnd_val`` on ``bnd``.

    ``balance`` rounds of stretch balancing (Yoshizawa, Belyaev & Seidel,
    "A fast and simple stretch-minimizing mesh parameterization", Shape
    Modeling International 2004): each round divides the weight of every
    edge ``ij`` by the stretch ``σ_j`` of the map at ``j``
    (:func:`vertex_stretch`) and solves again. A harmonic map squeezes a
    protrusion into a small part of the square (the bunny's ear tip into
    0.4 % of a face, 4 % from its corner), so that no grid node and no
    spline span reaches it; balancing gives it room. The weights stay
    positive, so with the convex boundary the map stays one-to-one
    (Floater 2003).
    """
    n = len(x)
    rounds = int(balance)
    if not 0 <= rounds <= MAX_BALANCE:
        raise InputError(f"stretch balancing takes 0 to {MAX_BALANCE} rounds, got {balance!r}")
    rows, cols, vals = (_cot_weights if kind == "cotangent" else _mean_value_weights)(x, tri)
    u = _solve_map(n, rows, cols, vals, bnd, bnd_val)
    for _ in range(rounds):
        vals = vals / vertex_stretch(x, tri, u)[cols]
        u = _solve_map(n, rows, cols, vals, bnd, bnd_val)
    return u


def _signed_areas(uv, tri):
    p = uv[tri]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


@njit(cache=True)
def _bary1(P, a2, t, x, y):  # pragma: no cover - compiled
    l0 = ((P[t, 1, 0] - x) * (P[t, 2, 1] - y) - (P[t, 1, 1] - y) * (P[t, 2, 0] - x)) / a2[t]
    l1 = ((P[t, 2, 0] - x) * (P[t, 0, 1] - y) - (P[t, 2, 1] - y) * (P[t, 0, 0] - x)) / a2[t]
    return l0, l1, 1.0 - l0 - l1


@njit(cache=True)
def _locate(q, G, bin_ptr, bin_tri, P, a2):  # pragma: no cover - compiled
    """Per query: the triangle of its bin it is least outside of (all triangles when outside every one)."""
    m = q.shape[0]
    best_t = np.zeros(m, np.int64)
    best_b = np.zeros((m, 3))
    for i in range(m):
        x, y = q[i, 0], q[i, 1]
        bi = min(max(int(np.floor(x * G)), 0), G - 1)
        bj = min(max(int(np.floor(y * G)), 0), G - 1)
        b = bi * G + bj
        best = -np.inf
        for r in range(bin_ptr[b], bin_ptr[b + 1]):
            t = bin_tri[r]
            l0, l1, l2 = _bary1(P, a2, t, x, y)
            sc = min(l0, min(l1, l2))
            if sc > best:
                best, best_t[i] = sc, t
                best_b[i, 0], best_b[i, 1], best_b[i, 2] = l0, l1, l2
        if best < -1e-9:  # outside every triangle of its bin: search all
            for t in range(P.shape[0]):
                l0, l1, l2 = _bary1(P, a2, t, x, y)
                sc = min(l0, min(l1, l2))
                if sc > best:
                    best, best_t[i] = sc, t
                    best_b[i, 0], best_b[i, 1], best_b[i, 2] = l0, l1, l2
        tot = 0.0
        for k in range(3):
            best_b[i, k] = max(best_b[i, k], 0.0)
            tot += best_b[i, k]
        for k in range(3):
            best_b[i, k] /= tot
    return best_t, best_b


class PatchLocator:
    """Point location in a planar patch map ``uv`` and the piecewise-linear map back to 3D.

    Triangles are binned by their bounding boxes on a ``G × G`` grid over the
    unit square; a query tests the triangles of its bin and keeps the one it
    is least outside of (barycentrics clamped). Degenerate (zero-area)
    triangles of the map are skipped.
    """

    def __init__(self, x, tri, uv):
        a2 = 2.0 * _signed_areas(uv, tri)
        tid = np.flatnonzero(np.abs(a2) > 1e-14)
        self.P = uv[tri[tid]]
        self.a2 = a2[tid]
        self.X = x[tri[tid]]
        B = np.stack([self.P[:, 1] - self.P[:, 0], self.P[:, 2] - self.P[:, 0]], axis=2)  # (T, 2, 2)
        E = np.stack([self.X[:, 1] - self.X[:, 0], self.X[:, 2] - self.X[:, 0]], axis=2)  # (T, 3, 2)
        self.M = E @ np.linalg.inv(B)  # d x / d (s, t), (T, 3, 2)
        G = int(np.clip(np.sqrt(len(tid)) / 2, 4, 128))
        self.G = G
        lo = np.clip(np.floor((self.P.min(1) - 1e-9) * G), 0, G - 1).astype(np.int64)
        hi = np.clip(np.floor((self.P.max(1) + 1e-9) * G), 0, G - 1).astype(np.int64)
        ni, nj = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
        cnt = ni * nj
        rep = np.repeat(np.arange(len(tid)), cnt)
        off = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        b = (lo[rep, 0] + off // nj[rep]) * G + lo[rep, 1] + off % nj[rep]
        order = np.argsort(b, kind="stable")
        self.bin_tri = rep[order]
        self.bin_ptr = np.concatenate([[0], np.cumsum(np.bincount(b, minlength=G * G))])

    def locate(self, q):
        """Triangle (of the non-degenerate ones) and clamped barycentrics of each query, (m,), (m, 3)."""
        q = np.ascontiguousarray(np.asarray(q, float).reshape(-1, 2))
        return _locate(q, self.G, self.bin_ptr, self.bin_tri, self.P, self.a2)

    def evaluate(self, q):
        """3D points and their derivatives ``d x / d (s, t)``, (m, 3), (m, 3, 2)."""
        t, bc = self.locate(q)
        return np.einsum("mk,mkd->md", bc, self.X[t]), self.M[t]


def surface_grid(v, f, labels, paths, grid, weights, balance: int = 0):
    """Boundary nodes of the (nu+1, nv+1, nw+1) grid (NaN inside).

    ``balance``: rounds of stretch balancing of each patch map (:func:`harmonic_map`).

    Returns ``(nodes, kinds, locators, taus)``: the weights used per face,
    a :class:`PatchLocator` per face and the arc-length parameters of the paths.
    """
    N = np.asarray(grid, np.int64)
    nodes = np.full((N[0] + 1, N[1] + 1, N[2] + 1, 3), np.nan)
    taus = [_arc_param(v, p) for p in paths]
    for k, (a, b) in enumerate(CUBE_EDGES):  # cube edges: sampled once by arc length, shared by both faces
        d = int(np.flatnonzero(CUBE[a] != CUBE[b])[0])
        sgn = int(CUBE[b, d] - CUBE[a, d])
        t = np.linspace(0.0, 1.0, N[d] + 1)
        pts = np.stack([np.interp(t, taus[k], v[paths[k], dd]) for dd in range(3)], axis=1)
        idx = np.tile(CUBE[a] * N, (N[d] + 1, 1))
        idx[:, d] += sgn * np.arange(N[d] + 1)
        nodes[idx[:, 0], idx[:, 1], idx[:, 2]] = pts
    kinds, locators = [], []
    for fc, (ax, val, p, q, lo) in enumerate(FRAMES):
        loc, tri = np.unique(f[labels == fc], return_inverse=True)
        tri = tri.reshape(-1, 3)
        x = v[loc]
        gl = np.full(len(v), -1, np.int64)
        gl[loc] = np.arange(len(loc))
        bidx, buv = [], []
        for k in FACE_EDGES[fc]:
            a, b = CUBE_EDGES[k]
            A = CUBE[a, [p, q]].astype(float)
            B = CUBE[b, [p, q]].astype(float)
            bidx.append(gl[paths[k]])
            buv.append(A + taus[k][:, None] * (B - A))
        bidx, first = np.unique(np.concatenate(bidx), return_index=True)
        buv = np.concatenate(buv)[first]
        c2 = CUBE[list(lo)][:, [p, q]].astype(float)
        expect = np.sign(np.sum(c2[:, 0] * np.roll(c2[:, 1], -1) - np.roll(c2[:, 0], -1) * c2[:, 1]))
        for kind in ((weights, "mean-value") if weights == "cotangent" else (weights,)):
            uv = harmonic_map(x, tri, bidx, buv, kind, balance)
            flipped = int(np.sum(_signed_areas(uv, tri) * expect < -1e-12))
            if not flipped:
                break
        else:
            raise InputError(f"face {face_name(fc)} cannot be mapped to a square without folds "
                             f"({flipped} flipped triangles)")
        kinds.append(kind)
        locator = PatchLocator(x, tri, uv)
        locators.append(locator)
        ns, nt = int(N[p]), int(N[q])
        if ns > 1 and nt > 1:
            ii, jj = np.meshgrid(np.arange(1, ns), np.arange(1, nt), indexing="ij")
            pts, _ = locator.evaluate(np.stack([ii.ravel() / ns, jj.ravel() / nt], axis=1))
            idx = np.zeros((ii.size, 3), np.int64)
            idx[:, ax] = val * N[ax]
            idx[:, p], idx[:, q] = ii.ravel(), jj.ravel()
            nodes[idx[:, 0], idx[:, 1], idx[:, 2]] = pts
    return nodes, kinds, locators, taus


def surface_points(locators):
    """Every vertex of the six patch maps with its cube parameters and outward unit normal.

    Returns ``(uvw, xyz, normals)``, each ``(m, 3)``: a vertex on a patch
    boundary comes once per patch it bounds (same point, the parameters of
    each face). Normals are the area-weighted normals of the patch's
    triangles at the vertex, oriented like the mesh (outward for a mesh of
    positive volume).
    """
    uvw, xyz, nrm = [], [], []
    for fc, (ax, val, p, q, _) in enumerate(FRAMES):
        loc = locators[fc]
        pts, inv = np.unique(loc.X.reshape(-1, 3), axis=0, return_inverse=True)
        inv = inv.ravel()
        st = np.zeros((len(pts), 2))
        st[inv] = loc.P.reshape(-1, 2)
        area_n = np.cross(loc.X[:, 1] - loc.X[:, 0], loc.X[:, 2] - loc.X[:, 0])
        n = np.zeros((len(pts), 3))
        np.add.at(n, inv, np.repeat(area_n, 3, axis=0))
        w = np.empty((len(pts), 3))
        w[:, ax], w[:, p], w[:, q] = float(val), np.clip(st[:, 0], 0.0, 1.0), np.clip(st[:, 1], 0.0, 1.0)
        uvw.append(w)
        xyz.append(pts)
        nrm.append(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300))
    return np.concatenate(uvw), np.concatenate(xyz), np.concatenate(nrm)


def axis_spacing(nodes):
    """Mean edge length of the boundary nodes along each grid axis, ``(h_u, h_v, h_w)``.

    ``1 / h_a²`` are the axis weights of :func:`laplace_volume` and of the
    untangling energy: the discrete Laplace equation of the box with the
    body's proportions rather than of the unit cube, so that on a long body
    each cross-section's nodes follow its own boundary loop instead of being
    pulled toward the ends (with equal weights 100 of the 512 cells of an
    8×8×8 grid on a long bone fold before untangling; with these, 4).
    """
    h = np.ones(3)
    for ax in range(3):
        d = np.diff(nodes, axis=ax)
        parts = []
        for other in range(3):
            if other == ax:
                continue
            for end in (0, -1):
                idx = [slice(None)] * 3
                idx[other] = end
                parts.append(np.linalg.norm(d[tuple(idx)], axis=-1).ravel())
        cat = np.concatenate(parts)
        if cat.size:
            h[ax] = float(np.mean(cat))
    return np.maximum(h, 1e-9 * h.max())


def laplace_volume(nodes, weights=None):
    """Fill the interior nodes by the 6-neighbour discrete Laplace equation (000 eq. 3.2.3), one sparse solve.

    The interior unknowns satisfy ``Σ_a w_a (2 x_ijk − x_{−a} − x_{+a}) = 0``, i.e.
    ``(w_u T_u ⊗ I ⊗ I + w_v I ⊗ T_v ⊗ I + w_w I ⊗ I ⊗ T_w) x = b`` with ``T = tridiag(−1, 2, −1)``;
    ``weights`` ``(w_u, w_v, w_w)`` default to 1 (000 eq. 3.2.3: the mean of the six neighbours).
    """
    n = np.array(nodes.shape[:3]) - 2  # interior counts
    if np.any(n < 1):
        return nodes
    wt = np.ones(3) if weights is None else np.asarray(weights, np.float64)
    out = nodes.copy()
    inner = (slice(1, -1),) * 3
    b = out.copy()
    b[inner] = 0.0
    rhs = (wt[0] * (b[:-2, 1:-1, 1:-1] + b[2:, 1:-1, 1:-1]) + wt[1] * (b[1:-1, :-2, 1:-1] + b[1:-1, 2:, 1:-1])
           + wt[2] * (b[1:-1, 1:-1, :-2] + b[1:-1, 1:-1, 2:])).reshape(-1, 3)

    def T(m):
        return sp.diags([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])

    I = [sp.identity(int(m)) for m in n]
    A = (wt[0] * sp.kron(sp.kron(T(n[0]), I[1]), I[2]) + wt[1] * sp.kron(sp.kron(I[0], T(n[1])), I[2])
         + wt[2] * sp.kron(sp.kron(I[0], I[1]), T(n[2]))).tocsc()
    out[inner] = splu(A).solve(np.ascontiguousarray(rhs)).reshape(*n, 3)
    return out
