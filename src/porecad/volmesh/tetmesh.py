"""Tetrahedral meshes as plain arrays: validation, adjacency, colouring, quality.

A tet mesh is ``points`` of shape ``(V, 3)`` (float64, millimetres) and
``tets`` of shape ``(T, 4)`` (int64 vertex indices). A tet ``(p0, p1, p2, p3)``
is *positively oriented* when its signed volume

.. math:: V = \\frac{1}{6} \\det\\,[\\,p_1 - p_0,\\; p_2 - p_0,\\; p_3 - p_0\\,]

is positive, i.e. ``p3`` lies on the side of triangle ``(p0, p1, p2)`` that
its right-hand normal points to. Every function here that returns tets
returns them positively oriented; :func:`check_tet_mesh` is the gate for tets
from elsewhere (it flips an all-negative mesh and refuses a mixed one).

Local faces follow one convention throughout: local face ``k`` is the face
opposite local vertex ``k``, with the vertex order of :data:`FACE_LOCAL`, so
that for a positive tet its right-hand normal points *out* of the tet.

Public functions
----------------
check_tet_mesh
    Shapes, finite coordinates, index range, repeated vertices, degenerate
    and inverted tets, non-conforming faces and boundary edges.
signed_volumes, face_adjacency, boundary_faces
    Per-tet volumes, the tet across each face, the outward boundary surface.
rainbow_coloring
    A 4-colouring of the vertices in which every tet has all four colours
    (needed by the asymmetric TIS-G function), or None.
tet_quality
    Volumes, dihedral angles, radius and aspect ratios, edge lengths.
as_points, as_tets
    The checked input arrays.

Point location (:class:`TetLocator`, ``locate_points``) is in
:mod:`porecad.volmesh.tetlocate`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from porecad.errors import InputError

__all__ = [
    "FACE_LOCAL",
    "check_tet_mesh",
    "signed_volumes",
    "face_adjacency",
    "boundary_faces",
    "rainbow_coloring",
    "tet_quality",
    "as_points",
    "as_tets",
]

#: Local vertex indices of face ``k`` (the face opposite local vertex ``k``),
#: ordered so that the right-hand normal points out of a positively oriented tet:
#: e.g. for ``k = 3``, ``(p2 - p0) x (p1 - p0) . (p3 - p0) = -6 V < 0``.
FACE_LOCAL = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)

#: The six edges of a tet as local vertex pairs, and for each edge the two
#: local faces that meet along it (the faces opposite the two other vertices).
_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
_EDGE_FACES = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]], dtype=np.int64)


# ---------------------------------------------------------------------------
# input checking
# ---------------------------------------------------------------------------


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def as_points(points) -> np.ndarray:
    """``points`` checked to be a numeric ``(V, 3)`` array, as C-contiguous float64 (InputError otherwise)."""
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (V, 3), got {p.shape}")
    if not (np.issubdtype(p.dtype, np.floating) or np.issubdtype(p.dtype, np.integer)):
        raise InputError(f"points must be numeric, got dtype {p.dtype}")
    return np.ascontiguousarray(p, dtype=np.float64)


def as_tets(tets, n_points: int | None = None) -> np.ndarray:
    """``tets`` checked to be an integer ``(T, 4)`` array, as C-contiguous int64 (InputError otherwise).

    With ``n_points`` every index must lie in ``0 .. n_points-1``, else in
    ``0`` or more; the error names the first tet and vertex out of range.
    """
    t = np.asarray(tets)
    if t.ndim != 2 or t.shape[1] != 4:
        raise InputError(f"tets must have shape (T, 4), got {t.shape}")
    if t.size and not np.issubdtype(t.dtype, np.integer):
        raise InputError(f"tets must be integer vertex indices, got dtype {t.dtype}")
    t = np.ascontiguousarray(t, dtype=np.int64)
    if t.size:
        bad = (t < 0).any(axis=1)
        if n_points is not None:
            bad |= (t >= n_points).any(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            row = t[i]
            out = row < 0
            if n_points is not None:
                out |= row >= n_points
            v = int(row[out][0])
            limit = f"0..{n_points - 1}" if n_points is not None else "0 or more"
            raise InputError(f"tet {i} references vertex {v}, outside {limit} "
                             f"(vertices {', '.join(map(str, row))})")
    return t


def row_groups(rows: np.ndarray, n: int):
    """Sort integer rows and mark runs of equal rows.

    Parameters
    ----------
    rows : (M, m) int64 array with entries in ``0 .. n-1``
    n : int

    Returns
    -------
    order : (M,) int64
        Permutation sorting the rows lexicographically.
    first : (M,) bool
        ``first[i]`` is True where sorted row ``i`` differs from row ``i-1``.
    """
    m = rows.shape[1]
    M = rows.shape[0]
    if M == 0:
        return np.zeros(0, np.int64), np.zeros(0, bool)
    if float(max(n, 1)) ** m < 2.0**62:
        key = rows[:, 0].astype(np.int64)
        for j in range(1, m):
            key = key * np.int64(n) + rows[:, j]
        order = np.argsort(key, kind="stable")
        ks = key[order]
        first = np.empty(M, bool)
        first[0] = True
        np.not_equal(ks[1:], ks[:-1], out=first[1:])
    else:  # keys would overflow int64: sort the columns directly
        order = np.lexsort(rows.T[::-1])
        rs = rows[order]
        first = np.empty(M, bool)
        first[0] = True
        first[1:] = np.any(rs[1:] != rs[:-1], axis=1)
    return order, first


def _sorted_faces(tets: np.ndarray) -> np.ndarray:
    """All ``4 T`` faces as sorted vertex triples; face ``4 t + k`` is opposite local vertex ``k`` of ``t``."""
    f = tets[:, FACE_LOCAL].reshape(-1, 3)
    return np.sort(f, axis=1)


def face_groups(tets: np.ndarray, n_vertices: int):
    """Group equal faces: returns sorted triples, order, group id per sorted face and group sizes."""
    faces = _sorted_faces(tets)
    order, first = row_groups(faces, n_vertices)
    gid = np.cumsum(first) - 1
    sizes = np.bincount(gid)
    return faces, order, gid, sizes


def _raise_overshared(faces, order, gid, sizes):
    g = int(np.argmax(sizes > 2))
    members = np.sort(order[gid == g] // 4)
    a, b, c = faces[order[np.argmax(gid == g)]]
    raise InputError(
        f"tet mesh is not conforming: face ({a}, {b}, {c}) is shared by {len(members)} tets "
        f"({', '.join(map(str, members[:8]))}{', ...' if len(members) > 8 else ''})")


def bad_boundary_edges(faces, order, gid, sizes, n_vertices: int):
    """Boundary edges not in exactly two boundary faces (from :func:`face_groups`).

    Returns the edges ``(E, 2)`` (sorted pairs, in lexicographic order), their
    boundary-face counts and one tet owning such a face, for each.
    """
    none = np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    once = sizes[gid] == 1  # per sorted position
    bf_ids = order[once]  # face ids 4 t + k of the boundary faces
    if len(bf_ids) == 0:
        return none
    bf = faces[bf_ids]
    edges = np.concatenate([bf[:, [0, 1]], bf[:, [1, 2]], bf[:, [0, 2]]])  # sorted pairs
    e_owner = np.concatenate([bf_ids, bf_ids, bf_ids]) // 4
    eorder, efirst = row_groups(edges, n_vertices)
    egid = np.cumsum(efirst) - 1
    ecount = np.bincount(egid, minlength=1)
    bad = np.flatnonzero(ecount != 2)
    if len(bad) == 0:
        return none
    pos = np.flatnonzero(efirst)[bad]  # first sorted position of each bad group
    return edges[eorder[pos]], ecount[bad], e_owner[eorder[pos]]


def signed_volumes(points, tets) -> np.ndarray:
    """Signed volume of every tet, ``det[p1 - p0, p2 - p0, p3 - p0] / 6`` (mm³).

    Parameters
    ----------
    points : (V, 3) float array
    tets : (T, 4) int array

    Returns
    -------
    (T,) float64
        Positive for positively oriented tets.
    """
    p = as_points(points)
    t = as_tets(tets, len(p))
    q = p[t]
    a, b, c = (q[:, k] - q[:, 0] for k in (1, 2, 3))
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


def _edge_lengths(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(T, 6)``: the lengths of the six edges of every tet (:data:`_EDGES`)."""
    e = p[t[:, _EDGES[:, 1]]] - p[t[:, _EDGES[:, 0]]]
    return np.sqrt(np.einsum("ijk,ijk->ij", e, e))


