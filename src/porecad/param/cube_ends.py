"""Automatic corners around the two ends of a long body, and the end loops (hexahedral parameterisation, 000 §3.5).

Where the principal-axis box corners fold a face, the ends of the body are
taken as the regions around its two extreme points whose (smoothed) normals
face along the long axis (angle below 60°); a harmonic "dipole" field ``W``
(0 on one end, 1 on the other, 000 §3.5) and its conjugate ``Θ`` give
conformal cylinder coordinates (:class:`Cylinder`); the corners sit just
outside the ends at ``Θ`` spaced like the grid (:func:`end_corners`), and the
end loops are shortest paths in disjoint ``Θ`` corridors (:func:`guided_caps`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse.linalg import factorized

from ..errors import InputError
from ..mesh.operators import cotangent_laplacian, mass_matrix
from .cube import CUBE_EDGES, check_corners, edge_name, wrap_half
from .cube_edges import mesh_edges, periodic_angle, shortest_path
from .heat import face_gradient
from .patch_maps import harmonic_map

__all__ = ["Cylinder", "end_corners", "end_regions", "guided_caps"]


class Cylinder:
    """Conformal cylinder coordinates ``(W, Θ)`` of a closed genus-0 body between two end regions.

    ``W`` is harmonic on the surface with ``W = 0`` on the region ``r0`` and
    ``W = 1`` on ``r1`` (clipped cotangent weights: no interior extrema, so
    every level set is one loop around the body, the "dipole field" of 000
    §3.5); ``Θ`` (period 1) is its conjugate on the surface without the
    regions (:func:`periodic_angle`), oriented counter-clockwise seen from
    ``+W`` (``∇Θ · (∇W × n) > 0``). ``sigma`` is the area-weighted mean of
    ``|∇Θ| / |∇W|``, so ``(σ W, Θ)`` is locally isotropic.
    """

    def __init__(self, v, f, r0, r1):
        n = len(v)
        r0, r1 = np.unique(r0), np.unique(r1)
        fixed = np.concatenate([r0, r1])
        vals = np.concatenate([np.zeros(len(r0)), np.ones(len(r1))])[:, None]
        self.W = harmonic_map(v, f, fixed, vals, "cotangent")[:, 0]
        inr = np.zeros(n, bool)
        inr[fixed] = True
        keep = ~np.any(inr[f], axis=1)
        loc, tri = np.unique(f[keep], return_inverse=True)
        tri = tri.reshape(-1, 3)
        e, ln = mesh_edges(v, f)
        full = sp.coo_matrix((ln, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
        dist, pred, _ = dijkstra(full, directed=False, indices=r0, return_predecessors=True, min_only=True)
        end = int(r1[np.argmin(dist[r1])])
        cut = [end]
        while pred[cut[-1]] >= 0:
            cut.append(int(pred[cut[-1]]))
        cut = np.asarray(cut[::-1], np.int64)
        cut = cut[~inr[cut]]  # region 0 → region 1, outside both
        gl = np.full(n, -1, np.int64)
        gl[loc] = np.arange(len(loc))
        theta = periodic_angle(v[loc], tri, gl[cut])
        x = v[loc]
        gW = face_gradient(x, tri, self.W[loc])
        tf = theta[tri]
        tf = tf[:, :1] + wrap_half(tf - tf[:, :1])  # undo the jump inside each face
        pts = x[tri]
        nrm = np.cross(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0])
        dbl = np.linalg.norm(nrm, axis=1)
        nu = nrm / np.maximum(dbl, 1e-300)[:, None]
        gT = np.zeros((len(tri), 3))
        for c in range(3):
            gT += tf[:, c, None] * np.cross(nu, pts[:, (c + 2) % 3] - pts[:, (c + 1) % 3])
        gT /= np.maximum(dbl, 1e-300)[:, None]
        if np.sum(dbl * np.einsum("ij,ij->i", gT, np.cross(gW, nu))) < 0:
            theta = -theta
        self.Theta = np.full(n, np.nan)
        self.Theta[loc] = theta % 1.0
        gw = np.linalg.norm(gW, axis=1)
        ok = gw > 0
        self.sigma = float(np.sum(dbl[ok] * np.linalg.norm(gT[ok], axis=1) / gw[ok]) / np.sum(dbl[ok]))


def end_regions(v, f, frame, length, cos_max=0.5):
    """The two ends: vertices around the extreme points whose normals face along ``∓w``.

    Vertex normals are smoothed by one heat step ``(A − ℓ² L) n_s = A n``
    (``ℓ`` = ``length``); an end is the connected set of vertices around the
    lowest (highest) vertex along ``w`` with ``n_s · (∓w) ≥ cos_max``, its
    holes filled (so it is a disc).
    """
    n = len(v)
    c, R = frame
    p = v[f]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    A = mass_matrix(v, f)
    solve = factorized((sp.diags(A) - length ** 2 * cotangent_laplacian(v, f)).tocsc())
    vn = np.stack([solve(A * vn[:, d]) for d in range(3)], axis=1)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    nw = vn @ R[:, 2]
    proj = (v - c) @ R[:, 2]
    e, _ = mesh_edges(v, f)

    def grow(seed, mask):
        mask = mask.copy()
        mask[seed] = True
        k = mask[e[:, 0]] & mask[e[:, 1]]
        _, lab = connected_components(sp.coo_matrix((np.ones(int(k.sum())), (e[k, 0], e[k, 1])), shape=(n, n)),
                                      directed=False)
        inside = lab == lab[seed]
        out = ~inside
        k = out[e[:, 0]] & out[e[:, 1]]
        nc, lab = connected_components(sp.coo_matrix((np.ones(int(k.sum())), (e[k, 0], e[k, 1])), shape=(n, n)),
                                       directed=False)
        big = np.argmax(np.bincount(lab[out], minlength=nc))
        return np.flatnonzero(~(out & (lab == big)))

    r0 = grow(int(np.argmin(proj)), nw <= -cos_max)
    r1 = grow(int(np.argmax(proj)), nw >= cos_max)
    touch = np.zeros(n, bool)
    touch[r0] = True
    k = touch[e[:, 0]] | touch[e[:, 1]]
    if np.isin(r1, e[k].ravel()).any():
        raise InputError("the two ends of the body meet; the body is too short for one hexahedral block")
    return r0, r1


def end_corners(v, f, grid, cyl, frame, offset):
    """Corners just outside the two ends, spaced in ``Θ`` like the grid.

    Corners 0–3 at ``W = offset/σ``, 4–7 at ``W = 1 − offset/σ`` (no twist),
    at ``Θ = θ_0 + (0, n_u, n_u + n_v, 2n_u + n_v) / (2(n_u + n_v))`` so the
    side faces get conformally square-ish cells; ``θ_0`` puts corner 0 in the
    ``(−u, −v)`` direction of the principal frame at mid-length. Each corner
    is the vertex nearest to its target in ``(σ W, Θ)``.
    """
    nu_, nv_, _ = grid
    c, R = frame
    ok = np.isfinite(cyl.Theta) & (cyl.W > 0) & (cyl.W < 1)
    cand = np.flatnonzero(ok)
    mid = cand[np.argsort(np.abs(cyl.W[cand] - 0.5))[:max(8, len(cand) // 50)]]
    rel = (v[mid] - c) @ R
    th0 = cyl.Theta[mid[np.argmax(-rel[:, 0] - rel[:, 1])]]
    gaps = np.array([nu_, nv_, nu_, nv_], float) / (2.0 * (nu_ + nv_))
    targets = th0 + np.concatenate([[0.0], np.cumsum(gaps)[:3]])
    corners = np.empty(8, np.int64)
    for k in range(8):
        wl = offset / cyl.sigma if k < 4 else 1.0 - offset / cyl.sigma
        d2 = (cyl.sigma * (cyl.W[cand] - wl)) ** 2 + wrap_half(cyl.Theta[cand] - targets[k % 4]) ** 2
        corners[k] = cand[np.argmin(d2)]
    return check_corners(corners, len(v))


def guided_caps(v, f, corners, cyl, beta=0.3):
    """End loops e0–e3 and e4–e7 as shortest paths in disjoint corridors around each end.

    Edge ``a → b`` uses the vertices with ``Θ`` strictly between ``Θ_a`` and
    ``Θ_b`` (counter-clockwise), outside the end regions (``0 < W < 1``) and
    at most ``δ = beta (Θ_b − Θ_a) / σ`` beyond the line joining the
    corners' ``W`` in ``(Θ, W)`` towards the side (widened when that leaves
    no path). The corridors of one loop are disjoint.
    """
    n = len(v)
    e, ln = mesh_edges(v, f)
    T = cyl.Theta
    ok = np.isfinite(T) & (cyl.W > 0.0) & (cyl.W < 1.0)
    out = [None] * 8
    for k in range(8):
        a, b = (int(x) for x in CUBE_EDGES[k])
        ca, cb = corners[a], corners[b]
        span = (T[cb] - T[ca]) % 1.0
        if not 0.0 < span < 0.75:
            raise InputError(f"corners {a} and {b} are not in counter-clockwise order around the body")
        rel = (T - T[ca]) % 1.0
        level = cyl.W[ca] + (cyl.W[cb] - cyl.W[ca]) * rel / span
        delta = beta * span / max(cyl.sigma, 1e-12)
        beyond = (cyl.W - level) if k < 4 else (level - cyl.W)
        for grow in (1.0, 2.0, 4.0):
            allowed = ok & (rel > 0) & (rel < span) & (beyond <= grow * delta)
            allowed[corners] = False
            allowed[[ca, cb]] = True
            pth = shortest_path(n, e, ln, ca, cb, allowed)
            if pth is not None:
                break
        else:
            raise InputError(f"edge {edge_name(k)} finds no path in its corridor near the end of the body")
        out[k] = pth
    return out
