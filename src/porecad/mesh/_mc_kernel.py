"""Numba kernel: marching cubes over one z-slab of samples, with box caps.

Flying-edges style passes (Schroeder, Maynard & Geveci 2015), plane by plane
with rolling per-plane arrays (memory O(nx * ny), not O(slab)):

1. classify a plane: inside bits and each row's inside count by a
   branch-free loop that LLVM vectorises, then the 4-bit square cases of its
   face cells, 8 per 64-bit word (:func:`_classify_plane`);
2. list the active cubes of the layer below it (case not 0 or 255: about 1 %
   of all cubes) with the layer's exact triangle count: rows whose four sample
   rows are uniform are trimmed away from the row counts, the others are
   scanned 8 cubes per word (:func:`_layer_active`);
3. make exact room and emit the active cubes' triangles (:func:`_emit_cubes`)
   and the caps (:func:`_emit_caps`). A vertex is made once per intersected
   edge, by the first cube that needs it, and shared by id through flat
   per-plane edge-id arrays: no hashing and no position welding.

See :mod:`porecad.mesh.polygonise` for the driver that evaluates fields slab
by slab, runs this kernel on threads and welds the slabs by the grid keys of
their shared plane's vertices.
"""

from __future__ import annotations

import threading

import numpy as np
from numba import njit

from .mc_tables import (CENTRE, CUBE_CENTRE_COUNT, CUBE_CENTRE_EDGES, CUBE_COUNT, CUBE_TRIS, EDGE_AXIS,
                        EDGE_BASE, SQUARE_COUNT, SQUARE_TRIS)

# last-resort clamp of the edge parameter (the perturbation below keeps t away from 0/1)
T_EPS = 1e-7
# 64-bit word constants (typed: numba would turn uint64 op int64 into float64)
_U0, _U1, _U2, _U3, _U4, _U8, _U16, _U32, _U56 = (np.uint64(k) for k in (0, 1, 2, 3, 4, 8, 16, 32, 56))
_UFF, _ONES = np.uint64(0xFF), np.uint64(0xFFFFFFFFFFFFFFFF)


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
def _classify_plane(F, kk, p, thr, inb, in64, sq64, rowcnt, weights_x, weights_y, trap_x):
    """Pass 1 over plane ``kk`` (slot ``p``): inside bits, row counts, square cases.

    ``inb[p, j, i] = F[kk, j, i] <= thr`` (rows zero padded to whole 8-byte words, ``in64`` the same
    memory as words) by a loop that LLVM vectorises; ``rowcnt[p, j]`` the row's inside count (bytes
    summed 8 per word). Then the 4-bit square case of every face cell, 8 cells per word (``sq64[p, j]``:
    byte ``i`` is ``b(j, i) | b(j, i+1) << 1 | b(j+1, i) << 2 | b(j+1, i+1) << 3``; bytes from
    ``nx - 1`` on are padding). Returns ``sum_j wy[j] sum_i wx[i] [F <= thr]`` (fastmath only reorders
    it); with ``trap_x`` (``wx`` the trapezoid rule, ``nx >= 2``) a row's sum is its count less half
    its end bits: the same number, as sums of halves are exact in any order.
    """
    ny, nx, nw = inb.shape[1], F.shape[2], in64.shape[2]
    total = 0.0
    for j in range(ny):
        for i in range(nx):
            inb[p, j, i] = np.uint8(F[kk, j, i] <= thr)
        cnt = 0
        for w in range(nw):     # bytes 0 or 1: their sum by shifts (at most 8, no carry between bytes)
            x = in64[p, j, w]
            x += x >> _U8
            x += x >> _U16
            x += x >> _U32
            cnt += np.int64(x & _UFF)
        rowcnt[p, j] = cnt
        if trap_x:
            acc = cnt - 0.5 * (np.float64(inb[p, j, 0]) + np.float64(inb[p, j, nx - 1]))
        else:
            acc = 0.0
            for i in range(nx):
                acc += weights_x[i] * inb[p, j, i]
        total += weights_y[j] * acc
        if j > 0:
            r = j - 1
            for w in range(nw):
                lo = in64[p, r, w]
                hi = in64[p, j, w]
                lo_n = in64[p, r, w + 1] if w + 1 < nw else _U0
                hi_n = in64[p, j, w + 1] if w + 1 < nw else _U0
                lo1 = (lo >> _U8) | (lo_n << _U56)   # byte i: the sample at i + 1
                hi1 = (hi >> _U8) | (hi_n << _U56)
                sq64[p, r, w] = lo | (lo1 << _U1) | (hi << _U2) | (hi1 << _U3)
    return total