def _checked_arrays(points, tets):
    """Checks 1-2 of :func:`check_tet_mesh`: returns ``(points (V, 3) float64, tets (T, 4) int64)``.

    Takes the raw ``points`` and ``tets``; raises InputError for a wrong
    shape or type, no tets, a non-finite point, an index out of range or a
    tet that repeats a vertex.
    """
    p = as_points(points)
    t = as_tets(tets)
    if len(t) == 0:
        raise InputError("tet mesh has no tetrahedra")
    finite = np.isfinite(p).all(axis=1)
    if not finite.all():
        i = int(np.argmin(finite))
        raise InputError(f"point {i} has a non-finite coordinate ({', '.join(map(str, p[i]))})")
    t = as_tets(t, len(p))
    rep = ((t[:, 0] == t[:, 1]) | (t[:, 0] == t[:, 2]) | (t[:, 0] == t[:, 3])
           | (t[:, 1] == t[:, 2]) | (t[:, 1] == t[:, 3]) | (t[:, 2] == t[:, 3]))
    if rep.any():
        i = int(np.argmax(rep))
        raise InputError(f"tet {i} repeats a vertex (vertices {', '.join(map(str, t[i]))})")
    return p, t


def _oriented(p: np.ndarray, t: np.ndarray, rel_tol: float) -> np.ndarray:
    """Checks 3-4 of :func:`check_tet_mesh`: the checked tets, flipped when all are negative.

    Takes the arrays from :func:`_checked_arrays` and the degeneracy
    tolerance; returns ``tets (T, 4) int64``, positively oriented. Raises
    InputError naming the first degenerate tet, or the first inverted one.
    """
    vol = signed_volumes(p, t)
    l_mean = float(_edge_lengths(p, t).mean())
    eps = float(rel_tol) * l_mean**3
    flat = np.abs(vol) <= eps
    if flat.any():
        i = int(np.argmax(flat))
        raise InputError(f"tet {i} is degenerate (signed volume {_fmt(vol[i])} mm³, at most "
                         f"{rel_tol:g} x mean edge³ = {_fmt(eps)} mm³; "
                         f"vertices {', '.join(map(str, t[i]))})")
    neg = vol < 0
    n_neg = int(neg.sum())
    if n_neg == len(t):
        t = np.ascontiguousarray(t[:, [0, 1, 3, 2]])
    elif n_neg:
        minority = neg if n_neg <= len(t) - n_neg else ~neg
        i = int(np.argmax(minority))
        if neg[i]:
            raise InputError(f"tet {i} is inverted (signed volume {_fmt(vol[i])} mm³; "
                             f"vertices {', '.join(map(str, t[i]))})")
        raise InputError(f"tet {i} is inverted (signed volume {_fmt(vol[i])} mm³ while {n_neg} of "
                         f"{len(t)} tets are negative; vertices {', '.join(map(str, t[i]))})")
    return t


