"""Numba kernel: marching cubes over one z-slab of samples, with box caps.

The kernel walks the slab layer by layer with rolling per-plane arrays (memory
O(nx * ny), not O(slab)). Per plane it computes the inside bits and the
4-bit square case of every face cell with branch-free loops that LLVM
vectorises; a cube's 8-bit case is then ``lower | upper << 4``. Only active
cubes (case not 0 or 255, a few percent of all cubes) do real work, and an
edge's vertex is created lazily by the first active cube that needs it, so
every vertex is made exactly once and shared by id (no position welding).

See :mod:`porecad.mesh.polygonise` for the driver that evaluates fields slab
by slab, runs this kernel on threads and welds the slabs.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .mc_tables import (CENTRE, CUBE_CENTRE_COUNT, CUBE_CENTRE_EDGES, CUBE_COUNT, CUBE_TRIS, EDGE_AXIS,
                        EDGE_BASE, SQUARE_COUNT, SQUARE_TRIS)

# last-resort clamp of the edge parameter (the perturbation below keeps t away from 0/1)
T_EPS = 1e-7


@njit(cache=True, nogil=True, inline="always")
def _g(v, eta):
    """Guarded sample value: ``|v| < eta`` becomes ``+eta``."""
    if abs(v) < eta:
        return eta
    return np.float64(v)


@njit(cache=True, nogil=True)
def _grow(a, need):
    """A copy of ``a`` with room for at least ``need`` rows (grown by half again)."""
    n = max(need, a.shape[0] + a.shape[0] // 2 + 1024)
    new = np.empty((n, a.shape[1]), dtype=a.dtype)
    for r in range(a.shape[0]):      # element loops: a slice assignment compiles a broadcast check (seconds)
        for c in range(a.shape[1]):
            new[r, c] = a[r, c]
    return new


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _plane_cases(F, kk, p, q, eta, inb, sq, weights_x, weights_y):
    """One pass over plane ``kk`` (slot ``p``): inside bits, square cases and counts.

    Returns the plane's weighted inside count ``sum_j wy[j] sum_i wx[i] [F < 0]``
    and, when ``kk > 0``, the exact number of triangles marching cubes emits
    in the layer between planes ``kk - 1`` (slot ``q``) and ``kk``. (fastmath
    lets LLVM vectorise the weighted sum; it only reorders that sum.)
    """
    ny, nx = inb.shape[1], inb.shape[2]
    total = 0.0
    n_tri = 0
    for j in range(ny):
        acc = 0.0
        for i in range(nx):
            b = np.uint8(F[kk, j, i] <= -eta)
            inb[p, j, i] = b
            acc += weights_x[i] * b
        total += weights_y[j] * acc
        if j > 0:
            r = j - 1
            for i in range(nx - 1):
                sq[p, r, i] = (inb[p, r, i] | (inb[p, r, i + 1] << 1)
                               | (inb[p, j, i] << 2) | (inb[p, j, i + 1] << 3))
            if kk > 0:
                for i in range(nx - 1):
                    n_tri += CUBE_COUNT[sq[q, r, i] | (sq[p, r, i] << 4)]
    return total, n_tri


@njit(cache=True, nogil=True)
def _reset_slot(ids, slot, touched, ntouched):
    """Set the touched entries of ``ids[slot]`` back to -1."""
    for t in range(ntouched[slot]):
        ids[slot, touched[slot, t]] = -1
    ntouched[slot] = 0


@njit(cache=True, nogil=True)
def _edge_id(e, i, j, p, q, xe, ye, ze, nx):
    """Id of the (existing) vertex on cube edge ``e`` of cube (i, j) of the current layer."""
    bx = i + EDGE_BASE[e, 0]
    by = j + EDGE_BASE[e, 1]
    pl = p if EDGE_BASE[e, 2] else q
    cell = by * nx + bx
    ax = EDGE_AXIS[e]
    if ax == 0:
        return xe[pl, cell]
    if ax == 1:
        return ye[pl, cell]
    return ze[cell]


@njit(cache=True, nogil=True)
def _emit_cubes(F, kk, k0, p, q, eta, sq, xe, ye, ze, tx, ntx, ty, nty, tz, ntz,
                verts, faces, nv, nf, origin, spacing):
    """Triangles of the cube layer between planes ``kk - 1`` (slot q) and ``kk`` (slot p).

    ``verts`` and ``faces`` must have room for this layer (the caller grows
    them): keeping them fixed here lets LLVM keep the hot loop in registers.
    Cases with a star loop (see :mod:`porecad.mesh.mc_tables`) get a centre
    vertex after their triangles, the centroid of the loop's edge vertices
    (all made by then), patched into the triangles' ``-1`` slots.
    Returns the new ``(nv, nf)``.
    """
    ny, nx = sq.shape[1], sq.shape[2]
    ox, oy, oz = origin[0], origin[1], origin[2]
    hx, hy, hz = spacing[0], spacing[1], spacing[2]
    kq = kk - 1
    for j in range(ny - 1):
        for i in range(nx - 1):
            case = sq[q, j, i] | (sq[p, j, i] << 4)
            if case == 0 or case == 255:
                continue
            nf0 = nf
            for t in range(CUBE_COUNT[case]):
                for c in range(3):
                    e = CUBE_TRIS[case, t, c]
                    if e == CENTRE:
                        faces[nf, c] = -1  # the loop's centre: made below, once its edge vertices exist
                        continue
                    bx = i + EDGE_BASE[e, 0]
                    by = j + EDGE_BASE[e, 1]
                    up = EDGE_BASE[e, 2]
                    ax = EDGE_AXIS[e]
                    pl = p if up else q
                    kl = kk if up else kq
                    cell = by * nx + bx
                    if ax == 0:
                        vid = xe[pl, cell]
                        if vid < 0:
                            a = _g(F[kl, by, bx], eta)
                            tt = a / (a - _g(F[kl, by, bx + 1], eta))
                            tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                            verts[nv, 0] = ox + hx * (bx + tt)
                            verts[nv, 1] = oy + hy * by
                            verts[nv, 2] = oz + hz * (k0 + kl)
                            vid = nv
                            nv += 1
                            xe[pl, cell] = vid
                            tx[pl, ntx[pl]] = cell
                            ntx[pl] += 1
                    elif ax == 1:
                        vid = ye[pl, cell]
                        if vid < 0:
                            a = _g(F[kl, by, bx], eta)
                            tt = a / (a - _g(F[kl, by + 1, bx], eta))
                            tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                            verts[nv, 0] = ox + hx * bx
                            verts[nv, 1] = oy + hy * (by + tt)
                            verts[nv, 2] = oz + hz * (k0 + kl)
                            vid = nv
                            nv += 1
                            ye[pl, cell] = vid
                            ty[pl, nty[pl]] = cell
                            nty[pl] += 1
                    else:
                        vid = ze[cell]
                        if vid < 0:
                            a = _g(F[kq, by, bx], eta)
                            tt = a / (a - _g(F[kk, by, bx], eta))
                            tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                            verts[nv, 0] = ox + hx * bx
                            verts[nv, 1] = oy + hy * by
                            verts[nv, 2] = oz + hz * (k0 + kq + tt)
                            vid = nv
                            nv += 1
                            ze[cell] = vid
                            tz[ntz[0]] = cell
                            ntz[0] += 1
                    faces[nf, c] = vid
                nf += 1
            n_centre = CUBE_CENTRE_COUNT[case]
            if n_centre > 0:  # rare: a star loop (see mc_tables); its centre is the centroid of its vertices
                cx = 0.0
                cy = 0.0
                cz = 0.0
                for c in range(n_centre):
                    vid = _edge_id(CUBE_CENTRE_EDGES[case, c], i, j, p, q, xe, ye, ze, nx)
                    cx += verts[vid, 0]
                    cy += verts[vid, 1]
                    cz += verts[vid, 2]
                verts[nv, 0] = cx / n_centre
                verts[nv, 1] = cy / n_centre
                verts[nv, 2] = cz / n_centre
                for t in range(nf0, nf):
                    for c in range(3):
                        if faces[t, c] < 0:
                            faces[t, c] = nv
                nv += 1
    return nv, nf


@njit(cache=True, nogil=True)
def _emit_caps(kk, k0, p, q, inb, caps_on, xe, ye, ze, sv, ts, nts, verts, faces, nv, nf,
               origin, spacing):
    """Cap triangles on the box faces enabled in ``caps_on`` for the layer ``kk - 1 .. kk``.

    Each cap square lists polygon points: 0..3 its corners, 4..7 its edges. A
    face's local frame (u, v) has normal +axis; side-0 faces flip triangles.
    Returns the new ``(nv, nf)``.
    """
    ny, nx = inb.shape[1], inb.shape[2]
    ox, oy, oz = origin[0], origin[1], origin[2]
    hx, hy, hz = spacing[0], spacing[1], spacing[2]
    kq = kk - 1
    cs_i = np.empty(4, dtype=np.int64)
    cs_j = np.empty(4, dtype=np.int64)
    cs_p = np.empty(4, dtype=np.int64)
    ed_a = np.empty(4, dtype=np.int64)
    ed_i = np.empty(4, dtype=np.int64)
    ed_j = np.empty(4, dtype=np.int64)
    ed_p = np.empty(4, dtype=np.int64)
    for face in range(6):
        if not caps_on[face]:
            continue
        rev = face == 0 or face == 2 or face == 4
        if face < 2:
            n1, n2 = ny - 1, 1
        elif face < 4:
            n1, n2 = nx - 1, 1
        else:
            n1, n2 = ny - 1, nx - 1
        for s1 in range(n1):
            for s2 in range(n2):
                if face < 2:  # x = const, (u, v) = (y, z)
                    ii = 0 if face == 0 else nx - 1
                    jj = s1
                    cs_i[0], cs_j[0], cs_p[0] = ii, jj, q
                    cs_i[1], cs_j[1], cs_p[1] = ii, jj + 1, q
                    cs_i[2], cs_j[2], cs_p[2] = ii, jj + 1, p
                    cs_i[3], cs_j[3], cs_p[3] = ii, jj, p
                    ed_a[0], ed_i[0], ed_j[0], ed_p[0] = 1, ii, jj, q
                    ed_a[1], ed_i[1], ed_j[1], ed_p[1] = 2, ii, jj + 1, 0
                    ed_a[2], ed_i[2], ed_j[2], ed_p[2] = 1, ii, jj, p
                    ed_a[3], ed_i[3], ed_j[3], ed_p[3] = 2, ii, jj, 0
                elif face < 4:  # y = const, (u, v) = (z, x)
                    jj = 0 if face == 2 else ny - 1
                    ii = s1
                    cs_i[0], cs_j[0], cs_p[0] = ii, jj, q
                    cs_i[1], cs_j[1], cs_p[1] = ii, jj, p
                    cs_i[2], cs_j[2], cs_p[2] = ii + 1, jj, p
                    cs_i[3], cs_j[3], cs_p[3] = ii + 1, jj, q
                    ed_a[0], ed_i[0], ed_j[0], ed_p[0] = 2, ii, jj, 0
                    ed_a[1], ed_i[1], ed_j[1], ed_p[1] = 0, ii, jj, p
                    ed_a[2], ed_i[2], ed_j[2], ed_p[2] = 2, ii + 1, jj, 0
                    ed_a[3], ed_i[3], ed_j[3], ed_p[3] = 0, ii, jj, q
                else:  # z = const, (u, v) = (x, y)
                    jj = s1
                    ii = s2
                    sl = q if face == 4 else p
                    cs_i[0], cs_j[0], cs_p[0] = ii, jj, sl
                    cs_i[1], cs_j[1], cs_p[1] = ii + 1, jj, sl
                    cs_i[2], cs_j[2], cs_p[2] = ii + 1, jj + 1, sl
                    cs_i[3], cs_j[3], cs_p[3] = ii, jj + 1, sl
                    ed_a[0], ed_i[0], ed_j[0], ed_p[0] = 0, ii, jj, sl
                    ed_a[1], ed_i[1], ed_j[1], ed_p[1] = 1, ii + 1, jj, sl
                    ed_a[2], ed_i[2], ed_j[2], ed_p[2] = 0, ii, jj + 1, sl
                    ed_a[3], ed_i[3], ed_j[3], ed_p[3] = 1, ii, jj, sl
                code4 = 0
                for s in range(4):
                    code4 |= inb[cs_p[s], cs_j[s], cs_i[s]] << s
                nt = SQUARE_COUNT[code4]
                for t in range(nt):
                    for c in range(3):
                        code = SQUARE_TRIS[code4, t, c]
                        if code < 4:
                            pl = cs_p[code]
                            cell = cs_j[code] * nx + cs_i[code]
                            vid = sv[pl, cell]
                            if vid < 0:
                                verts[nv, 0] = ox + hx * cs_i[code]
                                verts[nv, 1] = oy + hy * cs_j[code]
                                verts[nv, 2] = oz + hz * (k0 + (kk if pl == p else kq))
                                vid = nv
                                nv += 1
                                sv[pl, cell] = vid
                                ts[pl, nts[pl]] = cell
                                nts[pl] += 1
                        else:
                            s = code - 4
                            cell = ed_j[s] * nx + ed_i[s]
                            ea = ed_a[s]
                            if ea == 0:
                                vid = xe[ed_p[s], cell]
                            elif ea == 1:
                                vid = ye[ed_p[s], cell]
                            else:
                                vid = ze[cell]
                        cc = c
                        if rev and c > 0:
                            cc = 3 - c
                        faces[nf, cc] = vid
                    nf += 1
    return nv, nf


def mesh_slab(F, k0, origin, spacing, caps, weights_z, weights_y, weights_x, est_tris, eta):
    """Mesh one slab of samples.

    Parameters
    ----------
    F : (nzp, ny, nx) float32
        Field samples of global planes ``k0 .. k0 + nzp - 1``; negative inside.
    k0 : int
        Global index of the slab's first plane.
    origin, spacing : (3,) float64
        Position of global sample (0, 0, 0) and the sample spacing.
    caps : (6,) bool
        Cap the solid on the faces x0, x1, y0, y1 (global grid boundary) and
        z0, z1 (this slab's first/last plane is the grid boundary).
    weights_z : (nzp,) float64
        Weight of each plane in the voxel volume (zero for a plane that the
        next slab counts).
    weights_y, weights_x : (ny,), (nx,) float64
        Weights of a plane's rows and columns (trapezoid rule): sample
        ``(j, i)`` of plane ``k`` weighs ``weights_z[k] * weights_y[j] * weights_x[i]``.
    est_tris : int
        Initial capacity guess for the triangle buffer.
    eta : float
        Degeneracy guard (simulation of simplicity): a sample with ``|f| < eta``
        is treated as ``f = +eta`` (outside). The surface then never passes
        exactly through a sample, so no two vertices coincide and no
        zero-area triangles appear; the displacement is ``O(eta / |grad f|)``.

    Returns
    -------
    verts : (V, 3) float64
    faces : (F, 3) int32
    bottom, top : (3, ny * nx) int32
        Vertex ids on the first and last plane (x-edges, y-edges, samples), -1 if none.
    inside_weight : float
        Weighted count of inside samples.
    """
    ny, nx = F.shape[1], F.shape[2]
    plane = ny * nx
    n = max(1024, int(est_tris))
    # the kernel's buffers and per-plane scratch, made here: allocations inside it compiled numba's
    # np.full / np.zeros overloads for 1.2 s on every first run (issue 22)
    ids = np.full((4, 2, plane), -1, np.int32)    # vertex ids per plane slot: x-edges, y-edges, samples, z-edges
    ends = np.full((2, 3, plane), -1, np.int32)   # the first and last plane's ids (bottom, top)
    verts, faces, nv, nf, inside = _mesh_slab(
        F, int(k0), origin, spacing, caps, weights_z, weights_y, weights_x, float(eta),
        np.empty((max(1024, n // 2), 3), np.float64), np.empty((n, 3), np.int32), ids,
        np.empty((4, 2, plane), np.int32), np.zeros((4, 2), np.int64), np.zeros((2, 2, ny, nx), np.uint8),
        np.zeros(6, np.bool_), ends)
    return _trim(verts, nv), _trim(faces, nf), ends[0], ends[1], inside


@njit(cache=True, nogil=True)
def _mesh_slab(F, k0, origin, spacing, caps, weights_z, weights_y, weights_x, eta, verts, faces, ids, touched,
               counts, planes, caps_on, ends):
    """:func:`mesh_slab` with its buffers and scratch given (see there): ``ids`` and ``ends`` all -1,
    ``counts``, ``planes`` and ``caps_on`` zero; ``verts``, ``faces`` grow as needed.

    Returns ``(verts, faces, nv, nf, inside_weight)``: the first ``nv`` and
    ``nf`` rows of the (possibly grown) buffers are the mesh.
    """
    nzp, ny, nx = F.shape
    any_side_cap = caps[0] or caps[1] or caps[2] or caps[3]
    # counters typed from a shape, not the literal 0: a literal argument makes numba compile the
    # callees (_emit_cubes, _emit_caps) twice, once for Literal[int](0), once for int64
    nv = F.shape[0] * 0
    nf = F.shape[0] * 0
    # vertex ids per plane slot (x-edges, y-edges, samples) and of the layer's z-edges
    xe, ye, sv, ze = ids[0], ids[1], ids[2], ids[3, 0]
    # entries set since the slot was last reset (each cell at most once per slot)
    tx, ty, ts, tz = touched[0], touched[1], touched[2], touched[3]    # tz: row 0 only
    ntx, nty, nts, ntz = counts[0], counts[1], counts[2], counts[3]    # ntz: entry 0 only
    inb, sq = planes[0], planes[1]
    bottom, top = ends[0], ends[1]
    max_sq_tris = 0
    for c in range(SQUARE_COUNT.shape[0]):
        max_sq_tris = max(max_sq_tris, SQUARE_COUNT[c])
    inside_w = 0.0

    for kk in range(nzp):
        p = kk & 1
        _reset_slot(xe, p, tx, ntx)
        _reset_slot(ye, p, ty, nty)
        _reset_slot(sv, p, ts, nts)
        q = p ^ 1
        w, n_cube_tris = _plane_cases(F, kk, p, q, eta, inb, sq, weights_x, weights_y)
        if weights_z[kk] != 0.0:
            inside_w += weights_z[kk] * w
        if kk == 0:
            continue
        kq = kk - 1
        for t in range(ntz[0]):
            ze[tz[0, t]] = -1
        ntz[0] = 0
        # room for this layer: its exact cube triangle count plus a bound for the caps
        nsq = 0
        if any_side_cap:
            nsq = 2 * (ny - 1) + 2 * (nx - 1)
        caps_on[0] = caps[0]
        caps_on[1] = caps[1]
        caps_on[2] = caps[2]
        caps_on[3] = caps[3]
        caps_on[4] = kq == 0 and caps[4]
        caps_on[5] = kk == nzp - 1 and caps[5]
        if caps_on[4]:
            nsq += (ny - 1) * (nx - 1)
        if caps_on[5]:
            nsq += (ny - 1) * (nx - 1)
        n_layer = n_cube_tris + max_sq_tris * nsq
        if nf + n_layer > faces.shape[0]:
            faces = _grow(faces, nf + n_layer)
        if nv + 3 * n_layer > verts.shape[0]:
            verts = _grow(verts, nv + 3 * n_layer)
        nv, nf = _emit_cubes(F, kk, k0, p, q, eta, sq, xe, ye, ze, tx, ntx, ty, nty, tz[0], ntz,
                             verts, faces, nv, nf, origin, spacing)
        if nsq > 0:
            nv, nf = _emit_caps(kk, k0, p, q, inb, caps_on, xe, ye, ze, sv, ts, nts, verts, faces,
                                nv, nf, origin, spacing)
        if kq == 0:
            _copy_ids(bottom, xe, ye, sv, q)
        if kk == nzp - 1:
            _copy_ids(top, xe, ye, sv, p)
    return verts, faces, nv, nf, inside_w


@njit(cache=True, nogil=True)
def _copy_ids(dst, xe, ye, sv, slot):
    """``dst[0..2] = xe[slot], ye[slot], sv[slot]`` (element loops, see :func:`_grow`)."""
    for c in range(dst.shape[1]):
        dst[0, c] = xe[slot, c]
        dst[1, c] = ye[slot, c]
        dst[2, c] = sv[slot, c]


def _trim(a, n):
    """``a[:n]``, copied when that frees much memory."""
    if n < a.shape[0] - a.shape[0] // 8:
        return a[:n].copy()
    return a[:n]


def compile_caps() -> None:
    """Compile :func:`_emit_caps` for the one signature :func:`_mesh_slab` calls it with (fills numba's cache).

    For the first run's background helper (:mod:`porecad.first_run`): the
    job then loads it while compiling the rest of marching cubes.
    """
    from numba import types as T

    i64, u8_3, b_1 = T.int64, T.uint8[:, :, ::1], T.boolean[::1]
    i32_1, i32_2, i64_1 = T.int32[::1], T.int32[:, ::1], T.int64[::1]
    f64_1, f64_2 = T.float64[::1], T.float64[:, ::1]
    _emit_caps.compile((i64, i64, i64, i64, u8_3, b_1, i32_2, i32_2, i32_1, i32_2, i32_2, i64_1, f64_2,
                        i32_2, i64, i64, f64_1, f64_1))
