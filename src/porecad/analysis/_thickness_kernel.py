"""Numba kernel of the local-thickness ball propagation (:mod:`porecad.analysis.pores`)."""

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def ball_sweep(mask, h, slack, c_in, r_in, c_out, r_out):
    """One Jacobi sweep: each phase voxel adopts a neighbour's ball if that ball (grown by ``slack`` mm) contains it and is larger.

    ``c_in[k, j, i]`` holds the index (k, j, i) of the centre of the largest
    ball known to contain the voxel and ``r_in`` its radius (mm). Returns the
    number of voxels that changed.
    """
    nz, ny, nx = mask.shape
    changed = np.zeros(nz, np.int64)
    for k in prange(nz):
        for j in range(ny):
            for i in range(nx):
                if not mask[k, j, i]:
                    r_out[k, j, i] = 0.0
                    continue
                br = r_in[k, j, i]
                b0, b1, b2 = c_in[k, j, i, 0], c_in[k, j, i, 1], c_in[k, j, i, 2]
                bd2 = ((k - b0) ** 2 + (j - b1) ** 2 + (i - b2) ** 2) * h * h
                for dk in range(-1, 2):
                    kk = k + dk
                    if kk < 0 or kk >= nz:
                        continue
                    for dj in range(-1, 2):
                        jj = j + dj
                        if jj < 0 or jj >= ny:
                            continue
                        for di in range(-1, 2):
                            ii = i + di
                            if ii < 0 or ii >= nx or not mask[kk, jj, ii]:
                                continue
                            r = r_in[kk, jj, ii]
                            if r < br:
                                continue
                            c0, c1, c2 = c_in[kk, jj, ii, 0], c_in[kk, jj, ii, 1], c_in[kk, jj, ii, 2]
                            d2 = ((k - c0) ** 2 + (j - c1) ** 2 + (i - c2) ** 2) * h * h
                            # a larger ball, or an equal one centred nearer (keeps centres from drifting
                            # sideways along ties, which left voxels outside every ball they could see)
                            if d2 <= (r + slack) * (r + slack) and (r > br or d2 < bd2):
                                br, b0, b1, b2, bd2 = r, c0, c1, c2, d2
                if br != r_in[k, j, i] or b0 != c_in[k, j, i, 0] or b1 != c_in[k, j, i, 1] \
                        or b2 != c_in[k, j, i, 2]:
                    changed[k] += 1
                r_out[k, j, i] = br
                c_out[k, j, i, 0], c_out[k, j, i, 1], c_out[k, j, i, 2] = b0, b1, b2
    return changed.sum()
