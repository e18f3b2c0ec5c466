"""Untangling of a structured hex grid whose surface nodes slide on the body (hexahedral parameterisation, step 6).

Not in 000: where a corner scaled Jacobian is low, the grid Laplace energy plus
barriers on low Jacobians is minimised, interior nodes moving freely and
surface nodes sliding inside their face map or along their cube edge
(:func:`untangle_grid`), then a derivative-free local search
(:func:`polish`) on the nodes still below the target.
"""

from __future__ import annotations

import time

import numpy as np

from .cube import CUBE, CUBE_EDGES, FRAMES, CORNER_NEIGHBOURS
from .hex_quality import (
    SAMPLE_D,
    SAMPLE_D_ALL,
    corner_jacobians,
    grid_to_hexes,
    min_corner_jacobian,
    min_sample_jacobian,
    min_sample_ratio,
    sample_dets,
    sample_jacobians,
)

__all__ = ["SJ_TARGET", "TETHER", "UNTANGLE_LIMIT", "untangle_estimate", "untangle_grid"]

#: untangling runs when a corner scaled Jacobian is below this, and aims above it
SJ_TARGET = 0.05
EDGE_GAP_MIN = 0.5  # untangling keeps each cube-edge gap at least this fraction of the even one
EDGE_GAP_POLISH = 0.35  # and the local search (:func:`_polish`) at least this one
#: seconds for all untangling of one parameterisation, by default (recipe ``body.untangle_limit``)
UNTANGLE_LIMIT = 90.0
TETHER = 1.0  # weight of a surface node's move in its face map or along its edge, per grid cell squared


def _boundary_dofs(shape, locators, paths, taus, v):
    """Movable boundary nodes: face nodes with their ``(s, t)``, cube-edge nodes with their ``τ``."""
    N = np.array(shape) - 1
    ids = np.arange(int(np.prod(shape))).reshape(shape)
    faces, edges = [], []
    for fc, (ax, val, p, q, _) in enumerate(FRAMES):
        ns, nt = int(N[p]), int(N[q])
        if ns < 2 or nt < 2:
            continue
        sl = [slice(1, -1)] * 3
        sl[ax] = int(val * N[ax])
        ii, jj = np.meshgrid(np.arange(1, ns) / ns, np.arange(1, nt) / nt, indexing="ij")
        faces.append((ids[tuple(sl)].ravel(), np.stack([ii.ravel(), jj.ravel()], 1), locators[fc], (ns, nt)))
    for k, (a, b) in enumerate(CUBE_EDGES):
        d = int(np.flatnonzero(CUBE[a] != CUBE[b])[0])
        n = int(N[d])
        if n < 2:
            continue
        idx = np.tile(CUBE[a] * N, (n - 1, 1))
        idx[:, d] += int(CUBE[b, d] - CUBE[a, d]) * np.arange(1, n)
        edges.append((ids[idx[:, 0], idx[:, 1], idx[:, 2]], np.arange(1, n) / n, v[paths[k]], taus[k], n))
    return ids, faces, edges


