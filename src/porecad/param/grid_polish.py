"""Derivative-free local search on the nodes of a structured hex grid's low elements (the last stage of
:func:`porecad.param.grid_untangle.untangle_grid`).

Each movable node of an element whose Jacobian is below the target tries
steps along its own coordinates (3D for interior nodes, ``(s, t)`` in the
face map for face nodes, ``τ`` along the cube edge for edge nodes, and the
outward lift for boundary nodes) and keeps the best that raises the minimum
Jacobian around it (:func:`polish_grid`). Derivative-free, so the kinks of
the piecewise-linear surface do not stall it.
"""

from __future__ import annotations

import numpy as np

from .hex_quality import min_det_ratio_at, min_scaled_jacobian_at, sample_dets, sample_jacobians
from .work_budget import charged

__all__ = ["EDGE_GAP_POLISH", "polish_grid"]

#: the local search keeps each cube-edge gap at least this fraction of the even one
EDGE_GAP_POLISH = 0.35

_STEPS8 = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, -1], [1, -1], [-1, 1]], float)


def _gap_short(t, r, q, n):
    """Whether moving the ``r``-th interior cube-edge node to ``τ = q`` shortens a gap below
    ``EDGE_GAP_POLISH / n``."""
    lo = t[r - 1] if r > 0 else 0.0
    hi = t[r + 1] if r + 1 < len(t) else 1.0
    new = min(q - lo, hi - q)
    return new * n < EDGE_GAP_POLISH and new < min(t[r] - lo, hi - t[r])  # a short gap may still grow


def polish_grid(P, els, faces, edges, parts, inner, target, rounds=30, watch=None, vref=None, budget=None,
                lifted=None, nrm=None, lift_max=0.0):
    """Local search on the nodes of the elements below ``target``: maximise the minimum Jacobian around them.

    Each movable node of such an element tries steps along its own
    coordinates (3D for interior nodes, ``(s, t)`` for face nodes, ``τ`` for
    edge nodes, and the outward lift ``ℓ ∈ [0, lift_max]`` for every
    boundary node) of ½, ¼, ⅛ and 1/16 of the local spacing, and keeps the
    best step that raises the minimum Jacobian (main samples; for watched
    elements also the dense samples and the determinant ratio) over the
    elements around it. Derivative-free, so the kinks of the
    piecewise-linear surface do not stall it.

    Takes the node array ``P`` (n, 3), the
    :class:`~porecad.param.grid_untangle.ElementSamples` ``els``, the face and
    cube-edge unknowns of the untangling (``faces``, ``edges``, the split
    unknowns ``parts``, the ``inner`` node ids), the ``watch``-ed elements
    with their reference ``vref``, the ``lifted`` nodes with their normals
    ``nrm``; stops after ``rounds`` rounds, a round that moves nothing, or
    once ``budget`` (a :class:`~porecad.param.work_budget.WorkBudget`,
    charged per trial) is spent. Returns the nodes, the lifts of ``lifted``,
    the face nodes' ``(s, t)`` and the edge nodes' ``τ``.
    """
    s = _NodeSearch(P, els, faces, edges, parts, inner, watch, vref, lifted, nrm, lift_max, budget)
    for _ in range(rounds):
        if budget is not None and budget.spent:
            break
        bad = s.bad_elements(target)
        if not bad.size:
            break
        cand = np.unique(els.nodes[bad])
        moved = False
        for a in cand:
            if budget is not None and budget.spent:
                break  # a round over many nodes of a 20-node grid takes minutes: stop inside it
            if s.improve(int(a)):
                moved = True
        if not moved:
            break
    return s.P, (s.lift[lifted] if lifted is not None else np.zeros(0)), s.st, s.tt


