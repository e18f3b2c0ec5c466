"""Conforming 3-refinement of a region of an all-hex mesh (004 Fig. 6, the full template of its ref. [11]).

Vertex-based 3-refinement (Schneiders; Zhang, Bajaj & Xu): the user marks
vertices; every hexahedron is replaced by the template fixed by which of its
corners are marked. With ``p = 1/3``, in the reference cube of the template
(canonical marked corners first):

* none marked — the hexahedron stays whole;
* one corner (``0``) — the point template of :mod:`porecad.volmesh.refine`
  (4 hexahedra);
* one edge (corners ``0, 1``) — the **edge template** (11 hexahedra): a row
  of three cubes ``[kp, (k+1)p] × [0, p]²`` along the edge, and the two
  prisms over the quads of the 2D corner template in the ``(y, z)`` section
  (``(p,0) (1,0) (1,1) (p,p)`` and its mirror), each the 2D 3-to-1
  transition (4 quads) extruded across the prism (4 hexahedra each);
* one face (corners ``0 1 2 3``) — the **face template** (22 hexahedra): a
  layer of 3 × 3 cubes ``z ∈ [0, p]`` and above it the 3 × 3 → 1 transition
  block of 13 hexahedra (9 on the 3 × 3 layer, reaching the side faces at
  height ``hs`` and inner nodes at ``hi``, then 4 closing it to the top face);
* all eight — 27 cubes.

The split of a face depends only on which of its corners are marked: none —
whole; one — the 2D corner template; the two of one edge — the 2D edge
template (a row of three squares ``t ∈ [0, p]`` and above it the 3-to-1
transition of four quads with inner nodes at ``(p, p + (1 - p) hs)`` and
``(2p, p + (1 - p) hs)``); all four — 3 × 3. Each pattern is symmetric under
the face's symmetries that keep its marking, so both hexahedra sharing a face
split it identically and the refined mesh is conforming. Other markings of a
hexahedron (two diagonal corners, three corners, ...) have no template and are
refused; :func:`refine_box` marks the vertices of a box of cells of a
structured grid, which only ever gives the four patterns above.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..errors import InputError
from .hexshapes import HEX_CORNER_NEIGHBOURS, check_hex_mesh

__all__ = ["refine_region", "refine_box", "TEMPLATES", "HS", "HI"]

_P = 1.0 / 3.0
#: Height (in the 3-to-1 transition, 0 at the fine side, 1 at the coarse) of the transition's inner nodes on faces.
HS = 0.5
#: Height of the inner nodes of the face template's 3 × 3 → 1 block.
HI = 0.25
_CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)


def _jac(h):
    e = h[HEX_CORNER_NEIGHBOURS] - h[:, None, :]
    return np.linalg.det(e)


def _valid(h):
    h = np.asarray(h, float)
    if np.all(_jac(h) > 0):
        return h
    flipped = h[[4, 5, 6, 7, 0, 1, 2, 3]]
    if np.all(_jac(flipped) > 0):
        return flipped
    raise AssertionError("refinement template is not a valid hexahedron")  # pragma: no cover


def _box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return lo + _CUBE * (hi - lo)


def _transition_2d():
    """The 2D 3-to-1 transition in ``(u, t)``: three segments at ``t = 0`` to one at ``t = 1`` (4 quads)."""
    a = [(0, 0), (_P, 0), (2 * _P, 0), (1, 0)]
    m1, m2, t0, t1 = (_P, HS), (2 * _P, HS), (0, 1), (1, 1)
    return np.array([[a[0], a[1], m1, t0], [a[1], a[2], m2, m1], [a[2], a[3], t1, m2], [m1, m2, t1, t0]], float)


def _point_template():
    """A cube of a third at corner 0 and three hexahedra joining its inner faces to the far faces."""
    s = _P
    hx = np.array([[s, 0, 0], [1, 0, 0], [1, 1, 0], [s, s, 0], [s, 0, s], [1, 0, 1], [1, 1, 1], [s, s, s]])
    out = [_CUBE * s]
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # Hx, then the cyclic axis permutations (Hy, Hz)
        out.append(_valid(hx[:, np.argsort(perm)]))
    return np.stack(out)


def _edge_template():
    s = _P
    out = [_box((k * s, 0, 0), ((k + 1) * s, s, s)) for k in range(3)]
    quad = np.array([[s, 0], [1, 0], [1, 1], [s, s]])  # Q1 in (y, z): t along y, s from z = 0 to the diagonal

    def prism(x, t, w, swap):
        yz = ((1 - t) * (1 - w))[..., None] * quad[0] + (t * (1 - w))[..., None] * quad[1] \
            + (t * w)[..., None] * quad[2] + ((1 - t) * w)[..., None] * quad[3]
        if swap:
            yz = yz[..., ::-1]
        return np.concatenate([x[..., None], yz], axis=-1)

    for swap in (False, True):
        for q in _transition_2d():
            u, t = q[:, 0], q[:, 1]
            bottom = prism(u, t, np.zeros(4), swap)
            top = prism(u, t, np.ones(4), swap)
            out.append(_valid(np.concatenate([bottom, top])))
    return np.stack(out)


def _face_template():
    s = _P
    out = [_box((i * s, j * s, 0), ((i + 1) * s, (j + 1) * s, s)) for j in range(3) for i in range(3)]

    def node(i, j, level):
        """Block nodes: level 0 the 3×3 layer's top, level 1 the surface (T at corners, side nodes, inner nodes)."""
        x, y = i / 3.0, j / 3.0
        if level == 0:
            z = 0.0
        elif i in (0, 3) and j in (0, 3):
            z = 1.0
        elif i in (0, 3) or j in (0, 3):
            z = HS
        else:
            z = HI
        return (x, y, s + (1 - s) * z)

    block = []
    for j in range(3):
        for i in range(3):
            c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
            block.append([node(a, b, 0) for a, b in c] + [node(a, b, 1) for a, b in c])
    m = lambda i, j: node(i, j, 1)  # noqa: E731
    block.append([m(1, 1), m(2, 1), m(2, 2), m(1, 2), m(0, 1), m(3, 1), m(3, 2), m(0, 2)])  # X
    block.append([m(0, 1), m(3, 1), m(3, 2), m(0, 2), m(0, 0), m(3, 0), m(3, 3), m(0, 3)])  # Y (to the top)
    block.append([m(1, 0), m(2, 0), m(2, 1), m(1, 1), m(0, 0), m(3, 0), m(3, 1), m(0, 1)])  # front
    block.append([m(1, 3), m(2, 3), m(2, 2), m(1, 2), m(0, 3), m(3, 3), m(3, 2), m(0, 2)])  # back
    out += [_valid(h) for h in block]
    return np.stack(out)


