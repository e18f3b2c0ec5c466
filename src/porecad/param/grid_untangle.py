"""Untangling of a structured hex grid whose surface nodes slide on the body (hexahedral parameterisation, step 6).

Not in 000: where a Jacobian of an element is low, the grid Laplace energy
plus barriers on low Jacobians is minimised, interior nodes moving freely and
surface nodes sliding inside their face map or along their cube edge
(:func:`untangle_grid`), then a derivative-free local search on the nodes
of the elements still below the target (:mod:`porecad.param.grid_polish`).

The elements are those the grid will be used as (:mod:`porecad.param.hex_quality`):

* ``hex8``: every cell; its scaled Jacobian at the 8 corners is barred
  (the standard corner measure), and — for cells whose trilinear map folds
  inside although the corners are valid — at 117 interior points;
* ``hex20``: every 2×2×2 block of cells as one 20-node serendipity
  hexahedron (corners and mid-edge nodes of the block; its face and centre
  nodes take part in the Laplace energy only). The serendipity map of a
  block is not the union of its eight trilinear cells and can fold where
  they do not (near the cube's corners on star-shaped blobs), so the
  barriers act on the serendipity map itself at a 4×4×4 lattice of points
  (corners included), on the block's straight 8-node corner cell, and — for
  blocks that still fold — at an 8×8×8 lattice.

The untangled grid is checked by the same measure the scaffold's mapping
refuses by (:func:`porecad.maps.hexmesh.sampled_jacobians`).
"""

from __future__ import annotations


import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from ..maps.hexmesh import corner_scaled_jacobians, sampled_jacobians, shape_derivatives
from .cube import CUBE, CUBE_EDGES, FRAMES
from .grid_polish import polish_grid
from .work_budget import WorkBudget, charged
from .hex_quality import (
    barrier_terms,
    grid_elements,
    lattice_points,
    rows_at,
    sample_dets,
    sample_jacobians,
)

__all__ = ["LIFT_MAX", "SJ_TARGET", "TETHER", "UNTANGLE_LIMIT", "ElementSamples", "boundary_normals",
           "element_quality", "untangle_estimate", "untangle_grid"]

#: untangling runs when a Jacobian is below this, and aims above it
SJ_TARGET = 0.05
EDGE_GAP_MIN = 0.5  # untangling keeps each cube-edge gap at least this fraction of the even one
#: seconds for all untangling of one parameterisation, by default (recipe ``body.untangle_limit``)
UNTANGLE_LIMIT = 60.0
TETHER = 1.0  # weight of a surface node's move in its face map or along its edge, per grid cell squared
#: how far (in mean grid edges) a boundary node may leave the surface outwards
LIFT_MAX = 2.0

_CORNERS = lattice_points((0.0, 1.0))
_D8_CORNERS = shape_derivatives("hex8", _CORNERS)
_D8_INSIDE = shape_derivatives("hex8", lattice_points((0.0, 1 / 3, 0.5, 2 / 3, 1.0), corners=False))
_D8_ALL = shape_derivatives("hex8", lattice_points((0.0, 1 / 3, 0.5, 2 / 3, 1.0)))
# hex20: the lattices of the check the scaffold's mapping refuses by (porecad.maps.hexmesh.sampled_jacobians:
# 4 and, for suspect cells, 12 points per axis, kept 1e-6 inside the cell), so that the barrier enforces it
_D20_MAIN = shape_derivatives("hex20", np.clip(lattice_points(np.linspace(0.0, 1.0, 4)), 1e-6, 1 - 1e-6))
_D20_WATCH = shape_derivatives("hex20", np.clip(lattice_points(np.linspace(0.0, 1.0, 12)), 1e-6, 1 - 1e-6))


