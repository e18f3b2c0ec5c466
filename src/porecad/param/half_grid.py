"""A node grid at half steps from an untangled one: the start of the 20-node untangling (hexahedral parameterisation).

A 20-node element is a 2×2×2 block of the half-step grid
(:mod:`porecad.param.hex_quality`). Untangled from scratch, the half-step
grid has eight times the cells of the element grid; most of its folds are
already those of the element grid, which is cheap to untangle as 8-node
cells. :func:`refine_grid` takes that untangled grid and puts

* interior nodes at the trilinear midpoints of its cells, so every interior
  20-node element starts as the (valid) 8-node cell it refines;
* surface nodes at the midpoints of their neighbours' *surface* coordinates
  — ``(s, t)`` in the face's harmonic map, ``τ`` along the cube edge — on
  the body, plus the neighbours' mean outward lift; the boundary elements
  then follow the body's curvature and are what the 20-node untangling
  (:func:`porecad.param.grid_untangle.untangle_grid` with ``element="hex20"``
  and ``start``) still has to fix.
"""

from __future__ import annotations

import numpy as np

from .cube import CUBE, CUBE_EDGES, FACE_EDGES, FRAMES
from .grid_untangle import boundary_normals, element_quality

__all__ = ["refine_grid", "regular_coords", "straighten_folded"]


def _halve(a, axes):
    """Linear refinement of ``a`` along ``axes``: ``n`` samples → ``2n − 1`` (the old ones, then midpoints)."""
    for ax in axes:
        a = np.moveaxis(a, ax, 0)
        out = np.empty((2 * a.shape[0] - 1,) + a.shape[1:], a.dtype)
        out[::2] = a
        out[1::2] = 0.5 * (a[:-1] + a[1:])
        a = np.moveaxis(out, 0, ax)
    return a


def _present(N):
    """The faces and cube edges that carry free nodes at cell counts ``N`` (the order of the untangling)."""
    faces = [fc for fc, (_, _, p, q, _) in enumerate(FRAMES) if N[p] >= 2 and N[q] >= 2]
    edges = [k for k, (a, b) in enumerate(CUBE_EDGES) if N[int(np.flatnonzero(CUBE[a] != CUBE[b])[0])] >= 2]
    return faces, edges


def regular_coords(N):
    """The surface coordinates of an unmoved surface grid: ``(i/n_s, j/n_t)`` per face, ``i/n`` per edge."""
    faces, edges = _present(N)
    st = []
    for fc in faces:
        _, _, p, q, _ = FRAMES[fc]
        ii, jj = np.meshgrid(np.arange(1, N[p]) / N[p], np.arange(1, N[q]) / N[q], indexing="ij")
        st.append(np.stack([ii.ravel(), jj.ravel()], 1))
    tt = []
    for k in edges:
        a, b = CUBE_EDGES[k]
        n = int(N[int(np.flatnonzero(CUBE[a] != CUBE[b])[0])])
        tt.append(np.arange(1, n) / n)
    return {"faces": st, "edges": tt}


def _edge_taus(N, coords):
    """Per cube edge: ``τ`` of all its nodes, ends included, from corner ``a`` to ``b``."""
    _, edges = _present(N)
    full = []
    given = dict(zip(edges, coords["edges"]))
    for k, (a, b) in enumerate(CUBE_EDGES):
        inner = given.get(k, np.zeros(0))
        full.append(np.concatenate([[0.0], np.asarray(inner, np.float64), [1.0]]))
    return full