def untangle_grid(nodes, locators, paths, taus, v, mu=0.2, kappa=20.0, mu2=SJ_TARGET, kappa2=2000.0, maxiter=300,
              tether=TETHER, deadline=None, progress=None):
    """Raise low corner Jacobians; interior nodes move freely, surface nodes slide on their face or edge.

    Minimises
    ``E = Σ_grid edges |x_i − x_j|² / h² + κ Σ_corners (μ − J)₊² + κ₂ Σ_corners (μ₂ − J)₊²
    + τ_t Σ_surface nodes |n ⊙ (s − s₀)|²``
    (``J`` the corner scaled Jacobian, ``h²`` the mean squared grid edge; the
    last term tethers each surface node to its place in the harmonic face map
    or on its cube edge, in grid cells: without it the edge springs pull the
    surface nodes together where the surface is concave, the boundary quads
    cut the body's corners and the grid loses volume — 11 % of the femur at
    5×7×20 — by an amount that depends on the L-BFGS path, hence on the SciPy
    version)
    over the interior nodes, the face nodes (by their ``(s, t)`` in the
    face's harmonic map, so they stay on their patch) and the cube-edge
    nodes (by their arc-length parameter ``τ``); the corners stay. The first
    term is the grid Laplace energy whose minimiser for the interior is 000
    eq. 3.2.3; the others are barriers on flat and inverted corners. A
    barrier ``κ₂ Σ (EDGE_GAP_MIN − n Δτ)₊²`` keeps the cube-edge nodes from
    bunching (uneven edge gaps fold the cells beside the edge inside).
    L-BFGS-B with restarts (the surface map is piecewise linear, line
    searches stall at its kinks), then a derivative-free local search on the
    nodes of the corners still below ``μ₂`` (:func:`_polish`).

    ``deadline`` (a :func:`time.perf_counter` value) stops the descent and
    the search at the first iteration past it; ``progress(done, total)`` is
    called per L-BFGS iteration (total: the iteration budget).

    Returns the node grid, the number of L-BFGS iterations and whether the deadline stopped it.
    """
    from scipy.optimize import minimize

    shape = nodes.shape[:3]
    flat = nodes.reshape(-1, 3).copy()
    _, hexes = grid_to_hexes(nodes)
    ids, faces, edges = _boundary_dofs(shape, locators, paths, taus, v)
    inner = ids[1:-1, 1:-1, 1:-1].ravel()
    x0 = np.concatenate([flat[inner].ravel()] + [fc[1].ravel() for fc in faces] + [ed[1] for ed in edges])
    sizes = [inner.size * 3] + [fc[1].size for fc in faces] + [ed[1].size for ed in edges]
    cuts = np.cumsum(sizes)[:-1]
    bounds = [(None, None)] * (inner.size * 3) + [(1e-6, 1 - 1e-6)] * int(sum(sizes[1:]))
    ea, eb = [], []
    for ax in range(3):
        sa, sb = [slice(None)] * 3, [slice(None)] * 3
        sa[ax], sb[ax] = slice(0, -1), slice(1, None)
        ea.append(ids[tuple(sa)].ravel())
        eb.append(ids[tuple(sb)].ravel())
    ea, eb = np.concatenate(ea), np.concatenate(eb)
    h2 = float(np.mean(np.sum((flat[ea] - flat[eb]) ** 2, axis=1)))

    def assemble(x):
        parts = np.split(x, cuts)
        P = flat.copy()
        P[inner] = parts[0].reshape(-1, 3)
        jac = []
        for fc, st in zip(faces, parts[1:1 + len(faces)]):
            X, M = fc[2].evaluate(st.reshape(-1, 2))
            P[fc[0]] = X
            jac.append(M)
        for ed, t in zip(edges, parts[1 + len(faces):]):
            poly, tau = ed[2], ed[3]
            P[ed[0]] = np.stack([np.interp(t, tau, poly[:, d]) for d in range(3)], 1)
            seg = np.clip(np.searchsorted(tau, t, side="right") - 1, 0, len(tau) - 2)
            jac.append((poly[seg + 1] - poly[seg]) / np.maximum(tau[seg + 1] - tau[seg], 1e-12)[:, None])
        return P, jac

    def fun(x):
        P, jac = assemble(x)
        D = P[eb] - P[ea]
        E = float(np.sum(D * D)) / h2
        G = np.zeros_like(P)
        np.add.at(G, eb, 2.0 * D / h2)
        np.add.at(G, ea, -2.0 * D / h2)
        J, parts = corner_jacobians(P, hexes, True)
        v1, v2 = np.maximum(mu - J, 0.0), np.maximum(mu2 - J, 0.0)
        E += kappa * float(np.sum(v1 ** 2)) + kappa2 * float(np.sum(v2 ** 2))
        for c, (a, nb, gs) in enumerate(parts):
            w = -2.0 * (kappa * v1[:, c] + kappa2 * v2[:, c])
            act = w != 0
            if np.any(act):
                for k in range(3):
                    gk = gs[k][act] * w[act, None]
                    np.add.at(G, nb[act, k], gk)
                    np.add.at(G, a[act], -gk)
        if watch.size:  # the map's Jacobian inside the watched cells (the corners alone let a cell fold inside)
            Js, Gs = sample_jacobians(P, hexes[watch], grad=True)
            vs = np.maximum(mu2 - Js, 0.0)
            E += kappa2 * float(np.sum(vs ** 2))
            Gc = np.einsum("hs,hscd->hcd", -2.0 * kappa2 * vs, Gs)
            # and its determinant against the cell's size: the scaled one stays finite where an
            # edge of the cell collapses, and the map can fold between the samples there
            Ds, Gd = sample_dets(P, hexes[watch], grad=True)
            vd = np.maximum(mu2 - Ds / vref[:, None], 0.0)
            E += kappa2 * float(np.sum(vd ** 2))
            Gc += np.einsum("hs,hscd->hcd", -2.0 * kappa2 * vd / vref[:, None], Gd)
            np.add.at(G, hexes[watch], Gc)
        out = [G[inner].ravel()]
        xs = np.split(x, cuts)
        for fc, M, st, st0 in zip(faces, jac[:len(faces)], xs[1:1 + len(faces)], x0s[1:1 + len(faces)]):
            sc = np.tile(np.asarray(fc[3], float), len(st) // 2)
            dd = (st - st0) * sc
            E += tether * float(np.sum(dd * dd))
            out.append(np.einsum("mdk,md->mk", M, G[fc[0]]).ravel() + 2.0 * tether * dd * sc)
        for ed, T, t, t0_ in zip(edges, jac[len(faces):], xs[1 + len(faces):], x0s[1 + len(faces):]):
            n = ed[4]
            d = np.maximum(EDGE_GAP_MIN - n * np.diff(np.concatenate([[0.0], t, [1.0]])), 0.0)
            E += kappa2 * float(np.sum(d * d))
            dt = (t - t0_) * n
            E += tether * float(np.sum(dt * dt))
            g = np.einsum("md,md->m", T, G[ed[0]]) + 2.0 * kappa2 * n * (d[1:] - d[:-1]) + 2.0 * tether * dt * n
            out.append(g)
        return E, np.concatenate(out)

    x0s = np.split(x0, cuts)

    budget_all = 5 * 10 * maxiter
    count = [0]
    stopped = [False]

    def cb(_):
        count[0] += 1
        if progress is not None and count[0] % 10 == 0:
            progress(min(count[0], budget_all), budget_all)
        if deadline is not None and time.perf_counter() > deadline:
            stopped[0] = True
            raise StopIteration

    def descend(x, budget):
        it, best = 0, fun(x)[0]
        for _ in range(10):
            if stopped[0]:
                break
            res = minimize(fun, x, jac=True, method="L-BFGS-B", bounds=bounds, callback=cb,
                           options={"maxiter": budget, "maxcor": 10})
            it += int(res.nit)
            improved = res.fun < best - 1e-6 * abs(best)
            if res.fun <= best:
                x, best = res.x, float(res.fun)
            if res.success or not improved or it >= budget:
                break
        return x, it

    # corners first; then, while some cell's map folds (or nearly) inside although its corners are
    # valid, add the interior samples of those cells (and of their neighbours) to the barrier
    watch, vref = np.zeros(0, np.int64), np.ones(0)
    x, nit = descend(x0, maxiter)
    cell_ids = np.arange(len(hexes)).reshape(tuple(np.array(shape) - 1))
    for _ in range(4):
        if stopped[0]:
            break
        P, _ = assemble(x)
        dets = sample_dets(P, hexes)
        vol = np.maximum(np.abs(dets).mean(axis=1), 1e-300)
        low = np.flatnonzero((sample_jacobians(P, hexes).min(axis=1) < mu2) | (dets.min(axis=1) / vol < mu2))
        low = np.setdiff1d(low, watch)
        if not low.size:
            break
        mask = np.zeros(cell_ids.shape, bool)
        mask.ravel()[low] = True
        grown = mask.copy()  # one layer of neighbours: moving a node changes all cells around it
        for ax in range(3):
            a = [slice(None)] * 3
            b = [slice(None)] * 3
            a[ax], b[ax] = slice(1, None), slice(None, -1)
            grown[tuple(a)] |= mask[tuple(b)]
            grown[tuple(b)] |= mask[tuple(a)]
        watch = np.union1d(watch, cell_ids[grown].ravel())
        vref = vol[watch]  # the cells' mean |det|, fixed during the descent
        x, it = descend(x, maxiter)
        nit += it
    P, _ = assemble(x)
    if not stopped[0]:
        P = _polish(P, hexes, faces, edges, np.split(x, cuts), inner, mu2, watch=watch, vref=vref,
                    deadline=deadline)
    if progress is not None:
        progress(budget_all, budget_all)
    return P.reshape(nodes.shape), nit, stopped[0] or (deadline is not None and time.perf_counter() > deadline)


def _gap_short(t, r, q, n):
    """Whether moving the ``r``-th interior cube-edge node to ``τ = q`` shortens a gap below ``EDGE_GAP_POLISH / n``."""
    lo = t[r - 1] if r > 0 else 0.0
    hi = t[r + 1] if r + 1 < len(t) else 1.0
    new = min(q - lo, hi - q)
    return new * n < EDGE_GAP_POLISH and new < min(t[r] - lo, hi - t[r])  # a short gap may still grow


def _polish(P, hexes, faces, edges, parts, inner, target, rounds=30, watch=None, vref=None, deadline=None):
    """Local search on the nodes of the corners below ``target``: maximise the minimum Jacobian of their cells.

    Each movable node of such a corner tries steps along its own coordinates
    (3D for interior nodes, ``(s, t)`` for face nodes, ``τ`` for edge nodes)
    of ½, ¼, ⅛ and 1/16 of the local spacing, and keeps the best step that
    raises the minimum corner Jacobian over the (up to 8) cells around it.
    Derivative-free, so the kinks of the piecewise-linear surface do not stall it.
    The cells in ``watch`` also count their Jacobian at the interior samples
    (:func:`sample_jacobians`): all 8 nodes of such a cell with a sample
    below ``target`` are tried.
    """
    P = P.copy()
    watched = np.zeros(len(hexes), bool)
    vcell = np.ones(len(hexes))
    if watch is not None:
        watched[np.asarray(watch, np.int64)] = True
        vcell[np.asarray(watch, np.int64)] = vref
    n = len(P)
    kind = np.zeros(n, np.int64)  # 0 fixed, 1 interior, 2 face, 3 edge
    where = np.zeros((n, 2), np.int64)
    kind[inner] = 1
    where[inner, 1] = np.arange(inner.size)
    st = [parts[1 + i].reshape(-1, 2).copy() for i in range(len(faces))]
    tt = [parts[1 + len(faces) + i].copy() for i in range(len(edges))]
    for fi, fc in enumerate(faces):
        kind[fc[0]] = 2
        where[fc[0], 0], where[fc[0], 1] = fi, np.arange(fc[0].size)
    for ei, ed in enumerate(edges):
        kind[ed[0]] = 3
        where[ed[0], 0], where[ed[0], 1] = ei, np.arange(ed[0].size)
    order = np.argsort(hexes.ravel(), kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(hexes.ravel(), minlength=n))])
    cell_of = order // 8

    def cells(a):
        return cell_of[ptr[a]:ptr[a + 1]]

    def local_min(cs):
        val = float(min_corner_jacobian(P, hexes[cs], CORNER_NEIGHBOURS))
        cw = cs[watched[cs]]
        if cw.size:
            val = min(val, float(min_sample_jacobian(P, hexes[cw], SAMPLE_D)),
                      float(min_sample_ratio(P, hexes[cw], SAMPLE_D_ALL, vcell[cw])))
        return val

    steps8 = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, -1], [1, -1], [-1, 1]], float)
    for _ in range(rounds):
        if deadline is not None and time.perf_counter() > deadline:
            break
        J = corner_jacobians(P, hexes)[0]
        bad = np.argwhere(J < target)
        wi = np.flatnonzero(watched)
        if wi.size:
            low = np.minimum(sample_jacobians(P, hexes[wi]).min(axis=1),
                             sample_dets(P, hexes[wi]).min(axis=1) / vcell[wi])
            bad_in = wi[low < target]
        else:
            bad_in = wi
        if not len(bad) and not bad_in.size:
            break
        cand = set(int(x) for x in hexes[bad[:, 0], bad[:, 1]])
        cand.update(int(x) for x in hexes[bad_in].ravel())
        for h, c in bad:
            cand.update(int(x) for x in hexes[h, CORNER_NEIGHBOURS[c]])
        moved = False
        for a in sorted(cand):
            k = kind[a]
            if k == 0:
                continue
            cs = cells(a)
            base = local_min(cs)
            keep = P[a].copy()
            if k == 1:
                nb = np.unique(hexes[cs])
                dirs = np.vstack([np.eye(3), -np.eye(3)]) * float(np.mean(np.linalg.norm(P[nb] - P[a], axis=1)))
                cur = P[a].copy()
            elif k == 2:
                fi, r = where[a]
                dirs = steps8 / np.array(faces[fi][3], float)
                cur = st[fi][r].copy()
            else:
                ei, r = where[a]
                dirs = np.array([[1.0], [-1.0]]) / edges[ei][4]
                cur = np.array([tt[ei][r]])
            best_val, best = base, None
            for frac in (0.5, 0.25, 0.125, 0.0625):
                for d in dirs:
                    q = cur + frac * d
                    if k == 1:
                        P[a] = q
                    elif np.any(q <= 1e-6) or np.any(q >= 1 - 1e-6):
                        continue
                    elif k == 3 and _gap_short(tt[ei], r, q[0], edges[ei][4]):
                        continue
                    elif k == 2:
                        P[a] = faces[fi][2].evaluate(q)[0][0]
                    else:
                        poly, tau = edges[ei][2], edges[ei][3]
                        P[a] = [np.interp(q[0], tau, poly[:, dd]) for dd in range(3)]
                    val = local_min(cs)
                    if val > best_val + 1e-9:
                        best_val, best = val, (q.copy(), P[a].copy())
                P[a] = keep
            if best is not None:
                P[a] = best[1]
                if k == 2:
                    st[fi][r] = best[0]
                elif k == 3:
                    tt[ei][r] = best[0][0]
                moved = True
        if not moved:
            break
    return P


def untangle_estimate(nodes, locators, v):
    """Seconds the untangling may take: one timed energy-like evaluation × a typical iteration count.

    The L-BFGS descent evaluates the energy about 1.1 times per iteration and
    typically needs a few hundred iterations (about ``0.6 (nodes)^⅓ · 40``
    measured on the femur and on noisy blobs); one evaluation is dominated by
    the corner Jacobians with their gradient and the face-map lookups, which
    are timed here once.
    """
    t = time.perf_counter()
    pts, hexes = grid_to_hexes(nodes)
    corner_jacobians(pts, hexes, True)
    sample_jacobians(pts, hexes[: max(1, len(hexes) // 4)])
    q = np.full((max(1, len(pts) // 3), 2), 0.5)
    locators[0].evaluate(q)
    per = 2.0 * (time.perf_counter() - t) + 5e-6 * len(pts)  # + the L-BFGS-B step itself
    iters = 25.0 * float(len(pts)) ** (1.0 / 3.0)
    return per * 1.1 * iters