def _full_template():
    s = _P
    return np.stack([_box((i * s, j * s, k * s), ((i + 1) * s, (j + 1) * s, (k + 1) * s))
                     for k in range(3) for j in range(3) for i in range(3)])


#: Templates by name: (n, 8, 3) reference coordinates (VTK order, valid) with their canonical marked corners.
TEMPLATES = {
    "point": (_point_template(), (0,)),
    "edge": (_edge_template(), (0, 1)),
    "face": (_face_template(), (0, 1, 2, 3)),
    "full": (_full_template(), tuple(range(8))),
}


def _rotations():
    """The 24 rotations of the cube as corner permutations σ (new corner c = old corner σ[c])."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            R = np.zeros((3, 3))
            R[range(3), perm] = signs
            if np.linalg.det(R) < 0:
                continue
            moved = (_CUBE - 0.5) @ R.T + 0.5
            sigma = np.array([int(np.flatnonzero(np.all(np.isclose(_CUBE, q), axis=1))[0]) for q in moved])
            out.append(sigma)
    return out


def _pattern_table():
    """Map a corner-marking bitmask to (template name, σ) with the canonical corners of the template marked."""
    table = {0: None}
    for sigma in _rotations():
        for name, (_, canon) in TEMPLATES.items():
            mask = sum(1 << int(sigma[c]) for c in canon)
            table.setdefault(mask, (name, sigma))
    return table


_TABLE = _pattern_table()


def refine_region(points, hexes, marked_vertices, tol=1e-9):
    """3-refine a hex mesh around the marked vertices; return the conforming refined ``(points, hexes)``.

    Every hexahedron with all eight corners marked becomes 27; those with one
    marked face, edge or corner get the face, edge or point transition
    template (module docstring). Any other marking of a hexahedron is refused
    with :class:`~porecad.errors.InputError` (mark the vertices of a box of
    cells, e.g. with :func:`refine_box`).
    """
    from ..maps.hexmesh import shape_hex8
    from ..mesh.weld import close_point_representatives

    P, H = check_hex_mesh(points, hexes)
    marked = np.unique(np.asarray(list(marked_vertices), dtype=np.int64).reshape(-1))
    if marked.size == 0:
        return P, H
    if marked.min() < 0 or marked.max() >= len(P):
        raise InputError(f"refinement vertex ids must lie in 0..{len(P) - 1}")
    is_marked = np.zeros(len(P), bool)
    is_marked[marked] = True
    masks = (is_marked[H].astype(np.int64) << np.arange(8)).sum(axis=1)
    bad = [h for h, m in enumerate(masks) if int(m) not in _TABLE]
    if bad:
        h = bad[0]
        raise InputError(f"hexahedron {h} has marked corners {[int(v) for v in H[h][is_marked[H[h]]]]} that are not "
                         "one corner, one edge, one face or all eight: no 3-refinement template fits; mark the "
                         "vertices of a box of cells (refine_box)")
    new_pts = [P]
    new_hex = [H[masks == 0]]
    n = len(P)
    for h in np.flatnonzero(masks):
        name, sigma = _TABLE[int(masks[h])]
        tmpl = TEMPLATES[name][0]
        pts = shape_hex8(tmpl.reshape(-1, 3)) @ P[H[h][sigma]]
        new_pts.append(pts)
        new_hex.append(np.arange(n, n + len(pts)).reshape(-1, 8))
        n += len(pts)
    allp = np.concatenate(new_pts)
    allh = np.concatenate(new_hex)
    rep = close_point_representatives(allp, tol * (float(np.ptp(P, axis=0).max()) or 1.0))
    used, inv = np.unique(rep, return_inverse=True)
    return check_hex_mesh(allp[used], inv.reshape(-1)[allh.reshape(-1)].reshape(-1, 8))


def refine_box(points, hexes, grid_shape, lo, hi):
    """3-refine the cells ``lo <= (i, j, k) < hi`` of a structured grid mesh (:func:`hex_grid` numbering).

    Marks every vertex of those cells and calls :func:`refine_region`; the
    cells around the box get the transition templates.
    """
    try:
        shape = tuple(int(v) for v in grid_shape)
        lo = tuple(int(v) for v in lo)
        hi = tuple(int(v) for v in hi)
    except (TypeError, ValueError):
        raise InputError("grid_shape, lo and hi must be three integers each") from None
    if not (len(shape) == len(lo) == len(hi) == 3):
        raise InputError("grid_shape, lo and hi must be three integers each")
    nx, ny, nz = shape
    if min(shape) < 1:
        raise InputError(f"grid_shape must be positive, got {shape}")
    P = np.asarray(points)
    H = np.asarray(hexes)
    if len(P) != (nx + 1) * (ny + 1) * (nz + 1) or len(H) != nx * ny * nz:
        raise InputError(f"the mesh ({len(P)} points, {len(H)} hexes) is not a {nx}×{ny}×{nz} hex_grid")
    for a, b, n, ax in zip(lo, hi, shape, "ijk"):
        if not (0 <= a < b <= n):
            raise InputError(f"box {ax} range [{a}, {b}) must be non-empty and lie in [0, {n}]")
    c, b, a = np.meshgrid(np.arange(lo[2], hi[2] + 1), np.arange(lo[1], hi[1] + 1), np.arange(lo[0], hi[0] + 1),
                          indexing="ij")
    marked = (a + (nx + 1) * (b + (ny + 1) * c)).ravel()
    return refine_region(P, H, marked)
