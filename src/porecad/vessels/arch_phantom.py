"""An aortic-arch CT phantom: the shortcut through the heart and the spine (issue 55).

The failure it reproduces: on a thoracic contrast CT the aortic root meets
the contrast-filled heart and the descending aorta lies against the
vertebrae, all as bright as the lumen, so a minimal path between the two
ends of the aorta can leave the vessel, cross the heart and the spine and
never climb the arch. :func:`arch_phantom` builds, in Hounsfield units and
ITK's LPS frame (x left, y posterior, z superior), for a vessel radius ``r``:

* the **aorta** (300 HU): the ascending aorta from its root at
  ``(−1.5 r, −2.5 r, 0)`` up to ``z = 5 r``, a half-elliptic **arch** rising
  ``3 r`` higher and crossing to ``(2.5 r, 1.5 r)``, the descending aorta
  down to ``z = −4 r`` (not symmetric under RAS ↔ LPS, so a centreline's frame
  can be told from the image);
* a **chamber** (300 HU, the heart): a capsule of radius ``2.2 r`` under the
  root, running into it by ``merge`` mm (the left ventricle's outflow is
  continuous with the aortic root: no edge between them), reaching back into
  the spine by as much;
* the **spine** (300 HU vertebral bodies of radius ``1.6 r``, 90 HU discs)
  behind the descending aorta at ``gap`` (closed by the blur);
* soft tissue (40 HU) around them (a crop of the chest); **partial volume**
  (three sub-slices per slice, in-plane blur of half a voxel), Gaussian
  **noise** — as :mod:`porecad.vessels.ct_phantom`.

Variants (for the ``path-not-tube`` check, issue 55): ``chamber_hu`` /
``bone_hu`` and ``chamber_scale`` / ``bone_scale`` (radii in vessel radii) make
the chamber and the spine brighter or larger; ``taper`` narrows the aorta
smoothly from ``r`` at the root to ``taper × r`` at its descending end (a
gradual change over many radii, not a jump); ``stenosis`` narrows it to
``(1 − stenosis) r`` at the middle of the descending part (a cosine profile
two radii long each side).

The truth: :meth:`ArchPhantom.distance` (signed distance to the true vessel
surface, a swept tube), the mask of voxel centres inside it, the centreline,
and :attr:`ArchPhantom.ends` (the two ends of the aorta, the seeds a user
would give).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from .ct_phantom import BLOOD, BONE, DISC, TISSUE, bone_distances, render_ct
from .graph import CentrelineGraph
from .local_fields import tube_distance

#: the ascending aorta's height and the arch's rise above it, in vessel radii
ASCENT, RISE = 5.0, 3.0


@dataclass
class ArchPhantom:
    array: np.ndarray          # (nx, ny, nz) int16 HU, indexed [i, j, k]
    geometry: dict             # spacing, origin, direction (LPS, identity)
    axis: tuple                # (points, radii) of the aorta's centreline (LPS mm)
    chamber: tuple             # (points, radii) of the chamber's capsule
    bone: dict                 # the spine: axis points, radius, vertebra/disc heights
    mask: np.ndarray           # voxel centres inside the true vessel

    @property
    def graph(self) -> CentrelineGraph:
        P, R = self.axis
        n = len(P)
        return CentrelineGraph(P.copy(), R.copy(), np.stack([np.arange(n - 1), np.arange(1, n)], 1),
                               source="arch-phantom")

    @property
    def ends(self) -> np.ndarray:
        """The root and the descending end of the aorta, half a radius inside (mm, LPS)."""
        P, R = self.axis
        return np.stack([P[0] + [0, 0, 0.5 * R[0]], P[-1] + [0, 0, 0.5 * R[-1]]])

    def distance(self, points) -> np.ndarray:
        """Signed distance (mm) of ``points (N, 3)`` to the true vessel surface (negative inside)."""
        return tube_distance(np.asarray(points, float).reshape(-1, 3), *self.axis)


def arch_axis(r: float, step: float = 1.0, taper: float = 1.0, stenosis: float = 0.0):
    """The aorta's centreline (points every ~``step`` mm, radius ``r``): ascending, arch, descending; radii
    tapering to ``taper × r`` and narrowed by ``stenosis`` (module docstring)."""
    def line(a, b):
        n = max(2, int(np.ceil(np.linalg.norm(np.subtract(b, a)) / step)) + 1)
        return np.linspace(a, b, n)
    a0, a1 = np.array([-1.5 * r, -2.5 * r]), np.array([2.5 * r, 1.5 * r])
    asc = line([*a0, 0.0], [*a0, ASCENT * r])
    m = max(8, int(np.ceil(np.pi * 2.7 * r / step)) + 1)
    th = np.linspace(0.0, np.pi, m)
    xy = 0.5 * (a0 + a1) + np.cos(th)[:, None] * 0.5 * (a0 - a1)
    arch = np.column_stack([xy, ASCENT * r + RISE * r * np.sin(th)])
    desc = line([2.5 * r, 1.5 * r, ASCENT * r], [2.5 * r, 1.5 * r, -4.0 * r])
    P = np.concatenate([asc, arch[1:], desc[1:]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    R = float(r) * (1.0 + (float(taper) - 1.0) * s / s[-1])
    if stenosis:
        s0 = s[-1] - 0.5 * np.linalg.norm(desc[-1] - desc[0])      # the middle of the descending part
        u = np.clip(np.abs(s - s0) / (2.0 * r), 0.0, 1.0)
        R = R * (1.0 - float(stenosis) * np.cos(0.5 * np.pi * u) ** 2)
    return P, R


def _scene(r: float, gap: float, merge: float, chamber_scale: float = 2.2, bone_scale: float = 1.6):
    rb = bone_scale * r
    z = np.linspace(-8.0 * r, (ASCENT + RISE + 2.0) * r, 18)
    spine = np.stack([np.full_like(z, 2.5 * r), np.full_like(z, 1.5 * r + r + gap + rb), z], 1)
    bone = {"axis": spine, "radius": rb, "s_axis": 2, "height": 2.0 * r + 4.0, "disc": 5.0}
    rc = chamber_scale * r
    zc = -r + merge - rc
    c2 = np.array([-1.5 * r, 3.5 * r, zc])
    # the chamber's far end runs into the spine by the same depth
    d = np.hypot(*(spine[0, :2] - c2[:2]))
    u = (spine[0, :2] - c2[:2]) / d
    c2[:2] += u * (d - rb + merge - rc)
    chamber = (np.array([[-1.5 * r, -2.5 * r, zc], c2]), np.full(2, rc))
    return bone, chamber


def arch_phantom(radius: float = 6.0, spacing=(1.0, 1.0, 1.5), gap: float = 0.5, merge: float = 1.0,
                 noise: float = 20.0, seed: int = 0, margin: float = 4.0, chamber_hu: float = BLOOD,
                 bone_hu: float = BONE, chamber_scale: float = 2.2, bone_scale: float = 1.6, taper: float = 1.0,
                 stenosis: float = 0.0) -> ArchPhantom:
    """The arch phantom (module docstring) on an image just holding the scene; deterministic for a ``seed``."""
    r = float(radius)
    h = np.asarray(spacing, float)
    P, R = arch_axis(r, taper=taper, stenosis=stenosis)
    bone, chamber = _scene(r, gap, merge, chamber_scale, bone_scale)
    lo = np.minimum([-4.8 * r, -4.8 * r, -6.0 * r], (chamber[0] - chamber[1][:, None]).min(0)) - margin
    hi = np.array([4.1 * r, bone["axis"][0, 1] + bone["radius"], (ASCENT + RISE + 1.0) * r]) + margin
    shape = tuple(int(v) for v in np.ceil((hi - lo) / h) + 1)
    origin = lo
    axes = [origin[a] + h[a] * np.arange(shape[a]) for a in range(3)]
    sigma = 0.5 * float(h.min())
    f = lambda dist: ndtr(-dist / sigma)  # noqa: E731

    def scene(X):
        dv = tube_distance(X, P, R)
        db, dd = bone_distances(X, bone)
        fv, fc = f(dv), f(tube_distance(X, *chamber))
        return TISSUE + np.maximum((BLOOD - TISSUE) * fv, (chamber_hu - TISSUE) * fc) \
            + (bone_hu - TISSUE) * f(db) + (DISC - TISSUE) * f(dd), dv
    arr, mask = render_ct(axes, h, scene, noise, seed)
    geo = {"spacing": h.tolist(), "origin": origin.tolist(), "direction": np.eye(3).tolist()}
    return ArchPhantom(arr, geo, (P, R), chamber, bone, mask)
