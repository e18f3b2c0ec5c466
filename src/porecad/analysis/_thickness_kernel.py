"""Numba kernels of the local-thickness analysis (:mod:`porecad.analysis.thickness`).

* :func:`propagate_closest` — closest-wall-point transform: exact closest
  points of the seed voxels are passed on to every voxel by raster sweeps
  (forward over the 13 preceding neighbours, then backward), each voxel
  keeping the candidate nearest to it (Danielsson 1980's vector propagation,
  with surface points instead of seed offsets).
* :func:`ridge_flags` — the distance ridge (Hildebrand & Rüegsegger 1997):
  voxels whose ball is not inside a neighbour's ball.
* :func:`medial_pairs` — a sub-voxel medial ball from two neighbouring voxels
  whose closest wall points face each other.
* :func:`paint_balls` — local thickness ``τ(x) = 2 max {R : x ∈ B(m, R)}``
  over a list of balls.

No kernel raises, formats strings or broadcasts arrays (each would add
seconds to the first, compiling run), and none runs threads (the exact
distance queries of :mod:`porecad.analysis._nearest_kernel` do).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the 13 neighbours that precede a voxel in raster order (k, j, i increasing)
_HALF = np.array([(dk, dj, di) for dk in (-1, 0, 1) for dj in (-1, 0, 1) for di in (-1, 0, 1)
                  if (dk, dj, di) < (0, 0, 0)], dtype=np.int64)
_ALL = np.array([(dk, dj, di) for dk in (-1, 0, 1) for dj in (-1, 0, 1) for di in (-1, 0, 1)
                 if (dk, dj, di) != (0, 0, 0)], dtype=np.int64)


@njit(cache=True, nogil=True)
def _sweep(cp, dist, origin, h, sign, half):
    nz, ny, nx = dist.shape
    changed = 0
    for kk in range(nz):
        k = kk if sign > 0 else nz - 1 - kk
        pz = origin[2] + k * h
        for jj in range(ny):
            j = jj if sign > 0 else ny - 1 - jj
            py = origin[1] + j * h
            for ii in range(nx):
                i = ii if sign > 0 else nx - 1 - ii
                px = origin[0] + i * h
                best = dist[k, j, i]
                b2 = best * best
                found = False
                bx = by = bz = 0.0
                for n in range(half.shape[0]):
                    k2 = k + sign * half[n, 0]
                    j2 = j + sign * half[n, 1]
                    i2 = i + sign * half[n, 2]
                    if k2 < 0 or k2 >= nz or j2 < 0 or j2 >= ny or i2 < 0 or i2 >= nx:
                        continue
                    if not dist[k2, j2, i2] < np.inf:
                        continue
                    cx, cy, cz = cp[k2, j2, i2, 0], cp[k2, j2, i2, 1], cp[k2, j2, i2, 2]
                    d2 = (px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2
                    if d2 < b2 * (1.0 - 1e-5):
                        b2, bx, by, bz, found = d2, cx, cy, cz, True
                if found:
                    dist[k, j, i] = math.sqrt(b2)
                    cp[k, j, i, 0], cp[k, j, i, 1], cp[k, j, i, 2] = bx, by, bz
                    changed += 1
    return changed


@njit(cache=True, nogil=True)
def propagate_closest(cp, dist, origin, h, max_rounds):
    """Pass closest wall points on until no voxel finds a nearer one (or ``max_rounds`` rounds).

    ``cp[k, j, i]`` (float32, mm) is the nearest wall point known for voxel
    ``(k, j, i)`` at ``origin + (i, j, k) h`` and ``dist`` its distance
    (``inf`` where none is known yet). Returns the number of rounds run.
    """
    # the signs typed from an argument, not literals: literal 1 and -1 would compile _sweep twice
    fwd = max_rounds * 0 + 1
    for r in range(max_rounds):
        n = _sweep(cp, dist, origin, h, fwd, _HALF) + _sweep(cp, dist, origin, h, -fwd, _HALF)
        if n == 0:
            return r + 1
    return max_rounds


@njit(cache=True, nogil=True)
def ridge_flags(phase, dist, h, tau, out):
    """``out[v] = 1`` for phase voxels whose ball is inside no neighbour's ball (with ``tau * h`` of slack).

    Ball ``B(p, D(p))`` lies in ``B(q, D(q))`` when ``D(q) >= D(p) + |p - q|``;
    the slack keeps voxels next to an oblique wall (whose neighbours along
    the normal are a lattice direction away) off the ridge. Returns the count.
    """
    nz, ny, nx = dist.shape
    count = 0
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                out[k, j, i] = 0
                if not phase[k, j, i]:
                    continue
                d = dist[k, j, i]
                inner = False
                for n in range(_ALL.shape[0]):
                    k2, j2, i2 = k + _ALL[n, 0], j + _ALL[n, 1], i + _ALL[n, 2]
                    if k2 < 0 or k2 >= nz or j2 < 0 or j2 >= ny or i2 < 0 or i2 >= nx or not phase[k2, j2, i2]:
                        continue
                    step = h * math.sqrt(_ALL[n, 0] ** 2 + _ALL[n, 1] ** 2 + _ALL[n, 2] ** 2)
                    if dist[k2, j2, i2] >= d + step - tau * h:
                        inner = True
                        break
                if not inner:
                    out[k, j, i] = 1
                    count += 1
    return count


@njit(cache=True, nogil=True)
def medial_pairs(phase, dist, cp, idx, origin, h, cos_max, centre, radius, bound):
    """Sub-voxel medial ball at each ridge voxel from the neighbour whose closest point faces its own.

    For ridge voxel ``p`` (``idx[r] = (k, j, i)``) with closest wall point
    ``s_p`` and inward normal ``n_p = (p - s_p) / |p - s_p|``, and a phase
    neighbour ``q`` with ``n_p · n_q < cos_max``, the ball tangent to the
    wall at both closest points has its centre at ``s_p + t n_p = s_q + t n_q``;
    in the least-squares sense

    .. math:: t = \\frac{(s_p - s_q)\\cdot(n_q - n_p)}{|n_q - n_p|^2}, \\qquad
              m = \\tfrac12 (s_p + s_q) + \\tfrac{t}{2} (n_p + n_q),

    exact for a slab, a cylinder and a sphere. The largest ``t`` whose centre
    lies inside ``p``'s own ball (so inside the phase) and within the
    Lipschitz bound ``t <= D(p) + |m - p|`` is kept: ``centre[r]``, the
    estimate ``radius[r]`` (0 where none) and ``bound[r]``, an upper bound of
    the true distance of ``m`` to the wall (its distance to ``s_p`` or ``s_q``)
    for the exact check the caller makes.
    """
    nz, ny, nx = dist.shape
    for r in range(idx.shape[0]):
        k, j, i = idx[r, 0], idx[r, 1], idx[r, 2]
        px, py, pz = origin[0] + i * h, origin[1] + j * h, origin[2] + k * h
        dp = dist[k, j, i]
        centre[r, 0], centre[r, 1], centre[r, 2] = px, py, pz
        radius[r] = 0.0
        bound[r] = dp
        if not dp > 0.0 or not dp < np.inf:
            continue
        sx, sy, sz = cp[k, j, i, 0], cp[k, j, i, 1], cp[k, j, i, 2]
        nxp, nyp, nzp = (px - sx) / dp, (py - sy) / dp, (pz - sz) / dp
        for n in range(_ALL.shape[0]):
            k2, j2, i2 = k + _ALL[n, 0], j + _ALL[n, 1], i + _ALL[n, 2]
            if k2 < 0 or k2 >= nz or j2 < 0 or j2 >= ny or i2 < 0 or i2 >= nx or not phase[k2, j2, i2]:
                continue
            dq = dist[k2, j2, i2]
            if not dq > 0.0 or not dq < np.inf:
                continue
            qx, qy, qz = origin[0] + i2 * h, origin[1] + j2 * h, origin[2] + k2 * h
            tx, ty, tz = cp[k2, j2, i2, 0], cp[k2, j2, i2, 1], cp[k2, j2, i2, 2]
            nxq, nyq, nzq = (qx - tx) / dq, (qy - ty) / dq, (qz - tz) / dq
            if nxp * nxq + nyp * nyq + nzp * nzq >= cos_max:
                continue
            ex, ey, ez = nxq - nxp, nyq - nyp, nzq - nzp
            e2 = ex * ex + ey * ey + ez * ez
            t = ((sx - tx) * ex + (sy - ty) * ey + (sz - tz) * ez) / e2
            if not t > radius[r] or not t > 0.0:
                continue
            mx = 0.5 * (sx + tx) + 0.5 * t * (nxp + nxq)
            my = 0.5 * (sy + ty) + 0.5 * t * (nyp + nyq)
            mz = 0.5 * (sz + tz) + 0.5 * t * (nzp + nzq)
            off = math.sqrt((mx - px) ** 2 + (my - py) ** 2 + (mz - pz) ** 2)
            if off >= dp or t > dp + off:
                continue
            ub = min(math.sqrt((mx - sx) ** 2 + (my - sy) ** 2 + (mz - sz) ** 2),
                     math.sqrt((mx - tx) ** 2 + (my - ty) ** 2 + (mz - tz) ** 2))
            centre[r, 0], centre[r, 1], centre[r, 2] = mx, my, mz
            radius[r] = t
            bound[r] = ub


@njit(cache=True, nogil=True)
def paint_balls(phase, lt, centre, radius, origin, h, slack, n_slabs):
    """``lt[x] = max(lt[x], 2 R)`` for every phase voxel ``x`` within ``R + slack`` of a ball's centre.

    Slab by slab along z (a ball visits only the slabs it meets); ``centre``
    and ``radius`` in mm. One thread: a few percent of an analysis, and a
    parallel kernel costs a second more to compile on the first run.
    """
    nz, ny, nx = lt.shape
    per = (nz + n_slabs - 1) // n_slabs
    for s in range(n_slabs):
        z0 = s * per
        z1 = min(nz, z0 + per)
        for b in range(radius.shape[0]):
            R = radius[b]
            if not R > 0.0:
                continue
            reach = R + slack
            r2 = reach * reach
            val = np.float32(2.0 * R)
            cx = (centre[b, 0] - origin[0]) / h
            cy = (centre[b, 1] - origin[1]) / h
            cz = (centre[b, 2] - origin[2]) / h
            rr = reach / h
            k0 = max(int(math.ceil(cz - rr)), z0)
            k1 = min(int(math.floor(cz + rr)), z1 - 1)
            if k0 > k1:
                continue
            j0 = max(int(math.ceil(cy - rr)), 0)
            j1 = min(int(math.floor(cy + rr)), ny - 1)
            i0 = max(int(math.ceil(cx - rr)), 0)
            i1 = min(int(math.floor(cx + rr)), nx - 1)
            for k in range(k0, k1 + 1):
                dz2 = ((k - cz) * h) ** 2
                for j in range(j0, j1 + 1):
                    dzy = dz2 + ((j - cy) * h) ** 2
                    if dzy > r2:
                        continue
                    for i in range(i0, i1 + 1):
                        if dzy + ((i - cx) * h) ** 2 <= r2 and phase[k, j, i] and lt[k, j, i] < val:
                            lt[k, j, i] = val


@njit(cache=True, nogil=True)
def prune_balls(idx, centre, radius, shape, tol, keep):
    """``keep[r] = False`` for a ball that a ball of a neighbouring voxel contains (within ``tol`` mm).

    Ball ``r`` belongs to voxel ``idx[r]``; ``B(m, R) ⊂ B(m', R' + tol)``
    when ``|m - m'| + R <= R' + tol``. Of two balls containing each other
    the one listed first stays. Painting with at least ``tol`` of slack then
    gives every voxel the same value without the pruned balls.
    """
    nz, ny, nx = shape[0], shape[1], shape[2]
    where = np.full(nz * ny * nx, -1, np.int64)
    for r in range(idx.shape[0]):
        where[(idx[r, 0] * ny + idx[r, 1]) * nx + idx[r, 2]] = r
    for r in range(idx.shape[0]):
        keep[r] = True
        k, j, i = idx[r, 0], idx[r, 1], idx[r, 2]
        R = radius[r]
        for n in range(_ALL.shape[0]):
            k2, j2, i2 = k + _ALL[n, 0], j + _ALL[n, 1], i + _ALL[n, 2]
            if k2 < 0 or k2 >= nz or j2 < 0 or j2 >= ny or i2 < 0 or i2 >= nx:
                continue
            s = where[(k2 * ny + j2) * nx + i2]
            if s < 0:
                continue
            gap = math.sqrt((centre[r, 0] - centre[s, 0]) ** 2 + (centre[r, 1] - centre[s, 1]) ** 2
                            + (centre[r, 2] - centre[s, 2]) ** 2) + R - radius[s]
            if gap <= tol and (gap < -tol or radius[s] > R or (radius[s] == R and s < r)):
                keep[r] = False
                break