def _require_conforming(t: np.ndarray, n_points: int) -> None:
    """Check 5 of :func:`check_tet_mesh` on tets ``t`` over ``n_points`` points; returns None.

    Raises InputError naming a face in more than two tets, or a boundary edge
    not in exactly two boundary faces (with a tet near it).
    """
    faces, order, gid, sizes = face_groups(t, n_points)
    if (sizes > 2).any():
        _raise_overshared(faces, order, gid, sizes)
    edges, counts, owners = bad_boundary_edges(faces, order, gid, sizes, n_points)
    if len(edges):
        a, b = edges[0]
        raise InputError(
            f"tet mesh is not conforming: boundary edge ({a}, {b}) is used by {int(counts[0])} "
            f"boundary face(s) (hanging node or gap near tet {int(owners[0])})")


def check_tet_mesh(points, tets, rel_tol: float = 1e-9):
    """Validate a tetrahedral mesh and return it positively oriented.

    Checks, in order (the first failure raises):

    1. ``points`` is ``(V, 3)`` numeric and finite, ``tets`` is ``(T, 4)``
       integer with ``T >= 1`` and every index in ``0 .. V-1``;
    2. no tet repeats a vertex;
    3. no tet is degenerate: ``|vol| > rel_tol * l_mean**3`` with ``vol`` the
       signed volume (module docstring) and ``l_mean`` the mean edge length;
    4. orientation: if every tet is negative the mesh is flipped (columns 2
       and 3 swapped); if the signs are mixed, the first tet of the minority
       sign is reported as inverted (ties count the negative tets as inverted);
    5. conformity: no face (sorted vertex triple) belongs to more than two
       tets, and the boundary faces (those used once) form a closed
       edge-manifold surface: every boundary edge lies in exactly two boundary
       faces. Each tet puts every one of its edges in two of its faces, and an
       interior face takes two of those incidences away, so a boundary edge
       always has an even count; 4 or more means a hanging node (a face or
       edge split on one side only), or tets touching along an edge only.

    Parameters
    ----------
    points : (V, 3) array_like of float
        Vertex coordinates, mm. Points used by no tet are allowed.
    tets : (T, 4) array_like of int
        Vertex indices per tet.
    rel_tol : float
        Degeneracy tolerance relative to the cube of the mean edge length.

    Returns
    -------
    points : (V, 3) float64, C-contiguous
    tets : (T, 4) int64, C-contiguous, positively oriented

    Raises
    ------
    InputError
        With a one-line message naming the offending point, tet, face or edge,
        e.g. ``"tet 17 is inverted (signed volume -0.0031 mm³; vertices 3, 5, 9, 12)"``.
    """
    p, t = _checked_arrays(points, tets)
    t = _oriented(p, t, rel_tol)
    _require_conforming(t, len(p))
    return p, t