@njit(cache=True, nogil=True)
def _layer_active(p, q, nx, rowcnt, sq64, acol, acase, arow):
    """Pass 2: active cubes (case not 0 or 255) of the layer between slots ``q`` (lower) and ``p`` (upper).

    Flying-edges style trimming: a cube row whose four sample rows are all
    outside (or all inside) is skipped from the row counts alone; otherwise its
    cube cases ``sq[q] | sq[p] << 4`` are formed 8 at a time in 64-bit words and
    a word of 8 inactive cubes (all 0 or all 255: neighbouring cubes share 4
    corners) is skipped. Lists the active cubes in row-major order: column
    ``acol[n]``, case ``acase[n]``, row ``j``'s from ``arow[j]`` to ``arow[j + 1]``.
    Returns ``(n, n_triangles)``, the exact triangle count of the layer.
    """
    ny, nw = sq64.shape[1], sq64.shape[2]
    na = 0
    n_tri = 0
    arow[0] = 0
    for j in range(ny - 1):
        arow[j + 1] = na
        r0 = rowcnt[q, j]
        if r0 == 0 or r0 == nx:
            if rowcnt[q, j + 1] == r0 and rowcnt[p, j] == r0 and rowcnt[p, j + 1] == r0:
                continue
        for w in range(nw):
            cw = sq64[q, j, w] | (sq64[p, j, w] << _U4)
            if cw == _U0 or cw == _ONES:
                continue
            for bb in range(8):
                i = 8 * w + bb
                if i >= nx - 1:
                    break
                c = np.int64((cw >> np.uint64(8 * bb)) & _UFF)
                if c != 0 and c != 255:
                    acol[na] = i
                    acase[na] = c
                    na += 1
                    n_tri += CUBE_COUNT[c]
        arow[j + 1] = na
    return na, n_tri


@njit(cache=True, nogil=True)
def _edge_tables(kk, p, q, nx, plane, tab):
    """Per cube edge ``e`` of the layer ``kk - 1 .. kk``, offsets to add to a cube's ``j * nx + i``.

    ``tab[0, e]``: its entry in the edge-id array (x-edges of slots 0, 1, then
    y-edges of slots 0, 1, then the layer's z-edges, ``plane`` entries each);
    ``tab[1, e]``: its first sample in the slab (flat); ``tab[2, e]``: the
    step to its second sample; ``tab[3, e]``: its touched list (the slot, or 2
    for z-edges); ``tab[4, e]``: the plane (slab index) of its first sample.
    """
    for e in range(12):
        ax = EDGE_AXIS[e]
        up = EDGE_BASE[e, 2]
        slot = p if up else q
        kl = kk if up else kk - 1
        cell = EDGE_BASE[e, 1] * nx + EDGE_BASE[e, 0]
        if ax == 2:
            tab[0, e] = 4 * plane + cell
            tab[2, e] = plane
            tab[3, e] = 2
            kl = kk - 1
        else:
            tab[0, e] = (2 * ax + slot) * plane + cell
            tab[2, e] = 1 if ax == 0 else nx
            tab[3, e] = slot
        tab[1, e] = kl * plane + cell
        tab[4, e] = kl