class ElementSamples:
    """The elements of a node grid and the sample sets their Jacobians are barred at.

    ``main``: ``[(nodes (H, n), D (S, 3, n))]`` — every element, its scaled
    Jacobian barred by both barriers (row ``e`` of each set belongs to
    element ``e``); ``watch``: ``(nodes, D_scaled, D_det)`` used for the
    elements that fold between the main samples; ``shape``: the element grid.
    """

    def __init__(self, shape, element="hex8"):
        self.element = element
        cells = np.asarray(shape[:3]) - 1
        if element == "hex8":
            e8 = grid_elements(shape, "hex8")
            self.main = [(e8, _D8_CORNERS)]
            self.watch = (e8, _D8_INSIDE, _D8_ALL)
            self.shape = tuple(int(c) for c in cells)
        else:
            e20 = grid_elements(shape, "hex20")
            self.main = [(e20, _D20_MAIN)]
            self.watch = (e20, _D20_WATCH, _D20_WATCH)
            self.shape = tuple(int(c) // 2 for c in cells)
        self.nodes = self.main[0][0]
        self.n = len(self.nodes)

    def main_min(self, P):
        """Smallest main-sample scaled Jacobian of every element, (H,)."""
        return np.min([sample_jacobians(P, e, D).min(axis=1) for e, D in self.main], axis=0)


def element_quality(nodes, element="hex8"):
    """Per element: minimum corner scaled Jacobian and the sampled determinant ratio of the scaffold's check.

    The corner measure is the scaled Jacobian of the element's map at its
    corners (:func:`porecad.maps.hexmesh.corner_scaled_jacobians`); the
    sampled one is :func:`porecad.maps.hexmesh.sampled_jacobians` (min det /
    mean |det| inside the element's map, hex8 or hex20). Both flattened in C
    order of the elements.
    """
    g = np.asarray(nodes, np.float64)
    return (corner_scaled_jacobians(g, element).ravel(), sampled_jacobians(g, element).ravel())


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


def boundary_normals(nodes, ids):
    """Boundary node ids of a node grid and their outward unit normals (the mean of their faces' normals).

    On each of the six boundary slices the normal is the cross product of the
    slice's two in-plane tangents (central differences), turned away from the
    next inner layer.
    """
    g = np.asarray(nodes, np.float64)
    acc = np.zeros_like(g)
    for ax in range(3):
        for end in (0, -1):
            sl = [slice(None)] * 3
            sl[ax] = end
            face = g[tuple(sl)]
            inner_sl = list(sl)
            inner_sl[ax] = 1 if end == 0 else -2
            d1, d2 = (np.gradient(face, axis=a) for a in (0, 1))
            n = np.cross(d1, d2)
            out = face - g[tuple(inner_sl)]
            n *= np.where(np.einsum("...d,...d->...", n, out) < 0, -1.0, 1.0)[..., None]
            n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
            acc[tuple(sl)] += n
    on = np.zeros(g.shape[:3], bool)
    for ax in range(3):
        sl = [slice(None)] * 3
        for end in (0, -1):
            sl[ax] = end
            on[tuple(sl)] = True
    bid = ids[on].ravel()
    nrm = acc.reshape(-1, 3)[bid]
    return bid, nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)


def _scatter(G, elems, Gc):
    """``G[elems[h, c]] += Gc[h, c]`` (bincount per coordinate: much faster than ``np.add.at``)."""
    idx = elems.ravel()
    for d in range(3):
        G[:, d] += np.bincount(idx, weights=Gc[:, :, d].ravel(), minlength=len(G))


def _grown(mask):
    """``mask`` (an element grid) and its 6-neighbours."""
    grown = mask.copy()
    for ax in range(3):
        a = [slice(None)] * 3
        b = [slice(None)] * 3
        a[ax], b[ax] = slice(1, None), slice(None, -1)
        grown[tuple(a)] |= mask[tuple(b)]
        grown[tuple(b)] |= mask[tuple(a)]
    return grown