# ---------------------------------------------------------------------------
# adjacency
# ---------------------------------------------------------------------------


def face_adjacency(tets) -> np.ndarray:
    """The tet across each face.

    Parameters
    ----------
    tets : (T, 4) int array

    Returns
    -------
    neighbours : (T, 4) int64
        ``neighbours[t, k]`` is the tet sharing the face opposite local vertex
        ``k`` of tet ``t``, or ``-1`` where that face is on the boundary.

    Raises
    ------
    InputError
        If a face is shared by more than two tets.
    """
    t = as_tets(tets)
    nt = len(t)
    nb = np.full((nt, 4), -1, np.int64)
    if nt == 0:
        return nb
    faces, order, gid, sizes = face_groups(t, int(t.max()) + 1)
    if (sizes > 2).any():
        _raise_overshared(faces, order, gid, sizes)
    s = sizes[gid]
    # a pair occupies consecutive sorted positions i, i + 1
    i = np.flatnonzero((s == 2)[:-1] & (gid[1:] == gid[:-1]))
    f1, f2 = order[i], order[i + 1]
    nb.reshape(-1)[f1] = f2 // 4
    nb.reshape(-1)[f2] = f1 // 4
    return nb


def boundary_faces(tets):
    """The boundary surface of a tet mesh: faces that belong to one tet only.

    Parameters
    ----------
    tets : (T, 4) int array
        Positively oriented tets (as returned by :func:`check_tet_mesh`).

    Returns
    -------
    faces : (F, 3) int64
        Boundary triangles, ordered so that the right-hand normal points out
        of the owning tet (out of the mesh): local face ``k`` of tet ``t`` is
        ``tets[t, FACE_LOCAL[k]]``. In order of (owner, local).
    owner : (F,) int64
        The tet each face belongs to.
    local : (F,) int64
        The local vertex index (0..3) of ``owner`` opposite the face.
    """
    t = as_tets(tets)
    nb = face_adjacency(t)
    owner, local = np.nonzero(nb < 0)
    owner = owner.astype(np.int64)
    local = local.astype(np.int64)
    faces = t[owner[:, None], FACE_LOCAL[local]]
    return np.ascontiguousarray(faces), owner, local


# ---------------------------------------------------------------------------
# rainbow colouring
# ---------------------------------------------------------------------------


