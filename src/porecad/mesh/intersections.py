"""Self-intersections of a triangle mesh: pairs of faces that cross other than along shared edges and vertices.

Triangle–triangle tests after Möller 1997 [1]_ with the orientation
predicates of Guigue & Devillers 2003 [2]_ for coplanar pairs (tolerances
relative to the mean edge), on candidate pairs from a uniform grid hashed into
a table (Teschner et al. 2003 [3]_), in parallel numba kernels.

References
----------
.. [1] T. Möller, "A fast triangle-triangle intersection test", Journal of
   Graphics Tools 2(2):25-30, 1997.
.. [2] P. Guigue, O. Devillers, "Fast and robust triangle-triangle overlap test
   using orientation predicates", Journal of Graphics Tools 8(1):25-32, 2003.
.. [3] M. Teschner et al., "Optimized spatial hashing for collision detection
   of deformable objects", VMV 2003 (uniform grid hashed into a table).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from porecad.errors import InputError
from porecad.mesh.arrays import as_mesh


# ---------------------------------------------------------------------------
# geometric predicates for self-intersection (points are 3-tuples)
# ---------------------------------------------------------------------------


@njit(cache=True, nogil=True, inline="always")
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, nogil=True, inline="always")
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True, inline="always")
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, nogil=True, inline="always")
def _pt(vertices, i):
    return (vertices[i, 0], vertices[i, 1], vertices[i, 2])


@njit(cache=True, nogil=True)
def _drop_axis(n):
    """Axis of the largest normal component: projecting it away keeps area."""
    ax, ay, az = abs(n[0]), abs(n[1]), abs(n[2])
    if ax >= ay and ax >= az:
        return 0
    if ay >= az:
        return 1
    return 2


@njit(cache=True, nogil=True, inline="always")
def _proj(p, k):
    if k == 0:
        return (p[1], p[2])
    if k == 1:
        return (p[2], p[0])
    return (p[0], p[1])


@njit(cache=True, nogil=True, inline="always")
def _orient2(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


@njit(cache=True, nogil=True)
def _on_segment2(a, b, p):
    """``p`` (known collinear with ``ab``) lies in the closed box of ``ab``."""
    return (min(a[0], b[0]) <= p[0] <= max(a[0], b[0])) and (min(a[1], b[1]) <= p[1] <= max(a[1], b[1]))


@njit(cache=True, nogil=True)
def _seg_seg2(a, b, c, d):
    """Closed 2D segments ``ab`` and ``cd`` intersect (orientation signs)."""
    d1 = _orient2(c, d, a)
    d2 = _orient2(c, d, b)
    d3 = _orient2(a, b, c)
    d4 = _orient2(a, b, d)
    if ((d1 > 0 and d2 < 0) or (d1 < 0 and d2 > 0)) and ((d3 > 0 and d4 < 0) or (d3 < 0 and d4 > 0)):
        return True
    if d1 == 0 and _on_segment2(c, d, a):
        return True
    if d2 == 0 and _on_segment2(c, d, b):
        return True
    if d3 == 0 and _on_segment2(a, b, c):
        return True
    if d4 == 0 and _on_segment2(a, b, d):
        return True
    return False


@njit(cache=True, nogil=True)
def _in_tri2(p, a, b, c):
    """``p`` in the closed 2D triangle ``abc`` (either winding)."""
    s1 = _orient2(a, b, p)
    s2 = _orient2(b, c, p)
    s3 = _orient2(c, a, p)
    return (s1 >= 0 and s2 >= 0 and s3 >= 0) or (s1 <= 0 and s2 <= 0 and s3 <= 0)


@njit(cache=True, nogil=True)
def _seg_tri2(x, y, a, b, c):
    if _in_tri2(x, a, b, c) or _in_tri2(y, a, b, c):
        return True
    return _seg_seg2(x, y, a, b) or _seg_seg2(x, y, b, c) or _seg_seg2(x, y, c, a)


@njit(cache=True, nogil=True)
def _tri_tri2(p0, p1, p2, q0, q1, q2):
    if _in_tri2(p0, q0, q1, q2) or _in_tri2(q0, p0, p1, p2):
        return True
    for e in range(3):
        if e == 0:
            a, b = p0, p1
        elif e == 1:
            a, b = p1, p2
        else:
            a, b = p2, p0
        if _seg_seg2(a, b, q0, q1) or _seg_seg2(a, b, q1, q2) or _seg_seg2(a, b, q2, q0):
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _snap(o, thr):
    return 0.0 if abs(o) <= thr else o


@njit(cache=True, nogil=True)
def _seg_tri(x, y, a, b, c, n, thr):
    """Closed segment ``xy`` meets closed triangle ``abc`` (normal ``n``).

    Endpoint heights ``n . (x - a)`` within ``thr`` of zero count as on the
    plane.  Both on the plane: 2D test in the projection dropping the largest
    normal component; one on it: that point in the triangle, in 2D.
    Otherwise the segment crosses the plane iff the heights
    differ in sign, and the crossing lies in the triangle iff the line
    orientations ``d . ((a - x) x (b - x))`` over the three edges agree in
    sign (Plücker-style side test, cf. [2]_).
    """
    ox = _snap(_dot(n, _sub(x, a)), thr)
    oy = _snap(_dot(n, _sub(y, a)), thr)
    if (ox > 0 and oy > 0) or (ox < 0 and oy < 0):
        return False
    if ox == 0 and oy == 0:
        k = _drop_axis(n)
        return _seg_tri2(_proj(x, k), _proj(y, k), _proj(a, k), _proj(b, k), _proj(c, k))
    if ox == 0 or oy == 0:
        # the segment meets the plane at an end point: test that point in 2D. (The line test
        # below is ill-conditioned there when the segment runs almost in the plane: MC contour
        # segments of neighbouring squares are nearly collinear and were falsely reported.)
        k = _drop_axis(n)
        return _in_tri2(_proj(x if ox == 0 else y, k), _proj(a, k), _proj(b, k), _proj(c, k))
    d = _sub(y, x)
    ax = _sub(a, x)
    bx = _sub(b, x)
    cx = _sub(c, x)
    s1 = _dot(d, _cross(ax, bx))
    s2 = _dot(d, _cross(bx, cx))
    s3 = _dot(d, _cross(cx, ax))
    return (s1 >= 0 and s2 >= 0 and s3 >= 0) or (s1 <= 0 and s2 <= 0 and s3 <= 0)


@njit(cache=True, nogil=True)
def _norm(a):
    return math.sqrt(_dot(a, a))


@njit(cache=True, nogil=True)
def _tri_tri(p0, p1, p2, q0, q1, q2, eps_len):
    """Closed triangles ``P`` and ``Q`` without shared vertices intersect.

    Möller's plane rejection ([1]_): if all vertices of one triangle lie
    strictly on one side of the other's plane there is no contact.  Coplanar
    pairs are tested in 2D.  Otherwise the intersection, if any, is a segment
    whose end points lie on the boundary of ``P`` or of ``Q``, so the pair
    intersects iff one of the six edges meets the other triangle.
    Heights below ``eps_len * |n|`` count as zero.
    """
    n1 = _cross(_sub(p1, p0), _sub(p2, p0))
    n2 = _cross(_sub(q1, q0), _sub(q2, q0))
    l1 = _norm(n1)
    l2 = _norm(n2)
    if l1 == 0.0 or l2 == 0.0:
        return False
    t1 = eps_len * l1
    t2 = eps_len * l2
    d0 = _snap(_dot(n1, _sub(q0, p0)), t1)
    d1 = _snap(_dot(n1, _sub(q1, p0)), t1)
    d2 = _snap(_dot(n1, _sub(q2, p0)), t1)
    if (d0 > 0 and d1 > 0 and d2 > 0) or (d0 < 0 and d1 < 0 and d2 < 0):
        return False
    e0 = _snap(_dot(n2, _sub(p0, q0)), t2)
    e1 = _snap(_dot(n2, _sub(p1, q0)), t2)
    e2 = _snap(_dot(n2, _sub(p2, q0)), t2)
    if (e0 > 0 and e1 > 0 and e2 > 0) or (e0 < 0 and e1 < 0 and e2 < 0):
        return False
    if d0 == 0 and d1 == 0 and d2 == 0:
        k = _drop_axis(n1)
        return _tri_tri2(_proj(p0, k), _proj(p1, k), _proj(p2, k), _proj(q0, k), _proj(q1, k), _proj(q2, k))
    return (
        _seg_tri(p0, p1, q0, q1, q2, n2, t2)
        or _seg_tri(p1, p2, q0, q1, q2, n2, t2)
        or _seg_tri(p2, p0, q0, q1, q2, n2, t2)
        or _seg_tri(q0, q1, p0, p1, p2, n1, t1)
        or _seg_tri(q1, q2, p0, p1, p2, n1, t1)
        or _seg_tri(q2, q0, p0, p1, p2, n1, t1)
    )


@njit(cache=True, nogil=True)
def _tri_tri_vertex(s, a, b, c, d, eps_len):
    """Triangles ``(s, a, b)`` and ``(s, c, d)`` sharing only vertex ``s``.

    ``P cap Q`` always contains ``s``.  On the line through ``s`` where the
    planes meet (or on any ray from ``s``, when coplanar) both triangles cover
    a segment starting at ``s`` and ending on the edge opposite ``s``; they
    overlap beyond ``s`` iff the shorter one's end lies in the other triangle.
    Hence: intersect iff edge ``ab`` meets ``Q`` or edge ``cd`` meets ``P``.
    """
    n1 = _cross(_sub(a, s), _sub(b, s))
    n2 = _cross(_sub(c, s), _sub(d, s))
    l1 = _norm(n1)
    l2 = _norm(n2)
    if l1 == 0.0 or l2 == 0.0:
        return False
    t1 = eps_len * l1
    t2 = eps_len * l2
    dc = _snap(_dot(n1, _sub(c, s)), t1)
    dd = _snap(_dot(n1, _sub(d, s)), t1)
    if (dc > 0 and dd > 0) or (dc < 0 and dd < 0):
        return False
    da = _snap(_dot(n2, _sub(a, s)), t2)
    db = _snap(_dot(n2, _sub(b, s)), t2)
    if (da > 0 and db > 0) or (da < 0 and db < 0):
        return False
    return _seg_tri(a, b, s, c, d, n2, t2) or _seg_tri(c, d, s, a, b, n1, t1)


@njit(cache=True, nogil=True)
def _tri_tri_edge(s, t, a, b, sin_fold):
    """Triangles ``(s, t, a)`` and ``(s, t, b)`` sharing edge ``st``.

    Non-coplanar planes meet only in the line ``st``, so such triangles touch
    only along the edge.  They overlap (a *fold*) iff ``a`` and ``b`` lie in
    the same half-plane of ``st``: the components ``u_a, u_b`` of ``a - s``,
    ``b - s`` normal to ``st`` point the same way (``u_a . u_b > 0``) and the
    opening angle between them is below ``asin(sin_fold)``.
    """
    e = _sub(t, s)
    ee = _dot(e, e)
    if ee == 0.0:
        return False
    va = _sub(a, s)
    vb = _sub(b, s)
    fa = _dot(va, e) / ee
    fb = _dot(vb, e) / ee
    ua = (va[0] - fa * e[0], va[1] - fa * e[1], va[2] - fa * e[2])
    ub = (vb[0] - fb * e[0], vb[1] - fb * e[1], vb[2] - fb * e[2])
    if _dot(ua, ub) <= 0.0:
        return False
    return _norm(_cross(ua, ub)) <= sin_fold * _norm(ua) * _norm(ub)


@njit(cache=True, nogil=True)
def _faces_intersect(vertices, faces, i, j, eps_len, sin_fold):
    a0, a1, a2 = faces[i, 0], faces[i, 1], faces[i, 2]
    b0, b1, b2 = faces[j, 0], faces[j, 1], faces[j, 2]
    if a0 == a1 or a1 == a2 or a2 == a0 or b0 == b1 or b1 == b2 or b2 == b0:
        return False  # index-degenerate faces are reported by edge_topology
    # which corners of face i are shared with face j
    m0 = a0 == b0 or a0 == b1 or a0 == b2
    m1 = a1 == b0 or a1 == b1 or a1 == b2
    m2 = a2 == b0 or a2 == b1 or a2 == b2
    shared = int(m0) + int(m1) + int(m2)
    if shared == 0:
        return _tri_tri(
            _pt(vertices, a0), _pt(vertices, a1), _pt(vertices, a2),
            _pt(vertices, b0), _pt(vertices, b1), _pt(vertices, b2), eps_len,
        )
    if shared == 3:
        return True  # duplicate face
    # rotate both faces so that shared corners come first
    if shared == 1:
        s = a0 if m0 else (a1 if m1 else a2)
        if s == a0:
            pa, pb = a1, a2
        elif s == a1:
            pa, pb = a2, a0
        else:
            pa, pb = a0, a1
        if s == b0:
            qc, qd = b1, b2
        elif s == b1:
            qc, qd = b2, b0
        else:
            qc, qd = b0, b1
        return _tri_tri_vertex(
            _pt(vertices, s), _pt(vertices, pa), _pt(vertices, pb),
            _pt(vertices, qc), _pt(vertices, qd), eps_len,
        )
    # shared == 2
    if not m0:
        s, t, a = a1, a2, a0
    elif not m1:
        s, t, a = a2, a0, a1
    else:
        s, t, a = a0, a1, a2
    b = b0 if (b0 != s and b0 != t) else (b1 if (b1 != s and b1 != t) else b2)
    return _tri_tri_edge(_pt(vertices, s), _pt(vertices, t), _pt(vertices, a), _pt(vertices, b), sin_fold)


# ---------------------------------------------------------------------------
# broad phase: uniform grid hashed into buckets
# ---------------------------------------------------------------------------

_HASH_MUL = np.uint64(0x9E3779B97F4A7C15)  # Knuth / Fibonacci hashing


@njit(cache=True, nogil=True)
def _face_boxes(vertices, faces):
    nf = faces.shape[0]
    lo = np.empty((nf, 3))
    hi = np.empty((nf, 3))
    edge_sum = 0.0
    for f in range(nf):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        for a in range(3):
            x, y, z = vertices[i, a], vertices[j, a], vertices[k, a]
            lo[f, a] = min(x, y, z)
            hi[f, a] = max(x, y, z)
        for p, q in ((i, j), (j, k), (k, i)):
            dx = vertices[p, 0] - vertices[q, 0]
            dy = vertices[p, 1] - vertices[q, 1]
            dz = vertices[p, 2] - vertices[q, 2]
            edge_sum += math.sqrt(dx * dx + dy * dy + dz * dz)
    return lo, hi, edge_sum / max(3 * nf, 1)


@njit(cache=True, nogil=True, inline="always")
def _bucket(key, shift):
    return np.int64((np.uint64(key) * _HASH_MUL) >> np.uint64(shift))


@njit(cache=True, nogil=True)
def _fill_buckets(clo, chi, nx, ny, n_entries, bits):
    """Counting sort of (face, cell) entries into ``2**bits`` hash buckets."""
    nb = np.int64(1) << bits
    shift = 64 - bits
    start = np.zeros(nb + 1, np.int64)
    nf = clo.shape[0]
    for f in range(nf):
        for iz in range(clo[f, 2], chi[f, 2] + 1):
            for iy in range(clo[f, 1], chi[f, 1] + 1):
                for ix in range(clo[f, 0], chi[f, 0] + 1):
                    key = ix + nx * (iy + ny * iz)
                    start[_bucket(key, shift) + 1] += 1
    for b in range(nb):
        start[b + 1] += start[b]
    pos = start[:-1].copy()
    ent_face = np.empty(n_entries, np.int32)
    ent_key = np.empty(n_entries, np.int64)
    for f in range(nf):
        for iz in range(clo[f, 2], chi[f, 2] + 1):
            for iy in range(clo[f, 1], chi[f, 1] + 1):
                for ix in range(clo[f, 0], chi[f, 0] + 1):
                    key = ix + nx * (iy + ny * iz)
                    b = _bucket(key, shift)
                    ent_face[pos[b]] = f
                    ent_key[pos[b]] = key
                    pos[b] += 1
    return start, ent_face, ent_key


@njit(cache=True, nogil=True, parallel=True)
def _pair_pass(vertices, faces, lo, hi, clo, start, ent_face, ent_key, nx, ny,
               eps, sin_fold, n_chunks, chunk_count, out, out_offset, write):
    """Narrow phase over all candidate pairs, one hash-bucket chunk per task.

    A pair is considered only in the cell holding the minimum corner of the
    intersection of the two boxes (``max`` of their lower cell indices), so
    each pair is tested once however many cells the two faces share.
    With ``write`` False, counts hits per chunk into ``chunk_count``; with
    ``write`` True, writes the hits of chunk ``c`` to ``out`` from row
    ``out_offset[c]`` on, stopping at ``len(out)``.
    """
    nb = start.shape[0] - 1
    per = (nb + n_chunks - 1) // n_chunks
    cap = out.shape[0]
    for c in prange(n_chunks):
        row = out_offset[c] if write else 0
        hits = 0
        b_beg = c * per
        b_end = min(nb, (c + 1) * per)
        if write and (chunk_count[c] == 0 or row >= cap):
            b_end = b_beg  # nothing to write for this chunk
        for bkt in range(b_beg, b_end):
            s = start[bkt]
            e = start[bkt + 1]
            for p in range(s, e):
                i = ent_face[p]
                key = ent_key[p]
                for q in range(p + 1, e):
                    if ent_key[q] != key:
                        continue
                    j = ent_face[q]
                    if (lo[i, 0] > hi[j, 0] or lo[j, 0] > hi[i, 0]
                            or lo[i, 1] > hi[j, 1] or lo[j, 1] > hi[i, 1]
                            or lo[i, 2] > hi[j, 2] or lo[j, 2] > hi[i, 2]):
                        continue
                    cx = max(clo[i, 0], clo[j, 0])
                    cy = max(clo[i, 1], clo[j, 1])
                    cz = max(clo[i, 2], clo[j, 2])
                    if cx + nx * (cy + ny * cz) != key:
                        continue
                    span = 0.0
                    for a in range(3):
                        span = max(span, max(hi[i, a], hi[j, a]) - min(lo[i, a], lo[j, a]))
                    if _faces_intersect(vertices, faces, i, j, eps * span, sin_fold):
                        if write:
                            if row < cap:
                                out[row, 0] = min(i, j)
                                out[row, 1] = max(i, j)
                            row += 1
                        hits += 1
        if not write:
            chunk_count[c] = hits


@njit(cache=True, nogil=True)
def _cell_ranges(lo, hi, origin, h, clo, chi):
    """Integer cell range of every face box; returns the number of entries."""
    inv = 1.0 / h
    total = 0
    for f in range(lo.shape[0]):
        m = 1
        for a in range(3):
            c0 = np.int64(math.floor((lo[f, a] - origin[a]) * inv))
            c1 = np.int64(math.floor((hi[f, a] - origin[a]) * inv))
            clo[f, a] = c0
            chi[f, a] = c1
            m *= c1 - c0 + 1
        total += m
    return total


def _grid(lo, hi, mean_edge, cell_factor, max_entries):
    """Pick the cell size and the integer cell ranges of every face box.

    Starts from ``cell_factor * mean_edge`` and grows by 1.5x until the total
    number of (face, cell) entries is at most ``max_entries`` and the grid has
    fewer than ``2**20`` cells per axis (keys fit in int64).
    """
    origin = lo.min(axis=0)
    extent = float((hi.max(axis=0) - origin).max())
    h = cell_factor * mean_edge
    if not h > 0:
        h = extent if extent > 0 else 1.0
    h = max(h, extent / (2**20 - 2))
    clo = np.empty(lo.shape, np.int64)
    chi = np.empty(lo.shape, np.int64)
    while True:
        n_entries = _cell_ranges(lo, hi, origin, h, clo, chi)
        if n_entries <= max_entries:
            dims = chi.max(axis=0) + 1
            return clo, chi, dims, n_entries
        h *= 1.5


#: most candidate face pairs the broad phase may hand to the narrow phase (about a minute of tests)
MAX_PAIR_TESTS = 2_000_000_000


def check_pair_work(bucket_sizes) -> None:
    """Refuse, before testing, a search whose buckets hold too many face pairs (faces piled in one place).

    A mesh of 200,000 copies of one face puts them all in one cell: 2e10 pair
    tests, hours of work. Well-shaped meshes have a few faces per cell.
    """
    n = np.asarray(bucket_sizes, dtype=np.float64)
    pairs = float(np.sum(n * (n - 1) / 2))
    if pairs > MAX_PAIR_TESTS:
        from ..errors import ResourceError
        raise ResourceError(f"the self-intersection search would test {pairs:.3g} face pairs (at most "
                            f"{MAX_PAIR_TESTS:.3g}): many faces lie on top of each other (repeated faces?)")


def _broad_phase(v, f, cell_factor, max_entries_per_face):
    """The broad phase of :func:`self_intersections` on the checked mesh (two faces or more): face boxes
    bucketed by hashed grid cell, ``(lo, hi, clo, dims, start, ent_face, ent_key)``; raises when the pair
    work is too large (:func:`check_pair_work`)."""
    lo, hi, mean_edge = _face_boxes(v, f)
    max_entries = max(int(max_entries_per_face) * len(f), 1 << 16)
    clo, chi, dims, n_entries = _grid(lo, hi, mean_edge, cell_factor, max_entries)
    bits = max(4, int(math.ceil(math.log2(max(n_entries, 2)))) - 1)
    start, ent_face, ent_key = _fill_buckets(clo, chi, np.int64(dims[0]), np.int64(dims[1]), n_entries, bits)
    check_pair_work(np.diff(start))
    return lo, hi, clo, dims, start, ent_face, ent_key


def _narrow_phase(v, f, broad, eps, fold_angle, max_report: int):
    """The narrow phase on the buckets ``broad`` of :func:`_broad_phase`: ``(pairs (K, 2) sorted, total)``;
    a parallel pass counts, a second lists at most ``max_report`` pairs."""
    lo, hi, clo, dims, start, ent_face, ent_key = broad
    n_chunks = int(min(len(start) - 1, 4096))
    chunk_count = np.zeros(n_chunks, np.int64)
    offsets = np.zeros(n_chunks, np.int64)
    sin_fold = math.sin(math.radians(fold_angle))
    args = (v, f, lo, hi, clo, start, ent_face, ent_key, np.int64(dims[0]), np.int64(dims[1]),
            float(eps), sin_fold, n_chunks)
    _pair_pass(*args, chunk_count, np.zeros((0, 2), np.int64), offsets, False)
    total = int(chunk_count.sum())
    if total == 0 or max_report == 0:
        return np.zeros((0, 2), np.int64), total
    offsets[1:] = np.cumsum(chunk_count)[:-1]
    out = np.empty((min(total, max_report), 2), np.int64)
    _pair_pass(*args, chunk_count, out, offsets, True)
    out = out[np.lexsort((out[:, 1], out[:, 0]))]
    return out, total


def self_intersections(vertices, faces, max_report=1000, *, eps=1e-10, fold_angle=1e-6,
                       cell_factor=2.0, max_entries_per_face=8):
    """Pairs of faces that intersect other than along shared edges/vertices.

    Broad phase: the axis-aligned box of every face is rasterised into a
    uniform grid of cell size ``h = cell_factor x mean edge length`` (grown
    while the number of face/cell entries exceeds ``max_entries_per_face x
    F``, which bounds memory), and the entries are bucketed by a hash of the
    cell index ([4]_).  Faces in the same cell whose boxes overlap are
    candidates, each tested once.

    Narrow phase, by the number of shared vertex indices, in float64:

    * none: Möller's plane rejection, then edge/triangle tests, coplanar
      pairs in 2D ([1]_, [2]_);
    * one (``s``): intersect iff the edge opposite ``s`` of either face meets
      the other face (anything but ``s`` in common);
    * two (an edge): intersect iff folded, i.e. coplanar within
      ``fold_angle`` degrees with the third vertices on the same side;
    * three: a duplicated face, always reported.

    Contacts count as intersections: heights within ``eps x box size`` of a
    face plane are taken as on the plane.  Faces with a repeated vertex index
    or zero area are skipped (``edge_topology`` reports the former).

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
    max_report : int
        Return at most this many pairs; the count is always complete.
    eps : float
        Relative coplanarity tolerance.
    fold_angle : float
        Largest opening angle (degrees) of two faces sharing an edge that is
        reported as a fold.
    cell_factor : float
        Initial cell size in mean edge lengths.
    max_entries_per_face : int
        Memory bound of the broad phase.

    Returns
    -------
    pairs : (K, 2) int64 array
        Intersecting face pairs ``(i, j)``, ``i < j``, sorted, ``K <=
        max_report``.
    count : int
        Total number of intersecting pairs.

    Notes
    -----
    Parallel over hash buckets with numba threads; about 1 s per million faces
    on two cores for well-shaped meshes.  Meshes whose faces differ wildly in
    size (a few huge faces among many small ones) force large cells and run
    slower.
    """
    v, f = as_mesh(vertices, faces)
    max_report = int(max_report)
    if max_report < 0:
        raise InputError("max_report must be >= 0")
    if len(f) < 2:
        return np.zeros((0, 2), np.int64), 0
    broad = _broad_phase(v, f, cell_factor, max_entries_per_face)
    return _narrow_phase(v, f, broad, eps, fold_angle, max_report)
