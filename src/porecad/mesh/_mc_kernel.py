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

from .mc_tables import CUBE_COUNT, CUBE_TRIS, EDGE_AXIS, EDGE_BASE, SQUARE_COUNT, SQUARE_TRIS

# last-resort clamp of the edge parameter (the perturbation below keeps t away from 0/1)
T_EPS = 1e-7


@njit(cache=True, nogil=True, inline="always")
def _g(v, eta):
    """Guarded sample value: ``|v| < eta`` becomes ``+eta``."""
    if abs(v) < eta:
        return eta
    return np.float64(v)


@njit(cache=True, nogil=True)
def _grow2(a):
    new = np.empty((a.shape[0] * 2 + 1024, a.shape[1]), dtype=a.dtype)
    new[:a.shape[0]] = a
    return new


@njit(cache=True, nogil=True)
def _reset(arr, slot, touched, n, nx):
    for t in range(n):
        code = touched[t, slot]
        arr[slot, code // nx, code % nx] = -1


@njit(cache=True, nogil=True)
def mesh_slab(F, k0, origin, spacing, caps, weights_z, weights_xy, est_tris, eta):
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
    weights_xy : (ny, nx) float64
        Weights of a plane's samples (trapezoid rule).
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
    bottom, top : (3, ny, nx) int32
        Vertex ids on the first and last plane (x-edges, y-edges, samples), -1 if none.
    inside_weight : float
        Weighted count of inside samples, ``sum weights_z[k] * weights_xy[j, i]``.
    """
    nzp, ny, nx = F.shape
    ox, oy, oz = origin[0], origin[1], origin[2]
    hx, hy, hz = spacing[0], spacing[1], spacing[2]
    cap_x0, cap_x1, cap_y0, cap_y1, cap_z0, cap_z1 = caps[0], caps[1], caps[2], caps[3], caps[4], caps[5]
    any_cap = cap_x0 or cap_x1 or cap_y0 or cap_y1

    verts = np.empty((max(1024, est_tris // 2), 3), dtype=np.float64)
    faces = np.empty((max(1024, est_tris), 3), dtype=np.int32)
    nv = 0
    nf = 0
    plane = ny * nx

    xe = -np.ones((2, ny, nx), dtype=np.int32)
    ye = -np.ones((2, ny, nx), dtype=np.int32)
    sv = -np.ones((2, ny, nx), dtype=np.int32)
    ze = -np.ones((ny, nx), dtype=np.int32)
    inb = np.zeros((2, ny, nx), dtype=np.uint8)
    sq = np.zeros((2, ny, nx), dtype=np.uint8)
    # lists of touched entries, to reset only what was set
    tx = np.empty((1024, 2), dtype=np.int64)
    ty = np.empty((1024, 2), dtype=np.int64)
    ts = np.empty((1024, 2), dtype=np.int64)
    tz = np.empty(1024, dtype=np.int64)
    ntx = np.zeros(2, dtype=np.int64)
    nty = np.zeros(2, dtype=np.int64)
    nts = np.zeros(2, dtype=np.int64)
    ntz = 0
    bottom = -np.ones((3, ny, nx), dtype=np.int32)
    top = -np.ones((3, ny, nx), dtype=np.int32)
    inside_w = 0.0
    wy_row = np.empty(ny, dtype=np.float64)

    for kk in range(nzp):
        p = kk & 1
        # ---- reset the slot of plane kk-2
        _reset(xe, p, tx, ntx[p], nx)
        _reset(ye, p, ty, nty[p], nx)
        _reset(sv, p, ts, nts[p], nx)
        ntx[p] = 0
        nty[p] = 0
        nts[p] = 0
        # ---- inside bits and weighted inside count (branch-free, vectorisable)
        wz = weights_z[kk]
        for j in range(ny):
            acc = 0.0
            for i in range(nx):
                b = np.uint8(F[kk, j, i] <= -eta)
                inb[p, j, i] = b
                acc += weights_xy[j, i] * b
            wy_row[j] = acc
        if wz != 0.0:
            for j in range(ny):
                inside_w += wz * wy_row[j]
        # ---- square cases of the plane's face cells
        for j in range(ny - 1):
            for i in range(nx - 1):
                sq[p, j, i] = (inb[p, j, i] | (inb[p, j, i + 1] << 1)
                               | (inb[p, j + 1, i] << 2) | (inb[p, j + 1, i + 1] << 3))
        if kk == 0:
            continue
        q = p ^ 1
        kq = kk - 1
        # ---- reset z-edges of the previous layer
        for t in range(ntz):
            ze[tz[t] // nx, tz[t] % nx] = -1
        ntz = 0
        # ---- cubes of the layer between planes kk-1 (slot q) and kk (slot p)
        for j in range(ny - 1):
            for i in range(nx - 1):
                case = sq[q, j, i] | (sq[p, j, i] << 4)
                if case == 0 or case == 255:
                    continue
                nt = CUBE_COUNT[case]
                if nf + nt > faces.shape[0]:
                    faces = _grow2(faces)
                for t in range(nt):
                    for c in range(3):
                        e = CUBE_TRIS[case, t, c]
                        bx = i + EDGE_BASE[e, 0]
                        by = j + EDGE_BASE[e, 1]
                        up = EDGE_BASE[e, 2]
                        ax = EDGE_AXIS[e]
                        pl = p if up else q
                        kl = kk if up else kq
                        if ax == 0:
                            vid = xe[pl, by, bx]
                            if vid < 0:
                                a = _g(F[kl, by, bx], eta)
                                tt = a / (a - _g(F[kl, by, bx + 1], eta))
                                tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                                if nv >= verts.shape[0]:
                                    verts = _grow2(verts)
                                verts[nv, 0] = ox + hx * (bx + tt)
                                verts[nv, 1] = oy + hy * by
                                verts[nv, 2] = oz + hz * (k0 + kl)
                                vid = nv
                                nv += 1
                                xe[pl, by, bx] = vid
                                if ntx[pl] >= tx.shape[0]:
                                    tx = _grow2(tx)
                                tx[ntx[pl], pl] = by * nx + bx
                                ntx[pl] += 1
                        elif ax == 1:
                            vid = ye[pl, by, bx]
                            if vid < 0:
                                a = _g(F[kl, by, bx], eta)
                                tt = a / (a - _g(F[kl, by + 1, bx], eta))
                                tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                                if nv >= verts.shape[0]:
                                    verts = _grow2(verts)
                                verts[nv, 0] = ox + hx * bx
                                verts[nv, 1] = oy + hy * (by + tt)
                                verts[nv, 2] = oz + hz * (k0 + kl)
                                vid = nv
                                nv += 1
                                ye[pl, by, bx] = vid
                                if nty[pl] >= ty.shape[0]:
                                    ty = _grow2(ty)
                                ty[nty[pl], pl] = by * nx + bx
                                nty[pl] += 1
                        else:
                            vid = ze[by, bx]
                            if vid < 0:
                                a = _g(F[kq, by, bx], eta)
                                tt = a / (a - _g(F[kk, by, bx], eta))
                                tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                                if nv >= verts.shape[0]:
                                    verts = _grow2(verts)
                                verts[nv, 0] = ox + hx * bx
                                verts[nv, 1] = oy + hy * by
                                verts[nv, 2] = oz + hz * (k0 + kq + tt)
                                vid = nv
                                nv += 1
                                ze[by, bx] = vid
                                if ntz >= tz.shape[0]:
                                    tz2 = np.empty(tz.shape[0] * 2, dtype=np.int64)
                                    tz2[:ntz] = tz[:ntz]
                                    tz = tz2
                                tz[ntz] = by * nx + bx
                                ntz += 1
                        faces[nf, c] = vid
                    nf += 1
        # ---- caps. Each cap square lists polygon points: 0..3 corners, 4..7 edges.
        # A face's local frame (u, v) has normal +axis; side-0 faces flip triangles.
        nsq = 0
        if any_cap:
            nsq = 2 * (ny - 1) + 2 * (nx - 1)
        zc0 = kq == 0 and cap_z0
        zc1 = kk == nzp - 1 and cap_z1
        if zc0:
            nsq += (ny - 1) * (nx - 1)
        if zc1:
            nsq += (ny - 1) * (nx - 1)
        if nsq > 0:
            # corner samples (ci, cj, ck-slot) and edges (axis, i, j, slot) for each square
            cs_i = np.empty(4, dtype=np.int64)
            cs_j = np.empty(4, dtype=np.int64)
            cs_p = np.empty(4, dtype=np.int64)
            ed_a = np.empty(4, dtype=np.int64)
            ed_i = np.empty(4, dtype=np.int64)
            ed_j = np.empty(4, dtype=np.int64)
            ed_p = np.empty(4, dtype=np.int64)
            for face in range(6):
                if face == 0 and not cap_x0:
                    continue
                if face == 1 and not cap_x1:
                    continue
                if face == 2 and not cap_y0:
                    continue
                if face == 3 and not cap_y1:
                    continue
                if face == 4 and not zc0:
                    continue
                if face == 5 and not zc1:
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
                        if nt == 0:
                            continue
                        if nf + nt > faces.shape[0]:
                            faces = _grow2(faces)
                        for t in range(nt):
                            for c in range(3):
                                code = SQUARE_TRIS[code4, t, c]
                                if code < 4:
                                    pl = cs_p[code]
                                    cj = cs_j[code]
                                    ci = cs_i[code]
                                    vid = sv[pl, cj, ci]
                                    if vid < 0:
                                        if nv >= verts.shape[0]:
                                            verts = _grow2(verts)
                                        verts[nv, 0] = ox + hx * ci
                                        verts[nv, 1] = oy + hy * cj
                                        verts[nv, 2] = oz + hz * (k0 + (kk if pl == p else kq))
                                        vid = nv
                                        nv += 1
                                        sv[pl, cj, ci] = vid
                                        if nts[pl] >= ts.shape[0]:
                                            ts = _grow2(ts)
                                        ts[nts[pl], pl] = cj * nx + ci
                                        nts[pl] += 1
                                else:
                                    s = code - 4
                                    ea = ed_a[s]
                                    if ea == 0:
                                        vid = xe[ed_p[s], ed_j[s], ed_i[s]]
                                    elif ea == 1:
                                        vid = ye[ed_p[s], ed_j[s], ed_i[s]]
                                    else:
                                        vid = ze[ed_j[s], ed_i[s]]
                                cc = c
                                if rev and c > 0:
                                    cc = 3 - c
                                faces[nf, cc] = vid
                            nf += 1
        if kq == 0:
            bottom[0] = xe[q]
            bottom[1] = ye[q]
            bottom[2] = sv[q]
        if kk == nzp - 1:
            top[0] = xe[p]
            top[1] = ye[p]
            top[2] = sv[p]
    return verts[:nv].copy(), faces[:nf].copy(), bottom, top, inside_w