def _face_uv(N, coords, taus_full):
    """Per face: the ``(s, t)`` of all its nodes, (N_p + 1, N_q + 1, 2), boundary from the edges' ``τ``."""
    faces, _ = _present(N)
    given = dict(zip(faces, coords["faces"]))
    out = []
    for fc, (ax, val, p, q, _) in enumerate(FRAMES):
        uv = np.zeros((N[p] + 1, N[q] + 1, 2))
        if fc in given:
            uv[1:-1, 1:-1] = np.asarray(given[fc]).reshape(N[p] - 1, N[q] - 1, 2)
        for k in FACE_EDGES[fc]:
            a, b = CUBE_EDGES[k]
            d = int(np.flatnonzero(CUBE[a] != CUBE[b])[0])
            sgn = int(CUBE[b, d] - CUBE[a, d])
            idx = np.tile(CUBE[a] * np.asarray(N), (N[d] + 1, 1))
            idx[:, d] += sgn * np.arange(N[d] + 1)
            A, B = CUBE[a, [p, q]].astype(float), CUBE[b, [p, q]].astype(float)
            uv[idx[:, p], idx[:, q]] = A + taus_full[k][:, None] * (B - A)
        out.append(uv)
    return out


def refine_grid(nodes, coords, locators, paths, taus, v, lift_max=None):
    """The half-step grid ``(2nu+1, 2nv+1, 2nw+1, 3)`` of an (untangled) node grid, and its ``start``.

    Parameters
    ----------
    nodes : (nu+1, nv+1, nw+1, 3) float
    coords : dict or None
        ``{"faces", "edges"}`` surface coordinates the grid's surface nodes
        sit at (and optionally ``"lifts"``, ``"lifted"``, ``"normals"``), as
        returned by the untangling; None: :func:`regular_coords`, unlifted.
    locators, paths, taus, v
        The face maps, cube-edge paths and their arc-length parameters of
        the surface grid (:func:`porecad.param.patch_maps.surface_grid`), and
        the mesh vertices.
    lift_max : float, optional
        Largest lift (mm) kept.

    Returns
    -------
    fine : (2nu+1, 2nv+1, 2nw+1, 3) float64
    start : dict
        ``{"faces", "edges", "lifts"}`` for ``untangle_grid(fine, ..., start=start)``.
    """
    g = np.asarray(nodes, np.float64)
    N = tuple(int(s) - 1 for s in g.shape[:3])
    Nf = tuple(2 * n for n in N)
    if coords is None:
        coords = regular_coords(N)
    fine = _halve(g, (0, 1, 2))
    lift = np.zeros_like(g).reshape(-1, 3)
    if coords.get("lifted") is not None and len(coords["lifted"]):
        lift[coords["lifted"]] = np.asarray(coords["lifts"])[:, None] * coords["normals"]
    lift = _halve(lift.reshape(g.shape), (0, 1, 2))
    surf = fine.copy()  # surface positions of the boundary nodes (interior rows unused)
    tf = [_halve(t, (0,)) for t in _edge_taus(N, coords)]
    for k, (a, b) in enumerate(CUBE_EDGES):
        d = int(np.flatnonzero(CUBE[a] != CUBE[b])[0])
        sgn = int(CUBE[b, d] - CUBE[a, d])
        idx = np.tile(CUBE[a] * np.asarray(Nf), (Nf[d] + 1, 1))
        idx[:, d] += sgn * np.arange(Nf[d] + 1)
        poly = v[paths[k]]
        surf[idx[:, 0], idx[:, 1], idx[:, 2]] = np.stack([np.interp(tf[k], taus[k], poly[:, dd]) for dd in range(3)],
                                                         axis=1)
    uvf = [_halve(uv, (0, 1)) for uv in _face_uv(N, coords, _edge_taus(N, coords))]
    for fc, (ax, val, p, q, _) in enumerate(FRAMES):
        inner = uvf[fc][1:-1, 1:-1].reshape(-1, 2)
        if not len(inner):
            continue
        ii, jj = np.meshgrid(np.arange(1, Nf[p]), np.arange(1, Nf[q]), indexing="ij")
        idx = np.zeros((ii.size, 3), np.int64)
        idx[:, ax] = val * Nf[ax]
        idx[:, p], idx[:, q] = ii.ravel(), jj.ravel()
        surf[idx[:, 0], idx[:, 1], idx[:, 2]] = locators[fc].evaluate(inner)[0]
    ids = np.arange(int(np.prod(np.array(Nf) + 1))).reshape(tuple(n + 1 for n in Nf))
    provisional = fine.reshape(-1, 3).copy()
    bid, _ = boundary_normals(fine, ids)
    provisional[bid] = surf.reshape(-1, 3)[bid] + lift.reshape(-1, 3)[bid]
    provisional = provisional.reshape(fine.shape)
    bid, nrm = boundary_normals(provisional, ids)
    ell = np.maximum(np.einsum("md,md->m", lift.reshape(-1, 3)[bid], nrm), 0.0)
    if lift_max is not None:
        ell = np.minimum(ell, lift_max)
    out = provisional.reshape(-1, 3)
    out[bid] = surf.reshape(-1, 3)[bid] + ell[:, None] * nrm
    faces_p, edges_p = _present(Nf)
    start = {"faces": [uvf[fc][1:-1, 1:-1].reshape(-1, 2) for fc in faces_p],
             "edges": [tf[k][1:-1] for k in edges_p], "lifts": ell}
    return out.reshape(fine.shape), start