def untangle_grid(nodes, locators, paths, taus, v, element="hex8", mu=0.2, kappa=20.0, mu2=SJ_TARGET, kappa2=2000.0,
                  maxiter=300, tether=TETHER, budget=None, progress=None, lift_max=LIFT_MAX, start=None,
                  spacing=None):
    """Raise low element Jacobians; interior nodes move freely, surface nodes slide on their face or edge.

    Minimises
    ``E = Σ_grid edges |x_i − x_j|² / h_a² + κ Σ_samples (μ − J)₊² + κ₂ Σ_samples (μ₂ − J)₊²
    + τ_t Σ_surface nodes |n ⊙ (s − s₀)|²``
    (``J`` the scaled Jacobian of an element at its main samples — the
    corners of a hex8 cell; see the module docstring for hex20 —, ``h_a``
    the grid's spacing along the edge's axis, ``spacing`` (scaled so that
    the start grid's Laplace term is ``Σ |x_i − x_j|² / h²``, ``h²`` the
    mean squared edge; by default equal); the last term tethers each surface node to
    its place in the harmonic face map or on its cube edge, in grid cells:
    without it the edge springs pull the surface nodes together where the
    surface is concave, the boundary quads cut the body's corners and the
    grid loses volume — 11 % of the femur at 5×7×20 — by an amount that
    depends on the L-BFGS path, hence on the SciPy version) over the
    interior nodes, the face nodes (by their ``(s, t)`` in the face's
    harmonic map, so they stay on their patch) and the cube-edge nodes (by
    their arc-length parameter ``τ``); the corners stay. The first term is
    the grid Laplace energy whose minimiser for the interior is 000 eq.
    3.2.3; the others are barriers on flat and inverted elements. A barrier
    ``κ₂ Σ (EDGE_GAP_MIN − n Δτ)₊²`` keeps the cube-edge nodes from bunching
    (uneven edge gaps fold the cells beside the edge inside). Every boundary
    node may also leave the surface *outwards*, along the grid's outward
    normal there, by ``0 ≤ ℓ ≤ lift_max`` mean grid edges at a cost
    ``τ_t ℓ²``: a cube corner on a smooth surface has its three edges in the
    tangent plane (its Jacobian vanishes with the cell size), and a grid laid
    on a concave region folds; lifted a little, both open up. The grid then
    covers the body and slightly more; the scaffold is cut to the body
    afterwards (:func:`porecad.maps.hexmesh.hex_scaffold` with ``clip``).
    Elements whose
    map still folds (:func:`element_quality`) are then watched: their
    scaled Jacobian and determinant (against their mean) at a denser sample
    lattice join the barrier, and the descent runs again. L-BFGS-B with
    restarts (the surface map is piecewise linear, line searches stall at
    its kinks), then a derivative-free local search on the nodes of the
    elements still below ``μ₂`` (:func:`porecad.param.grid_polish.polish_grid`).

    ``budget`` (a :class:`WorkBudget`, charged by each energy evaluation
    and each trial of the search) stops the descent and the search at the
    first iteration after it is spent; ``progress(done, total)`` is
    called per 10 L-BFGS iterations (total: the iteration budget).

    ``start`` (optional, e.g. from :func:`porecad.param.half_grid.refine_grid`):
    the face nodes' ``(s, t)`` and the cube-edge nodes' ``τ`` (in the
    order of the grid's faces and edges) and the boundary nodes' lifts that
    ``nodes`` was built from; by default the even ``(i/n_s, j/n_t)`` and
    ``i/n`` of the surface grid, unlifted.

    Returns the node grid, the number of L-BFGS iterations, whether the budget stopped it, and
    ``{"max_lift"`` (in mean grid edges), ``"lifted_nodes"``, ``"coords"``: the final surface
    coordinates, lifts, lifted node ids and their normals (what ``start`` takes)``}``.
    """
    prob = _Untangling(nodes, locators, paths, taus, v, element, start, lift_max, spacing,
                       (mu, kappa, mu2, kappa2, tether))
    prob.budget = budget
    run = _Descent(prob, maxiter, budget, progress)
    # the main samples first; then, while some element's map folds (or nearly) between them, add the
    # dense samples of those elements (and of their neighbours) to the barrier
    x, nit = run.descend(prob.x0, maxiter)
    x, nit = _watch_folds(prob, run, x, nit, nodes.shape, element, mu2, maxiter)
    return _finish(prob, run, x, nit, nodes.shape, mu2, budget, progress, lift_max)


def _start_coords(faces, edges, start, n_lifted):
    """The face and cube-edge node tuples of :func:`_boundary_dofs` with their start coordinates from
    ``start`` (None: the even ones kept), and the ``n_lifted`` boundary nodes' start lifts (default 0)."""
    lift0 = np.zeros(n_lifted)
    if start is not None:  # the surface nodes' coordinates (and lifts) the grid starts from
        faces = [(fc[0], np.asarray(s0, np.float64).reshape(-1, 2), fc[2], fc[3])
                 for fc, s0 in zip(faces, start["faces"])]
        edges = [(ed[0], np.asarray(t0, np.float64), ed[2], ed[3], ed[4]) for ed, t0 in zip(edges, start["edges"])]
        if n_lifted:
            lift0 = np.asarray(start["lifts"], np.float64)
    return faces, edges, lift0