@njit(cache=True, nogil=True)
def _emit_cubes(Ff, k0, eta, acol, acase, arow, nx, tab, E, touched, nt, verts, faces, nv, nf, origin, spacing):
    """Pass 3: triangles of the active cubes of one layer (listed by :func:`_layer_active`; edge offsets
    ``tab``, see :func:`_edge_tables`).

    ``verts`` and ``faces`` must have room for this layer (the caller grows
    them): keeping them fixed here lets LLVM keep the hot loop in registers.
    A vertex is made once per intersected edge, by the first cube that needs
    it, and shared by id through the edge-id array ``E`` (its entry is
    recorded in ``touched[tab[3, e]]`` to be reset later). Cases with a star
    loop (see :mod:`porecad.mesh.mc_tables`) get a centre vertex after their
    triangles, the centroid of the loop's edge vertices (all made by then),
    patched into the triangles' ``-1`` slots. Returns the new ``(nv, nf)``.
    """
    ox, oy, oz = origin[0], origin[1], origin[2]
    hx, hy, hz = spacing[0], spacing[1], spacing[2]
    j = 0
    for m in range(arow[arow.shape[0] - 1]):
        while m >= arow[j + 1]:
            j += 1
        i = acol[m]
        case = np.int64(acase[m])
        cbase = j * nx + i
        nf0 = nf
        for t in range(CUBE_COUNT[case]):
            for c in range(3):
                e = CUBE_TRIS[case, t, c]
                if e == CENTRE:
                    faces[nf, c] = -1  # the loop's centre: made below, once its edge vertices exist
                    continue
                idx = tab[0, e] + cbase
                vid = E[idx]
                if vid < 0:
                    fa = tab[1, e] + cbase
                    a = _g(Ff[fa], eta)
                    tt = a / (a - _g(Ff[fa + tab[2, e]], eta))
                    tt = min(max(tt, T_EPS), 1.0 - T_EPS)
                    ax = EDGE_AXIS[e]   # tt added on the edge's axis: a branch, not three selects (5 % faster)
                    px, py = np.float64(i + EDGE_BASE[e, 0]), np.float64(j + EDGE_BASE[e, 1])
                    pz = np.float64(k0 + tab[4, e])
                    if ax == 0:
                        px += tt
                    elif ax == 1:
                        py += tt
                    else:
                        pz += tt
                    verts[nv, 0] = ox + hx * px
                    verts[nv, 1] = oy + hy * py
                    verts[nv, 2] = oz + hz * pz
                    vid = nv
                    nv += 1
                    E[idx] = vid
                    lst = tab[3, e]
                    touched[lst, nt[lst]] = idx
                    nt[lst] += 1
                faces[nf, c] = vid
            nf += 1
        n_centre = CUBE_CENTRE_COUNT[case]
        if n_centre > 0:  # rare: a star loop (see mc_tables); its centre is the centroid of its vertices
            cx = 0.0
            cy = 0.0
            cz = 0.0
            for c in range(n_centre):
                vid = E[tab[0, CUBE_CENTRE_EDGES[case, c]] + cbase]
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
def _emit_caps(kk, k0, p, q, nx, inb, caps_on, xe, ye, ze, sv, ts, nts, verts, faces, nv, nf,
               origin, spacing):
    """Cap triangles on the box faces enabled in ``caps_on`` for the layer ``kk - 1 .. kk``.

    Each cap square lists polygon points: 0..3 its corners, 4..7 its edges. A
    face's local frame (u, v) has normal +axis; side-0 faces flip triangles.
    ``inb`` rows may be padded beyond ``nx``. Returns the new ``(nv, nf)``.
    """
    ny = inb.shape[1]
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


_SCRATCH = threading.local()
#: a thread keeps its output buffers for the next slab up to this size
KEEP_BUFFER_BYTES = 64 << 20


def _scratch(ny, nx, caps=True):
    """This thread's kernel scratch for planes of ``ny * nx`` samples (69 bytes a sample), reused.

    Allocating and filling it per slab cost about as much as the marching itself on large grids; the
    kernel leaves the vertex ids ``E`` and ``sv`` all -1, as it found them (a failed run drops the
    scratch: :func:`mesh_slab`). Without ``caps``, ``sv`` (the caps') may be a stand-in, not filled.
    """
    sc = getattr(_SCRATCH, "arrays", None)
    if sc is not None and sc[0] == (ny, nx) and caps and sc[6].shape[1] < ny * nx:
        sc = _SCRATCH.arrays = sc[:6] + (np.full((2, ny * nx), -1, np.int32),) + sc[7:]
    if sc is None or sc[0] != (ny, nx):
        plane = ny * nx
        nw = nx // 8 + 1                               # words per padded row (at least one zero byte after nx)
        inb = np.zeros((2, ny, 8 * nw), np.uint8)       # inside bits per plane slot
        E = np.full(5 * plane, -1, np.int32)           # edge vertex ids: x-edges of slots 0, 1, y-edges 0, 1, z-edges
        sc = ((ny, nx), E, E[:2 * plane].reshape(2, plane), E[2 * plane:4 * plane].reshape(2, plane),
              E[4 * plane:],                              # views of E by kind (for the caps)
              np.empty((3, 2 * plane), np.int32),         # entries of E set per slot and for z-edges (to reset)
              np.full((2, plane if caps else 1), -1, np.int32),   # sample vertex ids per plane slot (caps)
              np.empty((2, plane), np.int32),             # cells of those set per slot
              inb, inb.view(np.uint64),
              np.zeros((2, ny, nw), np.uint64),           # square cases per plane slot, 8 per word
              np.zeros((2, ny), np.int64),                # inside count per row and plane slot
              np.empty(max(1, (ny - 1) * (nx - 1)), np.int32),  # a layer's active cubes: column,
              np.empty(max(1, (ny - 1) * (nx - 1)), np.uint8),  # case
              np.empty(ny, np.int32))                     # and where each row's start
        _SCRATCH.arrays = sc
    return sc[1:]