def straighten_folded(nodes, floor: float = 1e-3, step: float = 0.25, max_rounds: int = 12):
    """Straighten the 20-node elements of a half-step grid that fold, toward their valid 8-node corner cells.

    A 20-node element whose mid-edge nodes put a fold inside it (its corner
    cell being valid) is a curved version of that cell: moving its
    non-corner nodes toward the trilinear places of its corners (``t = 0``:
    as given, ``t = 1``: the corner cell itself, which a 20-node element
    reproduces exactly) unfolds it. The blend grows by ``step`` on every
    element whose quality (the smaller of the corner scaled Jacobian and the
    sampled determinant ratio, :func:`porecad.param.grid_untangle.element_quality`)
    is below ``floor``; a node shared by several elements takes the largest
    blend among them, so the neighbours are checked again on the next round
    (a straightened element can fold a neighbour through a shared edge). At
    most ``max_rounds`` rounds; the quality returned is that of the grid
    returned. A grid whose corner cells fold (as 8-node cells) is returned
    unchanged (``corner_cells_fold``, its quality not computed).

    Returns
    -------
    nodes : (2nu+1, 2nv+1, 2nw+1, 3) float64
        The blended grid (the corner nodes unmoved).
    info : dict
        ``elements``: elements blended; ``max_blend``; ``quality``: the
        smallest element quality after (None when the corner cells fold);
        ``rounds``: blending rounds run.
    """
    g0 = np.asarray(nodes, np.float64)
    cells = tuple((int(s) - 1) // 2 for s in g0.shape[:3])
    sj, si = element_quality(g0[::2, ::2, ::2], "hex8")
    if not min(float(sj.min()), float(si.min())) > 0:  # the corner cells fold: straightening cannot unfold them
        return g0, {"elements": 0, "max_blend": 0.0, "quality": None, "rounds": 0, "corner_cells_fold": True}
    straight = _halve(g0[::2, ::2, ::2], (0, 1, 2))
    t = np.zeros(cells)
    g = g0
    rounds = 0
    while True:
        sj, si = element_quality(g, "hex20")
        q = np.minimum(sj, si).reshape(cells)
        bad = (q < floor) & (t < 1.0)
        if not bad.any() or rounds == max_rounds:
            break
        rounds += 1
        t[bad] = np.minimum(t[bad] + step, 1.0)
        w = np.zeros(g0.shape[:3])
        for o in np.ndindex(3, 3, 3):  # every node of a 2×2×2 block takes the largest blend of its elements
            sl = tuple(slice(o[a], o[a] + 2 * cells[a], 2) for a in range(3))
            w[sl] = np.maximum(w[sl], t)
        g = g0 + w[..., None] * (straight - g0)
    return g, {"elements": int(np.sum(t > 0)), "max_blend": float(t.max()), "quality": float(q.min()),
               "rounds": rounds}