def _grid_laplacian(ids, flat, spacing):
    """The weighted grid graph Laplacian (CSR, nodes × nodes) of the node ids grid at ``flat`` (n, 3), and
    ``h²``, the mean squared grid edge.

    Each grid edge is weighted by 1 / h_a² (h_a: ``spacing`` along its axis), so that the interior's
    minimiser is the Laplace grid of the box with the body's proportions; scaled so that the start grid's
    energy is unchanged (``spacing`` None, equal spacings: every weight 1).
    """
    ea, eb = [], []
    for ax in range(3):
        sa, sb = [slice(None)] * 3, [slice(None)] * 3
        sa[ax], sb[ax] = slice(0, -1), slice(1, None)
        ea.append(ids[tuple(sa)].ravel())
        eb.append(ids[tuple(sb)].ravel())
    n_ax = [len(e) for e in ea]
    ea, eb = np.concatenate(ea), np.concatenate(eb)
    n_nodes = len(flat)
    d2 = np.sum((flat[ea] - flat[eb]) ** 2, axis=1)
    h2 = float(np.mean(d2))
    ew = np.ones(len(ea))
    if spacing is not None:
        ew = np.repeat(1.0 / np.asarray(spacing, np.float64) ** 2, n_ax)
        ew *= d2.sum() / max(float(ew @ d2), 1e-300)
    B = sp.csr_matrix((np.concatenate([np.sqrt(ew), -np.sqrt(ew)]),
                       (np.tile(np.arange(len(ea)), 2), np.concatenate([eb, ea]))), shape=(len(ea), n_nodes))
    Lap = (B.T @ B).tocsr()  # weighted grid graph Laplacian: Σ c_e |x_b − x_a|² = tr(Xᵀ L X)
    return Lap, h2