@njit(cache=True)
def _rainbow(tets, nbr, n_vertices):
    """BFS colouring; returns (colours, ok)."""
    nt = tets.shape[0]
    color = np.full(n_vertices, -1, np.int8)
    seen = np.zeros(nt, np.bool_)
    queue = np.empty(nt, np.int64)
    used = np.zeros(4, np.bool_)
    for seed in range(nt):
        if seen[seed]:
            continue
        # a new face-connected component; its vertices may already carry
        # colours where it touches an earlier component at an edge or vertex
        used[:] = False
        for j in range(4):
            c = color[tets[seed, j]]
            if c >= 0:
                if used[c]:
                    return color, False
                used[c] = True
        nxt = 0
        for j in range(4):
            v = tets[seed, j]
            if color[v] < 0:
                while used[nxt]:
                    nxt += 1
                color[v] = nxt
                used[nxt] = True
        seen[seed] = True
        head = 0
        tail = 1
        queue[0] = seed
        while head < tail:
            t = queue[head]
            head += 1
            for k in range(4):
                u = nbr[t, k]
                if u < 0:
                    continue
                want = color[tets[t, k]]  # the colour missing from the shared face
                for j in range(4):
                    w = tets[u, j]
                    if w != tets[t, 0] and w != tets[t, 1] and w != tets[t, 2] and w != tets[t, 3]:
                        if color[w] < 0:
                            color[w] = want
                        elif color[w] != want:
                            return color, False
                if not seen[u]:
                    seen[u] = True
                    queue[tail] = u
                    tail += 1
    return color, True


def rainbow_coloring(tets):
    """A 4-colouring of the vertices in which every tet has four different colours.

    Why: the cyclic TIS-G function (002 §3.2, 000 §4.2) is not symmetric in
    the four barycentric slots of a tet, so two tets sharing a face agree on it
    only if they feed the shared vertices into the same slots. If the vertices
    can be coloured 0..3 so that every tet holds each colour once (a
    "balanced" or foldable tet mesh), every tet can put the vertex of colour
    ``c`` into slot ``c``, and G is C⁰ across every face. BCC lattice meshes
    always have such a colouring (corner/centre x parity of ``i + j + k``, see
    :func:`porecad.volmesh.bcc.bcc_tet_mesh`); the 20-tet icosahedron has none,
    because its 12 outer vertices would need 3 colours and the icosahedron
    graph has chromatic number 4.

    Algorithm: breadth-first search over face adjacency. Colouring one tet
    ``0..3`` forces the colour of the fourth vertex of every face neighbour
    (the colour missing from the shared face); a vertex forced to two colours
    means no colouring exists. The colouring of a face-connected component is
    therefore unique up to a permutation of the colours. Components are
    seeded in tet order; components that touch only at edges or vertices are
    coloured greedily, so for such meshes ``None`` may occasionally be
    returned although a colouring exists.

    Parameters
    ----------
    tets : (T, 4) int array

    Returns
    -------
    colors : (V,) int8 or None
        ``V = tets.max() + 1``; the colour of each vertex (``-1`` for vertices
        in no tet), or None if the mesh cannot be coloured this way.
    """
    t = as_tets(tets)
    if len(t) == 0:
        return np.zeros(0, np.int8)
    nbr = face_adjacency(t)
    color, ok = _rainbow(t, nbr, int(t.max()) + 1)
    return color if ok else None


# ---------------------------------------------------------------------------
# quality
# ---------------------------------------------------------------------------


def _quality_arrays(p: np.ndarray, t: np.ndarray):
    """Per-tet signed volume, 6 dihedral angles (rad), radius ratio, 6 edge lengths and inradius."""
    q = p[t]
    a, b, c = (q[:, k] - q[:, 0] for k in (1, 2, 3))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    # outward area vectors of the four faces (for a positive tet)
    fq = q[:, FACE_LOCAL]  # (T, 4, 3 corners, 3)
    n = 0.5 * np.cross(fq[:, :, 1] - fq[:, :, 0], fq[:, :, 2] - fq[:, :, 0])
    area = np.linalg.norm(n, axis=2)  # (T, 4)
    i, j = _EDGE_FACES.T
    with np.errstate(invalid="ignore", divide="ignore"):
        cosang = np.einsum("ijk,ijk->ij", n[:, i], n[:, j]) / (area[:, i] * area[:, j])
        dihedral = np.pi - np.arccos(np.clip(cosang, -1.0, 1.0))
        # circumcentre offset (|a|² b×c + |b|² c×a + |c|² a×b) / (2 det); R = its norm
        num = (np.einsum("ij,ij->i", a, a)[:, None] * np.cross(b, c)
               + np.einsum("ij,ij->i", b, b)[:, None] * np.cross(c, a)
               + np.einsum("ij,ij->i", c, c)[:, None] * np.cross(a, b))
        # r = 3 |V| / A = |det| / (2 A);  R = |num| / (2 |det|);  3 r / R = 3 det² / (A |num|)
        ratio = 3.0 * det * det / (area.sum(axis=1) * np.linalg.norm(num, axis=1))
        r_in = np.abs(det) / (2.0 * area.sum(axis=1))
    return det / 6.0, dihedral, np.nan_to_num(ratio, nan=0.0), _edge_lengths(p, t), r_in