class _NodeSearch:
    """The state of :func:`polish_grid`: the nodes ``P`` (a copy), each node's kind (0 fixed, 1 interior,
    2 face, 3 edge, 4 a corner that may only lift) and place in its face or edge (``where``), the face
    coordinates ``st``, edge parameters ``tt``, lifts and normals, and the elements around each node."""

    def __init__(self, P, els, faces, edges, parts, inner, watch, vref, lifted, nrm, lift_max, budget=None):
        self.P = P.copy()
        self.budget = budget
        self.els, self.faces, self.edges, self.lift_max = els, faces, edges, lift_max
        H = els.n
        self.watched = np.zeros(H, bool)
        self.vcell = np.ones(H)
        if watch is not None and len(watch):
            self.watched[np.asarray(watch, np.int64)] = True
            self.vcell[np.asarray(watch, np.int64)] = vref
        n = len(P)
        kind = np.zeros(n, np.int64)  # 0 fixed, 1 interior, 2 face, 3 edge (4: a corner that may only lift)
        where = np.zeros((n, 2), np.int64)
        kind[inner] = 1
        where[inner, 1] = np.arange(inner.size)
        self.st = [parts[1 + i].reshape(-1, 2).copy() for i in range(len(faces))]
        self.tt = [parts[1 + len(faces) + i].copy() for i in range(len(edges))]
        for fi, fc in enumerate(faces):
            kind[fc[0]] = 2
            where[fc[0], 0], where[fc[0], 1] = fi, np.arange(fc[0].size)
        for ei, ed in enumerate(edges):
            kind[ed[0]] = 3
            where[ed[0], 0], where[ed[0], 1] = ei, np.arange(ed[0].size)
        self.lift = np.zeros(n)
        self.normal = np.zeros((n, 3))
        if lifted is not None and len(lifted):
            self.lift[lifted] = parts[-1]
            self.normal[lifted] = nrm
            kind[lifted[kind[lifted] == 0]] = 4
        self.kind, self.where = kind, where
        allnodes = els.nodes
        per = allnodes.shape[1]
        order = np.argsort(allnodes.ravel(), kind="stable")
        self.ptr = np.concatenate([[0], np.cumsum(np.bincount(allnodes.ravel(), minlength=n))])
        self.el_of = order // per

    def cells(self, a):
        """The elements around node ``a``."""
        return self.el_of[self.ptr[a]:self.ptr[a + 1]]

    def bad_elements(self, target):
        """Ids of the elements whose minimum Jacobian (watched: also dense samples, det ratio) is below ``target``."""
        P, els = self.P, self.els
        we, Ds, Dd = els.watch
        low = els.main_min(P)
        wi = np.flatnonzero(self.watched)
        if wi.size:
            low[wi] = np.minimum(low[wi], np.minimum(sample_jacobians(P, we[wi], Ds).min(axis=1),
                                                     sample_dets(P, we[wi], Dd).min(axis=1) / self.vcell[wi]))
        return np.flatnonzero(low < target)

    def local_min(self, cs):
        """Smallest Jacobian (and, for watched elements, det ratio) over the elements ``cs``."""
        P, els = self.P, self.els
        we, Ds, Dd = els.watch
        val = min(float(min_scaled_jacobian_at(P, e[cs], D)) for e, D in els.main)
        cw = cs[self.watched[cs]]
        if self.budget is not None:
            self.budget.charge(trials=1)
            for e, D in els.main:
                charged(self.budget, cs, D)
            charged(self.budget, cw, Ds, Dd)
        if cw.size:
            val = min(val, float(min_scaled_jacobian_at(P, we[cw], Ds)),
                      float(min_det_ratio_at(P, we[cw], Dd, self.vcell[cw])))
        return val

    def place(self, a, k, q, ref):
        """Position of node ``a`` at coordinates ``q`` (its own, then the lift); None when out of bounds."""
        if k == 1:
            return q
        if k != 4 and (np.any(q[:-1] <= 1e-6) or np.any(q[:-1] >= 1 - 1e-6)):
            return None
        if q[-1] < 0.0 or q[-1] > self.lift_max:
            return None
        if k == 4:
            return ref + q[-1] * self.normal[a]
        if k == 3:
            ei, r = self.where[a]
            if _gap_short(self.tt[ei], r, q[0], self.edges[ei][4]):
                return None
            poly, tau = self.edges[ei][2], self.edges[ei][3]
            x = np.array([np.interp(q[0], tau, poly[:, dd]) for dd in range(3)])
        else:
            x = self.faces[self.where[a, 0]][2].evaluate(q[:2])[0][0]
        return x + q[-1] * self.normal[a]

    def directions(self, a, k, size):
        """Node ``a``'s (kind ``k``) current coordinates and its step directions (full steps; ``size``: the
        mean distance to its neighbours)."""
        if k == 1:
            return self.P[a].copy(), np.vstack([np.eye(3), -np.eye(3)]) * size
        if k == 2:
            fi, r = self.where[a]
            own = _STEPS8 / np.array(self.faces[fi][3], float)
            cur = np.append(self.st[fi][r], self.lift[a])
        elif k == 3:
            ei, r = self.where[a]
            own = np.array([[1.0], [-1.0]]) / self.edges[ei][4]
            cur = np.array([self.tt[ei][r], self.lift[a]])
        else:
            own = np.zeros((0, 0))
            cur = np.array([self.lift[a]])
        dirs = [np.append(d, 0.0) for d in own]
        if self.lift_max > 0:
            dirs += [np.append(np.zeros(own.shape[1]), sgn * size) for sgn in (1.0, -1.0)]
        return cur, dirs

    def improve(self, a):
        """Try node ``a``'s steps of ½, ¼, ⅛ and 1/16; keep the best that raises the minimum Jacobian around it.
        Returns whether it moved."""
        P = self.P
        k = self.kind[a]
        if k == 0:
            return False
        cs = self.cells(a)
        base = self.local_min(cs)
        keep = P[a].copy()
        nb = np.unique(self.els.nodes[cs])
        size = float(np.mean(np.linalg.norm(P[nb] - P[a], axis=1)))
        ref = P[a] - self.lift[a] * self.normal[a]  # the node's place on the surface
        cur, dirs = self.directions(a, k, size)
        best_val, best = base, None
        for frac in (0.5, 0.25, 0.125, 0.0625):
            for d in dirs:
                q = cur + frac * d
                x = self.place(a, k, q, ref)
                if x is None:
                    continue
                P[a] = x
                val = self.local_min(cs)
                if val > best_val + 1e-9:
                    best_val, best = val, (q.copy(), P[a].copy())
            P[a] = keep
        if best is None:
            return False
        q, P[a] = best
        if k == 2:
            fi, r = self.where[a]
            self.st[fi][r] = q[:2]
        elif k == 3:
            ei, r = self.where[a]
            self.tt[ei][r] = q[0]
        if k != 1:
            self.lift[a] = q[-1]
        return True