class _Untangling:
    """The unknowns and the energy of one untangling (:func:`untangle_grid`).

    ``x`` (start ``x0``, ``bounds``): the interior nodes' coordinates, the face nodes' ``(s, t)``, the
    cube-edge nodes' ``τ`` and the boundary nodes' lifts, split at ``cuts``; :meth:`assemble` makes the
    node array, :meth:`fun` the energy and its gradient, with the ``watch``-ed elements (and their
    reference |det| ``vref``) that :func:`_watch_folds` sets between descents.
    """

    def __init__(self, nodes, locators, paths, taus, v, element, start, lift_max, spacing, weights):
        self.mu, self.kappa, self.mu2, self.kappa2, self.tether = weights
        shape = nodes.shape[:3]
        self.flat = flat = nodes.reshape(-1, 3).copy()
        self.els = ElementSamples(shape, element)
        ids, faces, edges = _boundary_dofs(shape, locators, paths, taus, v)
        self.inner = inner = ids[1:-1, 1:-1, 1:-1].ravel()
        lifted, self.nrm = boundary_normals(nodes, ids) if lift_max > 0 else (np.zeros(0, np.int64), np.zeros((0, 3)))
        self.lifted = lifted
        faces, edges, lift0 = _start_coords(faces, edges, start, len(lifted))
        self.faces, self.edges = faces, edges
        x0 = np.concatenate([flat[inner].ravel()] + [fc[1].ravel() for fc in faces] + [ed[1] for ed in edges]
                            + [lift0])
        sizes = [inner.size * 3] + [fc[1].size for fc in faces] + [ed[1].size for ed in edges] + [len(lifted)]
        self.cuts = np.cumsum(sizes)[:-1]
        n_st = int(sum(sizes[1:-1]))
        self.Lap, self.h2 = _grid_laplacian(ids, flat, spacing)
        x0[x0.size - len(lifted):] = np.clip(lift0, 0.0, lift_max * np.sqrt(self.h2))
        self.bounds = ([(None, None)] * (inner.size * 3) + [(1e-6, 1 - 1e-6)] * n_st
                       + [(0.0, lift_max * np.sqrt(self.h2))] * len(lifted))
        self.x0 = x0
        self.x0s = np.split(x0, self.cuts)
        self.watch, self.vref = np.zeros(0, np.int64), np.ones(0)
        self.budget = None  # a WorkBudget each evaluation is charged to

    def assemble(self, x):
        """The node array (n, 3) at the unknowns ``x``, and the Jacobians of the face and edge nodes' places
        with respect to their coordinates (per face (m, 3, 2), per edge (m, 3))."""
        faces, edges, lifted = self.faces, self.edges, self.lifted
        parts = np.split(x, self.cuts)
        P = self.flat.copy()
        P[self.inner] = parts[0].reshape(-1, 3)
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
        if len(lifted):
            P[lifted] += parts[-1][:, None] * self.nrm
        return P, jac

    def barrier(self, P, G, elems, D, soft, ratio=None):
        """Add a barrier's energy and gradient (``ratio``: bar ``det / ratio`` instead of the scaled Jacobian)."""
        if not len(elems):
            return 0.0
        E, W, act = barrier_terms(rows_at(P, elems, D), ratio if ratio is not None else np.ones(len(elems)),
                                  self.mu, self.kappa, self.mu2, self.kappa2, soft, ratio is None)
        if act.any():
            S = D.shape[0]
            Gc = np.matmul(D.reshape(S * 3, -1).T, W[act].reshape(-1, S * 3, 3))
            _scatter(G, elems[act], Gc)
        return E

    def fun(self, x):
        """The energy at the unknowns ``x`` and its gradient (``x``'s shape)."""
        faces, edges, lifted, tether, kappa2, h2 = (self.faces, self.edges, self.lifted, self.tether,
                                                    self.kappa2, self.h2)
        P, jac = self.assemble(x)
        if self.budget is not None:
            self.budget.charge(nodes=len(P))
            for elems, D in self.els.main:
                charged(self.budget, elems, D)
            we, Ds, Dd = self.els.watch
            charged(self.budget, we[self.watch], Ds, Dd)
        LP = self.Lap @ P
        E = float(np.sum(P * LP)) / h2
        G = 2.0 * LP / h2
        for elems, D in self.els.main:
            E += self.barrier(P, G, elems, D, True)
        if self.watch.size:  # the map's Jacobian inside the watched elements (the main samples let them fold between)
            we, Ds, Dd = self.els.watch
            E += self.barrier(P, G, we[self.watch], Ds, False)
            # and its determinant against the element's size: the scaled one stays finite where an
            # edge collapses, and the map can fold between the samples there
            E += self.barrier(P, G, we[self.watch], Dd, False, ratio=self.vref)
        out = [G[self.inner].ravel()]
        xs = np.split(x, self.cuts)
        x0s = self.x0s
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
        if len(lifted):
            lf = xs[-1]
            E += tether * float(np.sum(lf * lf)) / h2
            out.append(np.einsum("md,md->m", G[lifted], self.nrm) + 2.0 * tether * lf / h2)
        return E, np.concatenate(out)


class _Descent:
    """L-BFGS-B descents with restarts on an untangling's energy, sharing an iteration count (``count``,
    reported to ``progress`` per 10 of ``budget_all``) and a :class:`WorkBudget` (``stopped`` once spent)."""

    def __init__(self, prob, maxiter, budget, progress):
        self.prob, self.budget, self.progress = prob, budget, progress
        self.budget_all = 5 * 10 * maxiter
        self.count = 0
        self.stopped = False

    def callback(self, _):
        """Per L-BFGS iteration: count it, report progress, stop once the budget is spent."""
        self.count += 1
        if self.progress is not None and self.count % 10 == 0:
            self.progress(min(self.count, self.budget_all), self.budget_all)
        if self.budget is not None and self.budget.spent:
            self.stopped = True
            raise StopIteration

    def descend(self, x, budget):
        """Up to 10 L-BFGS-B runs from ``x`` (the surface map is piecewise linear, line searches stall at
        its kinks) while they improve, within ``budget`` iterations; returns the best ``x`` and the
        iterations used."""
        from scipy.optimize import minimize
        fun = self.prob.fun
        it, best = 0, fun(x)[0]
        for _ in range(10):
            if self.stopped:
                break
            # one BLAS thread: the L-BFGS-B vector operations are small, and threads waiting on each other
            # made each iteration ~80x slower on a loaded 2-core machine (0.13 s instead of 1.7 ms at 15k unknowns)
            with threadpool_limits(limits=1, user_api="blas"):
                res = minimize(fun, x, jac=True, method="L-BFGS-B", bounds=self.prob.bounds, callback=self.callback,
                               options={"maxiter": budget, "maxcor": 10})
            it += int(res.nit)
            improved = res.fun < best - 1e-6 * abs(best)
            if res.fun <= best:
                x, best = res.x, float(res.fun)
            if res.success or not improved or it >= budget:
                break
        return x, it