def mesh_slab(F, k0, origin, spacing, caps, weights_z, weights_y, weights_x, est_tris, eta, out=None):
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
    out : list, optional
        ``[verts, faces]`` buffers (or None) to mesh into, replaced by those used (grown if needed);
        ``verts``, ``faces`` are then views of them. Else the mesh is copied out of the thread's own.

    Returns
    -------
    verts : (V, 3) float64
    faces : (F, 3) int32
    bottom, top : ((n,) int64, (n,) int64) and, for bottom, two ints more
        The vertices on the first and last plane: their grid keys, sorted
        (``kind * ny * nx + j * nx + i``, kind 0: x-edge, 1: y-edge, 2: sample),
        and their local ids; ``bottom[2:]`` are the number of vertices made by
        the first cube layer and of faces made by the first two: later faces
        use only later vertices, so welding renumbers only that head of the faces.
    inside_weight : float
        Weighted count of inside samples.
    """
    ny, nx = F.shape[1], F.shape[2]
    n = max(1024, int(est_tris))
    thr = np.float32(-eta)   # made the largest float32 <= -eta: ``F <= thr`` is the float64 ``F <= -eta``
    if float(thr) > -eta:
        thr = np.nextafter(thr, np.float32(-np.inf))
    E, xe, ye, ze, touched, sv, ts, inb, in64, sq64, rowcnt, acol, acase, arow = _scratch(ny, nx, bool(np.any(caps)))
    w = np.asarray(weights_x)   # the trapezoid rule (ones, halves at both ends): rows' sums from their counts
    trap = len(w) >= 2 and w[0] == 0.5 and w[-1] == 0.5 and bool(np.all(w[1:-1] == 1.0))
    vbuf, fbuf = _out_buffers(max(1024, n // 2), n, out)
    heads = np.zeros(2, np.int64)
    try:
        verts, faces, nv, nf, inside, seam0, seam1 = _mesh_slab(
            F, int(k0), origin, spacing, caps, weights_z, weights_y, weights_x, trap, float(eta), thr,
            vbuf, fbuf, E, xe, ye, ze, touched, sv, ts,
            np.zeros(3, np.int64), np.zeros(2, np.int64), inb, in64, sq64, rowcnt, acol, acase, arow,
            np.zeros((5, 12), np.int64), np.zeros(6, np.bool_), heads)
    except BaseException:
        _SCRATCH.arrays = _SCRATCH.out = None   # its ids may not be all -1 any more
        raise
    ends = []
    for seam in (seam0, seam1):
        order = np.argsort(seam[0])
        ends.append((seam[0][order], seam[1][order]))
    ends[0] += (int(heads[0]), int(heads[1]))
    if out is not None:
        out[0], out[1] = verts, faces
        return verts[:nv], faces[:nf], ends[0], ends[1], inside
    # kept for the next slab (grown ones too), unless large: a long-lived thread would hold them
    _SCRATCH.out = (verts, faces) if verts.nbytes + faces.nbytes <= KEEP_BUFFER_BYTES else None
    return verts[:nv].copy(), faces[:nf].copy(), ends[0], ends[1], inside


@njit(cache=True, nogil=True)
def _mesh_slab(F, k0, origin, spacing, caps, weights_z, weights_y, weights_x, trap_x, eta, thr, verts, faces, E,
               xe, ye, ze, touched, sv, ts, nt, nts, inb, in64, sq64, rowcnt, acol, acase, arow, tab,
               caps_on, heads):
    """:func:`mesh_slab` with its buffers and scratch given (see there and :func:`_scratch`): ``E`` and
    ``sv`` all -1 (and left so), ``nt``, ``nts`` (lengths of the touched lists of ``E``: slot 0,
    1, z-edges, and of ``sv``: slot 0, 1) and ``caps_on`` zero; ``verts``, ``faces`` grow as needed.

    The passes per plane: classify it (:func:`_classify_plane`), list the
    active cubes of the layer below it with their exact triangle count
    (:func:`_layer_active`), make room, emit (:func:`_emit_cubes`,
    :func:`_emit_caps`). ``heads`` gets ``nv`` after the first layer and ``nf`` after the second.
    Returns ``(verts, faces, nv, nf, inside_weight, seam0, seam1)``: the first ``nv`` and
    ``nf`` rows of the (possibly grown) buffers are the mesh, ``seamE`` the first (0) and last (1)
    plane's vertices (:func:`_seam`).
    """
    nzp, ny, nx = F.shape
    plane = ny * nx
    Ff = F.reshape(nzp * plane)
    any_side_cap = caps[0] or caps[1] or caps[2] or caps[3]
    # counters typed from a shape, not the literal 0: a literal argument makes numba compile the
    # callees (_emit_cubes, _emit_caps) twice, once for Literal[int](0), once for int64
    nv = F.shape[0] * 0
    nf = F.shape[0] * 0
    max_sq_tris = 0
    for c in range(SQUARE_COUNT.shape[0]):
        max_sq_tris = max(max_sq_tris, SQUARE_COUNT[c])
    inside_w = 0.0
    seam0 = np.empty((2, 0), np.int64)
    seam1 = seam0

    for kk in range(nzp):
        p = kk & 1
        _reset(E, touched, nt, p)
        _reset(sv[p], ts, nts, p)
        q = p ^ 1
        w = _classify_plane(F, kk, p, thr, inb, in64, sq64, rowcnt, weights_x, weights_y, trap_x)
        if weights_z[kk] != 0.0:
            inside_w += weights_z[kk] * w
        if kk == 0:
            continue
        kq = kk - 1
        _reset(E, touched, nt, 2)
        na, n_cube_tris = _layer_active(p, q, nx, rowcnt, sq64, acol, acase, arow)
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
        _edge_tables(kk, p, q, nx, plane, tab)
        nv, nf = _emit_cubes(Ff, k0, eta, acol, acase, arow, nx, tab, E, touched, nt, verts, faces, nv, nf, origin, spacing)
        if nsq > 0:
            nv, nf = _emit_caps(kk, k0, p, q, nx, inb, caps_on, xe, ye, ze, sv, ts, nts, verts, faces,
                                nv, nf, origin, spacing)
        if kq == 0:
            seam0 = _seam(E, touched, nt, sv, ts, nts, q, plane)
            heads[0] = nv    # the first layer's end: later vertices are not on the first plane
        if kk <= 2:
            heads[1] = nf    # the second layer's end: later faces use only vertices made after the first layer
        if kk == nzp - 1:
            seam1 = _seam(E, touched, nt, sv, ts, nts, p, plane)
    for lst in range(3):   # leave the reused scratch as found: all ids -1
        _reset(E, touched, nt, lst)
    for slot in range(2):
        _reset(sv[slot], ts, nts, slot)
    return verts, faces, nv, nf, inside_w, seam0, seam1


@njit(cache=True, nogil=True)
def _reset(ids, touched, nt, lst):
    """Set the entries ``touched[lst, :nt[lst]]`` of ``ids`` back to -1 and empty that list."""
    for t in range(nt[lst]):
        ids[touched[lst, t]] = -1
    nt[lst] = 0


@njit(cache=True, nogil=True)
def _seam(E, touched, nt, sv, ts, nts, slot, plane):
    """The vertices of plane slot ``slot`` (x-edges, y-edges, samples): ``(2, n)``, row 0 keys, row 1 ids.

    Read from the slot's touched lists (not the whole plane).
    """
    dst = np.empty((2, nt[slot] + nts[slot]), np.int64)
    n = 0
    for t in range(nt[slot]):
        idx = touched[slot, t]
        kind = 0 if idx < 2 * plane else 1
        dst[0, n] = kind * plane + idx - (2 * kind + slot) * plane
        dst[1, n] = E[idx]
        n += 1
    for t in range(nts[slot]):
        cell = ts[slot, t]
        dst[0, n] = 2 * plane + cell
        dst[1, n] = sv[slot, cell]
        n += 1
    return dst


def _out_buffers(nv, nf, out=None):
    """Buffers for ``nv`` vertices, ``nf`` faces: ``out`` or this thread's (warm pages), new where too small."""
    v, f = (getattr(_SCRATCH, "out", None) or (None, None)) if out is None else out
    if v is None or v.shape[0] < nv:
        v = np.empty((nv, 3), np.float64)
    if f is None or f.shape[0] < nf:
        f = np.empty((nf, 3), np.int32)
    return v, f


def compile_caps() -> None:
    """Compile :func:`_emit_caps` for the one signature :func:`_mesh_slab` calls it with (fills numba's cache).

    For the first run's background helper (:mod:`porecad.first_run`): the
    job then loads it while compiling the rest of marching cubes.
    """
    from numba import types as T

    i64, u8_3, b_1 = T.int64, T.uint8[:, :, ::1], T.boolean[::1]
    i32_1, i32_2, i64_1 = T.int32[::1], T.int32[:, ::1], T.int64[::1]
    f64_1, f64_2 = T.float64[::1], T.float64[:, ::1]
    _emit_caps.compile((i64, i64, i64, i64, i64, u8_3, b_1, i32_2, i32_2, i32_1, i32_2, i32_2, i64_1, f64_2,
                        i32_2, i64, i64, f64_1, f64_1))
