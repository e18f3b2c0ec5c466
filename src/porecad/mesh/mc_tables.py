"""Marching-cubes and marching-squares tables, generated from one face rule.

The classic marching-cubes table (Lorensen & Cline 1987) leaves the
"ambiguous face" (two diagonally opposite corners inside) to chance, which
lets neighbouring cubes disagree and opens holes. Here the tables are
*generated* from a single rule applied identically to every face:

    on an ambiguous face the inside corners are separated
    (the inside region is face-disconnected).

Because two cubes that share a face see the same four corner signs, they cut
that face along the same segments, so the surface is crack-free; each cube's
surface is a set of disjoint loops on the cube boundary, each loop
triangulated as a disc (n-gon -> n-2 triangles, as in the classic table), so
the result is a closed 2-manifold wherever the grid closes it.

The same rule drives the marching-squares table used to cap solids on the
faces of the sampling box (the "outside triangles" that close a volume TPMS
structure, document 001 section 3.1), so caps meet the surface exactly.

Conventions
-----------
Corner ``c`` of a cube has offset ``(c & 1, (c >> 1) & 1, (c >> 2) & 1)`` in
``(x, y, z)``. Corner ``c`` is *inside* when its field value is negative and
contributes bit ``c`` to the case index. Edge ``e`` joins corners
``EDGE_CORNERS[e]`` along axis ``EDGE_AXIS[e]`` starting at offset
``EDGE_BASE[e]``. Triangles are oriented so that their right-hand normal
points from inside (negative) to outside (positive).

A square (a face of the sampling box) has corners 0:(0,0), 1:(1,0),
2:(1,1), 3:(0,1) in its local ``(u, v)`` frame and edges 0:(0-1), 1:(1-2),
2:(2-3), 3:(3-0). Cap points are coded 0..3 for corners and 4..7 for edges;
cap triangles are counter-clockwise in ``(u, v)``.
"""

from __future__ import annotations

import numpy as np

CORNER_OFFSETS = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=np.int64)


def _build_edges():
    corners, axes, bases = [], [], []
    for axis in range(3):
        for c in range(8):
            if not (c >> axis) & 1:
                corners.append((c, c | (1 << axis)))
                axes.append(axis)
                bases.append(CORNER_OFFSETS[c])
    return (np.array(corners, dtype=np.int64), np.array(axes, dtype=np.int64),
            np.array(bases, dtype=np.int64))


EDGE_CORNERS, EDGE_AXIS, EDGE_BASE = _build_edges()

# square corner offsets in (u, v), counter-clockwise
_SQ_CORNERS = [(0, 0), (1, 0), (1, 1), (0, 1)]
_SQ_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0)]


def _square_polygons(case: int) -> list[list[int]]:
    """Inside-region polygons of one square, CCW, points coded 0..3 corner, 4..7 edge."""
    inside = [(case >> s) & 1 for s in range(4)]
    if case in (0b0101, 0b1010):  # ambiguous: separate the inside corners
        polys = []
        for s in range(4):
            if inside[s]:
                # edges adjacent to corner s: the edge leaving s (s) and the edge arriving (s-1)
                polys.append([s, 4 + s, 4 + (s - 1) % 4])
        # CCW: corner s, then edge s (towards s+1) ... must be reordered CCW
        return [[p[0], p[1], p[2]] for p in polys]
    poly = []
    for s in range(4):
        if inside[s]:
            poly.append(s)
        a, b = _SQ_EDGES[s]
        if inside[a] != inside[b]:
            poly.append(4 + s)
    return [poly] if poly else []


def _point_uv(code: int) -> np.ndarray:
    if code < 4:
        return np.array(_SQ_CORNERS[code], dtype=float)
    a, b = _SQ_EDGES[code - 4]
    return 0.5 * (np.array(_SQ_CORNERS[a], float) + np.array(_SQ_CORNERS[b], float))