def _watch_folds(prob, run, x, nit, shape, element, mu2, maxiter):
    """Up to four times: watch the elements whose map still folds (or nearly) at ``x`` (and their
    neighbours) — their dense samples join ``prob``'s barrier — and descend again.

    Takes the :class:`_Untangling`, the :class:`_Descent`, the unknowns and iterations so far, the node
    grid's shape, the element kind, ``μ₂`` and the iteration budget; returns the unknowns and iterations.
    """
    els = prob.els
    el_ids = np.arange(els.n).reshape(els.shape)
    for _ in range(4):
        if run.stopped:
            break
        P, _ = prob.assemble(x)
        corner, inside = element_quality(P.reshape(shape), element)
        low = np.flatnonzero((np.minimum(corner, inside) < mu2) | (els.main_min(P) < mu2))
        low = np.setdiff1d(low, prob.watch)
        if not low.size:
            break
        mask = np.zeros(els.shape, bool)
        mask.ravel()[low] = True
        prob.watch = np.union1d(prob.watch, el_ids[_grown(mask)].ravel())
        we, _, Dd = els.watch
        # fixed during the descent
        prob.vref = np.maximum(np.abs(sample_dets(P, we[prob.watch], Dd)).mean(axis=1), 1e-300)
        x, it = run.descend(x, maxiter)
        nit += it
    return x, nit


def _finish(prob, run, x, nit, shape, mu2, budget, progress, lift_max):
    """The local search (unless the budget stopped the descent) and :func:`untangle_grid`'s return value
    at the unknowns ``x``: the node grid (``shape``), ``nit``, whether the budget stopped it, the stats."""
    P, _ = prob.assemble(x)
    parts = np.split(x, prob.cuts)
    nf = len(prob.faces)
    st = [p_.reshape(-1, 2) for p_ in parts[1:1 + nf]]
    tt = list(parts[1 + nf:1 + nf + len(prob.edges)])
    lifts = parts[-1]
    h2 = prob.h2
    if not run.stopped:
        P, lifts, st, tt = polish_grid(P, prob.els, prob.faces, prob.edges, np.split(x, prob.cuts), prob.inner,
                                       mu2, watch=prob.watch, vref=prob.vref, budget=budget,
                                       lifted=prob.lifted, nrm=prob.nrm, lift_max=lift_max * np.sqrt(h2))
    if progress is not None:
        progress(run.budget_all, run.budget_all)
    h = np.sqrt(h2)
    stats = {"max_lift": float(lifts.max(initial=0.0) / h), "lifted_nodes": int(np.sum(lifts > 1e-3 * h)),
             "coords": {"faces": st, "edges": tt, "lifts": lifts, "lifted": prob.lifted, "normals": prob.nrm}}
    return (P.reshape(shape), nit, run.stopped or (budget is not None and budget.spent),
            stats)


def untangle_estimate(nodes, element="hex8"):
    """Seconds the untangling may take: one modelled energy evaluation (:class:`WorkBudget`) × a typical count.

    The L-BFGS descent evaluates the energy about 1.1 times per iteration and
    typically needs a few hundred iterations (about ``25 (nodes)^⅓``
    measured on the femur and on noisy blobs).
    """
    P = np.asarray(nodes, np.float64).reshape(-1, 3)
    one = WorkBudget(0.0)
    one.charge(nodes=len(P))
    for elems, D in ElementSamples(nodes.shape[:3], element).main:
        charged(one, elems, D)
    per = -one.left
    iters = 25.0 * float(len(P)) ** (1.0 / 3.0)
    return per * 1.1 * iters