#: Histogram bin edges (degrees) of the dihedral angle distribution in :func:`tet_quality`.
DIHEDRAL_BINS = [0, 5, 10, 15, 20, 30, 40, 60, 90, 120, 150, 165, 170, 175, 180]


def tet_quality(points, tets) -> dict:
    """Quality report of a tet mesh (the corner nodes of a quadratic one), vectorised numpy.

    Dihedral angle along an edge: ``pi`` minus the angle between the outward
    normals of the two faces meeting there. Radius ratio ``3 r / R`` with
    inradius ``r = 3 |V| / A`` (``A`` the total face area) and circumradius
    ``R = |\\,|a|^2\\, b \\times c + |b|^2\\, c \\times a + |c|^2\\, a \\times b\\,| / (12 |V|)``
    (``a, b, c`` the edge vectors from ``p0``); 1 for the regular tet, 0 for
    a flat one. Aspect ratio: the longest edge over ``2 √6 r`` (1 for the regular tet, unbounded for slivers
    and needles). The regular tet has all dihedral angles ``arccos(1/3) = 70.53°``; BCC lattice tets have
    60° and 90° (Shewchuk, "What is a good linear finite element?", 2002, §6; Liu & Joe, *BIT* 34 (1994) 268).

    Parameters
    ----------
    points : (V, 3) float array
    tets : (T, 4) int array

    Returns
    -------
    dict
        ``tets``, ``vertices`` = ``nodes`` (distinct vertices used), ``volume_total`` = ``volume``,
        ``volume_min``, ``volume_max`` (signed, mm³), ``inverted`` (tets with volume ≤ 0),
        ``dihedral_min_deg``, ``dihedral_max_deg``, ``radius_ratio_min``, ``radius_ratio_mean``,
        ``edge_length_mean`` (mm); ``dihedral_deg`` {min, max, p01, p1, p5 (of each tet's smallest), median,
        histogram {edges, counts}} (an angle at a zero-area face counts as 180°), ``radius_ratio`` {min, p1,
        mean}, ``aspect_ratio`` {max, p99, mean (of the finite)}, ``below_5deg`` (tets with a dihedral angle
        under 5°); all plain Python numbers.
    """
    p = as_points(points)
    t = as_tets(tets, len(p))
    if len(t) == 0:
        raise InputError("tet mesh has no tetrahedra")
    vol, dihedral, ratio, edge, r_in = _quality_arrays(p, t)
    dih = np.degrees(np.nan_to_num(dihedral, nan=np.pi))
    dmin = dih.min(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect = np.nan_to_num(edge.max(axis=1) / (2 * np.sqrt(6) * r_in), nan=np.inf, posinf=np.inf)
    nodes, total = int(len(np.unique(t))), float(vol.sum())
    return {
        "tets": int(len(t)), "vertices": nodes, "nodes": nodes, "volume_total": total, "volume": total,
        "volume_min": float(vol.min()), "volume_max": float(vol.max()), "inverted": int((vol <= 0).sum()),
        "dihedral_min_deg": float(np.degrees(np.nanmin(dihedral))),
        "dihedral_max_deg": float(np.degrees(np.nanmax(dihedral))), "radius_ratio_min": float(ratio.min()),
        "radius_ratio_mean": float(ratio.mean()), "edge_length_mean": float(edge.mean()),
        "dihedral_deg": {"min": float(dih.min()), "max": float(dih.max()), "p01": float(np.percentile(dmin, 0.1)),
                         "p1": float(np.percentile(dmin, 1)), "p5": float(np.percentile(dmin, 5)),
                         "median": float(np.median(dih)), "histogram": {
                             "edges": DIHEDRAL_BINS, "counts": np.histogram(dih, bins=DIHEDRAL_BINS)[0].tolist()}},
        "radius_ratio": {"min": float(ratio.min()), "p1": float(np.percentile(ratio, 1)), "mean": float(ratio.mean())},
        "aspect_ratio": {"max": float(aspect.max()), "p99": float(np.percentile(aspect, 99)),
                         "mean": float(aspect[np.isfinite(aspect)].mean())},
        "below_5deg": int((dmin < 5).sum()),
    }