def _ccw(poly: list[int]) -> list[int]:
    pts = np.array([_point_uv(p) for p in poly])
    x, y = pts[:, 0], pts[:, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    return poly if area > 0 else poly[::-1]


def _build_square_table():
    """(16, 3, 3) triangle table of cap points, CCW, padded with -1; and counts."""
    table = -np.ones((16, 3, 3), dtype=np.int64)
    count = np.zeros(16, dtype=np.int64)
    segs = {}
    for case in range(16):
        tris = []
        seg = []
        for poly in _square_polygons(case):
            poly = _ccw(poly)
            for t in range(1, len(poly) - 1):
                tris.append((poly[0], poly[t], poly[t + 1]))
            n = len(poly)
            for t in range(n):
                p, q = poly[t], poly[(t + 1) % n]
                if p >= 4 and q >= 4:
                    seg.append((p - 4, q - 4))  # inside on the left of p->q (CCW)
        segs[case] = seg
        count[case] = len(tris)
        for t, tri in enumerate(tris):
            table[case, t] = tri
    return table, count, segs


SQUARE_TRIS, SQUARE_COUNT, _SQUARE_SEGMENTS = _build_square_table()

# cube faces: (axis, side); local frame (u, v) = the two other axes in cyclic order
_FACE_UV = {0: (1, 2), 1: (2, 0), 2: (0, 1)}


def _face_corner(axis: int, side: int, s: int) -> int:
    """Cube corner index of square corner s on face (axis, side)."""
    u_ax, v_ax = _FACE_UV[axis]
    du, dv = _SQ_CORNERS[s]
    off = [0, 0, 0]
    off[axis], off[u_ax], off[v_ax] = side, du, dv
    return off[0] | (off[1] << 1) | (off[2] << 2)


def _cube_edge(c0: int, c1: int) -> int:
    a, b = min(c0, c1), max(c0, c1)
    for e in range(12):
        if EDGE_CORNERS[e, 0] == a and EDGE_CORNERS[e, 1] == b:
            return e
    raise AssertionError("not an edge")


def _cube_loops(case: int, ambiguous_edges: set | None = None) -> list[list[int]]:
    """Surface loops of a cube case (edge indices); edges on an ambiguous face go to ``ambiguous_edges``."""
    nxt = {}
    for axis in range(3):
        for side in (0, 1):
            corners = [_face_corner(axis, side, s) for s in range(4)]
            sq_case = sum(((case >> corners[s]) & 1) << s for s in range(4))
            for p, q in _SQUARE_SEGMENTS[sq_case]:
                ep = _cube_edge(corners[_SQ_EDGES[p][0]], corners[_SQ_EDGES[p][1]])
                eq = _cube_edge(corners[_SQ_EDGES[q][0]], corners[_SQ_EDGES[q][1]])
                # the (u, v) frame has normal +axis; on side 0 the outward normal is -axis
                if side == 0:
                    ep, eq = eq, ep
                assert ep not in nxt
                nxt[ep] = eq
                if ambiguous_edges is not None and sq_case in (5, 10):
                    ambiguous_edges.update((ep, eq))
    loops = []
    while nxt:
        start = min(nxt)
        loop = [start]
        cur = nxt.pop(start)
        while cur != start:
            loop.append(cur)
            cur = nxt.pop(cur)
        loops.append(loop)
    return loops


def _triangulate_loop(n: int) -> list[tuple[int, int, int]]:
    """Zig-zag strip triangulation of an n-gon; every triangle keeps the loop order."""
    tris = []
    i, j, front = 0, n - 1, True
    while j - i >= 2:
        if front:
            tris.append((i, i + 1, j))
            i += 1
        else:
            tris.append((i, j - 1, j))
            j -= 1
        front = not front
    return tris


#: code of a loop's centre vertex in CUBE_TRIS (edges are 0..11)
CENTRE = 12


def _build_cube_table():
    """Triangles per cube case, plus the loops triangulated around a centre vertex.

    A loop of 5 or more vertices that crosses an ambiguous face is not a
    disc-like patch: strip triangulations of it fold through themselves for
    some edge parameters (seen on the femur at a body/lattice crease). Such a
    loop is triangulated as a star around the centroid of its vertices
    (code ``CENTRE``): the loop lies on the cube's surface and the centroid
    inside, so the central projection keeps the star's triangles apart.
    At most one loop per case needs it (asserted).
    """
    tris_all, centre_edges = [], []
    for case in range(256):
        tris, centre = [], []
        ambiguous = set()
        for loop in _cube_loops(case, ambiguous):
            # the loop runs with the inside on its left seen from outside the cube,
            # whose right-hand normal points inwards: reverse it to point outwards
            loop = loop[::-1]
            if len(loop) >= 5 and ambiguous & set(loop):
                assert not centre, "two star loops in one cube case"
                centre = loop
                for a in range(len(loop)):
                    tris.append((loop[a], loop[(a + 1) % len(loop)], CENTRE))
                continue
            for a, b, c in _triangulate_loop(len(loop)):
                tris.append((loop[a], loop[b], loop[c]))
        tris_all.append(tris)
        centre_edges.append(centre)
    maxt = max(len(t) for t in tris_all)
    table = -np.ones((256, maxt, 3), dtype=np.int64)
    count = np.zeros(256, dtype=np.int64)
    centres = -np.ones((256, 12), dtype=np.int64)
    centre_count = np.zeros(256, dtype=np.int64)
    for case, tris in enumerate(tris_all):
        count[case] = len(tris)
        for t, tri in enumerate(tris):
            table[case, t] = tri
        centre_count[case] = len(centre_edges[case])
        centres[case, :len(centre_edges[case])] = centre_edges[case]
    return table, count, centres, centre_count


CUBE_TRIS, CUBE_COUNT, CUBE_CENTRE_EDGES, CUBE_CENTRE_COUNT = _build_cube_table()
