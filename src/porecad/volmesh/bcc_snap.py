"""Shrink-wrapping a BCC tet mesh onto its body: boundary vertices moved toward the surface.

Step 4 of :func:`porecad.volmesh.bcc.bcc_tet_mesh`. Every vertex of the
domain's boundary (all outside the body) moves toward its closest point on
the body surface in Gauss-Seidel passes, trying fractions of the remaining
gap; a move is accepted only if every incident tet stays positive with a
radius ratio above a floor and every incident boundary face stays outside
the body (sampled on a barycentric grid, winding number 0). Vertices only
move, so the mesh stays conforming and keeps its colouring.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from porecad.bodies import distance_kernels as K
from porecad.bodies.mesh import MeshBody
from porecad.volmesh.tetmesh import boundary_faces

__all__ = ["snap_boundary"]

#: Fractions of the remaining gap to the surface tried per snapping move.
_SNAP_FRACTIONS = np.array([1.0, 0.5, 0.25])
_SNAP_PASSES = 4
#: Samples per edge on the boundary faces checked to stay outside the body.
_SNAP_FACE_SAMPLES = 4


@njit(cache=True)
def _csr(items, n):
    """Row -> positions CSR of ``items (M, m)``: for each value ``v`` the rows holding it."""
    start = np.zeros(n + 1, np.int64)
    for r in range(items.shape[0]):
        for c in range(items.shape[1]):
            start[items[r, c] + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    pos = start[:-1].copy()
    out = np.empty(start[-1], np.int64)
    for r in range(items.shape[0]):
        for c in range(items.shape[1]):
            v = items[r, c]
            out[pos[v]] = r
            pos[v] += 1
    return start, out


@njit(cache=True)
def _tet_shape(p, t):
    """(det, radius ratio) of tet ``t`` of points ``p``; see tetmesh.tet_quality."""
    ax = p[t[1], 0] - p[t[0], 0]
    ay = p[t[1], 1] - p[t[0], 1]
    az = p[t[1], 2] - p[t[0], 2]
    bx = p[t[2], 0] - p[t[0], 0]
    by = p[t[2], 1] - p[t[0], 1]
    bz = p[t[2], 2] - p[t[0], 2]
    cx = p[t[3], 0] - p[t[0], 0]
    cy = p[t[3], 1] - p[t[0], 1]
    cz = p[t[3], 2] - p[t[0], 2]
    bcx, bcy, bcz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx
    cax, cay, caz = cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax
    abx, aby, abz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    det = ax * bcx + ay * bcy + az * bcz
    if det <= 0.0:
        return det, 0.0
    a2 = ax * ax + ay * ay + az * az
    b2 = bx * bx + by * by + bz * bz
    c2 = cx * cx + cy * cy + cz * cz
    nx = a2 * bcx + b2 * cax + c2 * abx
    ny = a2 * bcy + b2 * cay + c2 * aby
    nz = a2 * bcz + b2 * caz + c2 * abz
    # face areas: |b×c|/2 (face 0,2,3), |c×a|/2, |a×b|/2, and the face opposite p0
    dx, dy, dz = bx - ax, by - ay, bz - az
    ex, ey, ez = cx - ax, cy - ay, cz - az
    fx, fy, fz = dy * ez - dz * ey, dz * ex - dx * ez, dx * ey - dy * ex
    area = 0.5 * (math.sqrt(bcx * bcx + bcy * bcy + bcz * bcz) + math.sqrt(cax * cax + cay * cay + caz * caz)
                  + math.sqrt(abx * abx + aby * aby + abz * abz) + math.sqrt(fx * fx + fy * fy + fz * fz))
    den = area * math.sqrt(nx * nx + ny * ny + nz * nz)
    if not den > 0.0:  # a flat tet whose det underflows the products (numba raises on x / 0.0)
        return det, 0.0
    return det, 3.0 * det * det / den


@njit(cache=True)
def _winding_point(bv, bf, px, py, pz, xy_start, xy_items, x0, y0, cell, nbx, nby):
    """Winding number of one point (crossings of the +z ray, as MeshBody.winding)."""
    b = K._bin_of(px, py, x0, y0, cell, nbx, nby)
    if b < 0:
        return 0
    w = 0
    for s in range(xy_start[b], xy_start[b + 1]):
        hit, z, sg = K._crossing(bv, bf, xy_items[s], px, py)
        if hit and z > pz:
            w += sg
    return w


@njit(cache=True)
def _faces_outside(p, bfaces, vf_start, vf_items, v, m, bv, bf, xy_start, xy_items, x0, y0, cell, nbx, nby):
    """Whether the samples of every boundary face around vertex ``v`` lie outside the body.

    Samples: the barycentric grid ``(i, j, k) / m``, ``i + j + k = m``, without the corners.
    """
    for s in range(vf_start[v], vf_start[v + 1]):
        f = vf_items[s]
        a, b, c = bfaces[f, 0], bfaces[f, 1], bfaces[f, 2]
        for i in range(m + 1):
            for j in range(m + 1 - i):
                k = m - i - j
                if i == m or j == m or k == m:
                    continue
                x = (i * p[a, 0] + j * p[b, 0] + k * p[c, 0]) / m
                y = (i * p[a, 1] + j * p[b, 1] + k * p[c, 1]) / m
                z = (i * p[a, 2] + j * p[b, 2] + k * p[c, 2]) / m
                if _winding_point(bv, bf, x, y, z, xy_start, xy_items, x0, y0, cell, nbx, nby) > 0:
                    return False
    return True


@njit(cache=True)
def _snap(p, tets, vt_start, vt_items, bfaces, vf_start, vf_items, cand, fractions, passes, rr_min,
          min_gap, m, bv, bf, lo3, cell3, band, nb3, xyz_start, xyz_items, xy_start, xy_items, x0, y0, cell,
          nbx, nby):
    """Move boundary vertices toward the surface; returns the number of accepted moves per vertex."""
    moves = np.zeros(cand.shape[0], np.int64)
    for _ in range(passes):
        any_move = False
        for ci in range(cand.shape[0]):
            v = cand[ci]
            px, py, pz = p[v, 0], p[v, 1], p[v, 2]
            d2, qx, qy, qz = K._nearest_point(bv, bf, px, py, pz, lo3, cell3, nb3, xyz_start, xyz_items,
                                              band)
            if not (d2 < band * band) or d2 < min_gap * min_gap:
                continue
            for fi in range(fractions.shape[0]):
                fr = fractions[fi]
                p[v, 0] = px + fr * (qx - px)
                p[v, 1] = py + fr * (qy - py)
                p[v, 2] = pz + fr * (qz - pz)
                ok = True
                for s in range(vt_start[v], vt_start[v + 1]):
                    det, rr = _tet_shape(p, tets[vt_items[s]])
                    if det <= 0.0 or rr < rr_min:
                        ok = False
                        break
                if ok:
                    ok = _faces_outside(p, bfaces, vf_start, vf_items, v, m, bv, bf, xy_start, xy_items,
                                        x0, y0, cell, nbx, nby)
                if ok:
                    moves[ci] += 1
                    any_move = True
                    break
                p[v, 0], p[v, 1], p[v, 2] = px, py, pz
        if not any_move:
            break
    return moves


def snap_boundary(body: MeshBody, points, tets, h: float, min_radius_ratio: float):
    """Shrink-wrap the boundary vertices of a BCC tet mesh onto the body, in place.

    Takes the body (a :class:`~porecad.bodies.mesh.MeshBody` whose band
    reaches the boundary vertices), ``points (P, 3)`` (moved in place),
    positive ``tets (T, 4)``, the lattice spacing ``h`` and the quality floor
    of a move; the rule is step 4 of
    :func:`porecad.volmesh.bcc.bcc_tet_mesh`. Returns ``(boundary vertex ids,
    number of them that moved)``.
    """
    bfaces, _, _ = boundary_faces(tets)
    cand = np.unique(bfaces)
    nv = len(points)
    vt_start, vt_items = _csr(tets, nv)
    vf_start, vf_items = _csr(bfaces, nv)
    moves = _snap(points, tets, vt_start, vt_items, bfaces, vf_start, vf_items, cand, _SNAP_FRACTIONS,
                  _SNAP_PASSES, min_radius_ratio, 1e-3 * h, _SNAP_FACE_SAMPLES,
                  body.vertices, body.faces, body._lo3, body._cell3, body.band, body._nb3, body._xyz_start,
                  body._xyz_items, body._xy_start, body._xy_items, body._x0, body._y0, body._cell_xy,
                  body._nbx, body._nby)
    return cand, int(np.count_nonzero(moves))
