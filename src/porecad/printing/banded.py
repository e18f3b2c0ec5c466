"""Walls, channels and closed pores found a band of layers at a time: memory bounded by a band, not by the part.

A voxel model of a 100 mm part at a third of a 0.3 mm limit has 10⁹ voxels:
judged whole, it must be made coarse (and then finds nothing). Here the model
arrives layer by layer and is judged in bands (:func:`judge`). Each band's
*core* of layers is judged with a *halo* of layers above and below, wide
enough (:func:`halo`) that every distance the checks use is exact in the
core: the distance to the other phase up to the ball's radius ``r``, the
cover of the ball centres within ``r`` of those, and the reach beyond that
cover up to ``r`` and a voxel — ``3 r`` and two voxels in all.

The pieces found in each core — thin parts (:func:`thin_mask`), connected
through faces, edges and corners, and void, connected through faces — take
new ids; the ids of pieces that touch across a seam between two cores are
joined by union-find (:class:`Pieces`), which sums their voxels and
centres, keeps whether any voxel reaches beyond the cover, the largest
width, and whether a void piece touches the model's boundary (else it is a
closed pore).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from ..mesh.union_find import Forest

#: voxels a band's window (core and halos) may hold: about 40 bytes each while it is judged
WINDOW_VOXELS = 16_000_000
_ALL = np.ones((3, 3, 3), bool)


def halo(radius: float, voxel: float) -> int:
    """Layers above and below a core that make its distances exact (module docstring)."""
    return int(math.ceil(3 * radius / voxel)) + 2


def ball(radius: float) -> np.ndarray:
    """The voxels within ``radius`` (in voxels) of the centre one, as a footprint."""
    k = int(math.floor(radius + 1e-9))
    g = np.mgrid[-k:k + 1, -k:k + 1, -k:k + 1]
    return (g ** 2).sum(axis=0) <= radius * radius + 1e-9


def thin_mask(mask: np.ndarray, radius: float, voxel: float):
    """``(thin, far)``: where no ball of ``radius`` (mm) fits in ``mask`` (out of the balls' cover), and where
    that is farther than the radius and a voxel from the cover.

    By morphology with ball footprints, exactly the distance tests ``d > r`` (a ball's centre: no other phase
    within ``r``), ``d ≤ r`` (covered) and ``d > r + voxel`` (far) on the voxel centres; the radii are a few
    voxels (a third of the limit is the voxel), so three small footprints cost less than three distance
    transforms. Beyond the array the phase goes on (as a distance transform sees it)."""
    r = radius / voxel
    centres = ndimage.binary_erosion(mask, ball(r), border_value=1)
    covered = ndimage.binary_dilation(centres, ball(r))
    thin = mask & ~covered
    far = thin & ~ndimage.binary_dilation(covered, ball(r + 1.0)) if thin.any() else thin
    return thin, far


def widths(mask: np.ndarray, labels: np.ndarray, n: int, offset: int, voxel: float) -> np.ndarray:
    """Twice the largest distance to the other phase over each piece of ``labels`` (which start at layer
    ``offset`` of ``mask``): the distance transform only around each piece."""
    out = np.zeros(n)
    m = 3
    for i, sl in enumerate(ndimage.find_objects(labels)):
        if sl is None:
            continue
        box = tuple(slice(max(0, a.start + (offset if j == 0 else 0) - m), a.stop + (offset if j == 0 else 0) + m)
                    for j, a in enumerate(sl))
        dt = ndimage.distance_transform_edt(mask[box]) * voxel
        inner = tuple(slice(a.start + (offset if j == 0 else 0) - b.start, a.stop + (offset if j == 0 else 0) - b.start)
                      for j, (a, b) in enumerate(zip(sl, box)))
        out[i] = 2 * float(dt[inner][labels[sl] == i + 1].max())
    return out


class Pieces:
    """Pieces of all bands by id, joined across seams (union-find), with their sums (module docstring)."""

    def __init__(self):
        self.forest = Forest()
        self.stats = np.zeros((0, 7))  # voxels, sum z, sum y, sum x, far, width, touches the boundary

    def add(self, labels: np.ndarray, n: int, k0: int, far=None, width=None, boundary=None) -> int:
        """The ``n`` pieces of a core's ``labels`` (its first layer is layer ``k0``): ``far`` and ``boundary``
        masks (any voxel of a piece in them counts), ``width`` one value per piece. Returns their first id."""
        z, y, x = np.nonzero(labels)
        lab = labels[z, y, x]
        st = np.zeros((n, 7))
        st[:, 0] = np.bincount(lab, minlength=n + 1)[1:]
        for j, c in ((1, z + k0), (2, y), (3, x)):
            st[:, j] = np.bincount(lab, weights=c, minlength=n + 1)[1:]
        for j, m in ((4, far), (6, boundary)):
            if m is not None:
                st[:, j] = np.bincount(lab, weights=m[z, y, x], minlength=n + 1)[1:] > 0
        if width is not None:
            st[:, 5] = width
        base = self.forest.grow(n)
        self.stats = np.concatenate([self.stats, st])
        return base

    def merged(self) -> np.ndarray:
        """One row of stats per joined piece (voxels, centre z, y, x in voxels, far, width, boundary)."""
        if not len(self.forest):
            return np.zeros((0, 7))
        roots = self.forest.roots()
        keys, inv = np.unique(roots, return_inverse=True)
        out = np.zeros((len(keys), 7))
        for j in range(4):
            np.add.at(out[:, j], inv, self.stats[:, j])
        for j in (4, 5, 6):
            np.maximum.at(out[:, j], inv, self.stats[:, j])
        out[:, 1:4] /= np.maximum(out[:, :1], 1)
        return out


def _seam_pairs(prev: np.ndarray, cur: np.ndarray, corners: bool):
    """Id pairs of pieces that touch across a seam (``prev``: the last layer's ids, ``cur``: the next one's)."""
    pairs = []
    shifts = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)] if corners else [(0, 0)]
    ny, nx = cur.shape
    for dy, dx in shifts:
        a = prev[max(0, -dy): ny - max(0, dy), max(0, -dx): nx - max(0, dx)]
        b = cur[max(0, dy): ny - max(0, -dy), max(0, dx): nx - max(0, -dx)]
        ok = (a >= 0) & (b >= 0)
        pairs.append(np.stack([a[ok], b[ok]]))
    p = np.unique(np.concatenate(pairs, axis=1), axis=1)
    return p[0], p[1]


class _Check:
    """One phase's thin parts, or the void's pieces: a core at a time (``radius`` None: the void's pieces)."""

    def __init__(self, radius, voxel, void: bool):
        self.radius, self.voxel, self.void = radius, voxel, void
        self.pieces = Pieces()
        self.last = None  # the previous core's last layer, as global ids (-1: none)

    def core(self, window: np.ndarray, c0: int, c1: int, k0: int, n_layers: int):
        """Judge the core ``window[c0:c1]`` (layers ``k0`` ...) of a window of solid layers."""
        mask = ~window if self.void else window
        if self.radius is None:
            sub = mask[c0:c1]
            labels, n = ndimage.label(sub)
            edge = np.zeros(sub.shape, bool)
            edge[:, [0, -1], :] = edge[:, :, [0, -1]] = True
            edge[0] |= k0 == 0
            edge[-1] |= k0 + len(sub) == n_layers
            base = self.pieces.add(labels, n, k0, boundary=edge)
        else:
            thin, far = thin_mask(mask, self.radius, self.voxel)
            labels, n = ndimage.label(thin[c0:c1], structure=_ALL)
            base = self.pieces.add(labels, n, k0, far=far[c0:c1], width=widths(mask, labels, n, c0, self.voxel))
        ids = np.where(labels > 0, labels - 1 + base, -1)
        if self.last is not None and n:
            self.pieces.forest.join(*_seam_pairs(self.last, ids[0], corners=self.radius is not None))
        self.last = ids[-1]


def judge(layers, shape, voxel: float, wall: float, channel: float):
    """Thin walls, narrow channels and the void's pieces of a model that arrives a layer at a time.

    ``layers`` yields the model's solid layers (bool ``(ny, nx)``) in order, ``shape`` is
    ``(n_layers, ny, nx)``; ``wall`` and ``channel`` are the balls' radii (0: not checked). Returns a dict of
    :meth:`Pieces.merged` rows: ``"thin-wall"`` and ``"narrow-channel"`` (those reaching beyond the radius
    and a voxel from the cover: column 4 set) and ``"void"``.
    """
    n, ny, nx = shape
    checks = {"void": _Check(None, voxel, True)}
    if wall > 0:
        checks["thin-wall"] = _Check(wall, voxel, False)
    if channel > 0:
        checks["narrow-channel"] = _Check(channel, voxel, True)
    h = max([halo(r, voxel) for r in (wall, channel) if r > 0], default=0)
    band = max(h, WINDOW_VOXELS // max(ny * nx, 1) - 2 * h, 1)
    buf, first, done = [], 0, 0  # layers first .. first + len(buf) - 1 are held; cores below done are judged
    for k, layer in enumerate(layers):
        buf.append(np.asarray(layer, bool))
        while done < n and k + 1 >= min(n, done + band + h):  # the next core and its upper halo are in
            c1 = min(n, done + band)
            window = _window(buf, first, done, c1, h, n, (ny, nx))
            for chk in checks.values():
                chk.core(window, h, h + c1 - done, done, n)
            done = c1
            keep = max(0, done - h)
            buf, first = buf[keep - first:], keep
    out = {}
    for name, chk in checks.items():
        rows = chk.pieces.merged()
        if name != "void":
            rows = rows[rows[:, 4] > 0]
        out[name] = rows
    return out


def _window(buf, first, c0, c1, h, n, plane):
    """Layers ``c0 - h`` .. ``c1 + h`` (void beyond the model's layers) from ``buf`` (layers ``first`` ...)."""
    out = np.zeros((c1 - c0 + 2 * h, *plane), bool)
    for i, k in enumerate(range(c0 - h, c1 + h)):
        if 0 <= k < n and k - first < len(buf):
            out[i] = buf[k - first]
    return out
