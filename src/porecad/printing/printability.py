"""Printability of a part against a printer: thin walls, narrow channels, closed pores, mid-air starts, overhangs.

Walls, channels and closed pores are judged on a voxel model of the part
(:func:`check_volume`, voxel about a third of the smallest limit, bounded in
size): a wall is thin where no ball of the printer's minimum feature fits
(the morphological opening of the solid by that ball leaves it out) and
the left-out piece reaches farther than the ball's radius from what the
ball covers (the slivers an opening always leaves at convex edges and
corners reach at most 0.73 of the radius, so they are not counted); a
channel is narrow likewise on the void with the minimum drainable channel;
a pore is closed when its void has no face-connected path out of the part.

Mid-air starts are found on the print layers themselves
(:class:`IslandTracker`): a connected piece of a layer that rests on no
solid of the layer below is the first layer of a piece that needs supports.

Overhangs come from a triangle mesh of the part: the area of down-facing
triangles by their angle from the horizontal, and the unsupported area
(steeper than the printer's maximum overhang from vertical, above the
first layer).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..findings import Finding

#: the most voxels of the check model (the voxel grows to fit): about 64 bytes and 1.4 µs of CPU per voxel for the
#: wall and channel checks together (12.5 M voxels: 0.8 GB, 17 s), so at most about 1.3 GB and half a minute
MAX_CHECK_VOXELS = 20_000_000
#: voxels across the printer's smallest limit that the wall and channel checks need
SAMPLES_ACROSS_LIMIT = 3


def _thin(mask: np.ndarray, radius: float, voxel: float):
    """Components of ``mask`` where no ball of ``radius`` fits and that reach beyond ``radius`` from the rest."""
    if radius <= 0 or not mask.any():
        return []
    dt = ndimage.distance_transform_edt(mask) * voxel
    centres = dt > radius
    if centres.any():
        covered = ndimage.distance_transform_edt(~centres) * voxel <= radius
        reach = ndimage.distance_transform_edt(~covered) * voxel
    else:
        reach = np.full(mask.shape, np.inf)
    thin = mask & ~(centres | (reach == 0))
    labels, n = ndimage.label(thin, structure=np.ones((3, 3, 3)))
    out = []
    if n == 0:
        return out
    idx = np.arange(1, n + 1)
    far = ndimage.maximum(np.where(np.isinf(reach), 1e30, reach), labels, idx)
    counts = ndimage.sum(thin, labels, idx)
    coms = ndimage.center_of_mass(thin, labels, idx)
    width = ndimage.maximum(dt, labels, idx)
    for i in range(n):
        if far[i] > radius * 1.0 + voxel:
            out.append({"voxels": int(counts[i]), "centre": coms[i], "thickness": float(2 * width[i])})
    return out


def check_volume(solid: np.ndarray, lo, voxel: float, printer, pixel: float = 0.0) -> tuple[list, dict]:
    """Findings of a voxel model ``solid`` (z, y, x; True = material; padded with void) and their numbers.

    ``pixel``: the print's; the checks need no voxel finer than it (see :func:`_coarse`)."""
    lo = np.asarray(lo, dtype=float)

    def where(c):  # voxel index (z, y, x) -> mm (x, y, z)
        return [round(float(lo[a] + (c[2 - a] + 0.5) * voxel), 4) for a in range(3)]
    findings, info = [], {"voxel": voxel, "solid_voxels": int(solid.sum())}
    vol = voxel ** 3
    for kind, mask, limit, code in (("wall", solid, printer.min_feature, "thin-wall"),
                                    ("channel", ~solid, printer.min_channel, "narrow-channel")):
        parts = _thin(mask, limit / 2, voxel)
        info[code] = [{"at": where(p["centre"]), "volume": p["voxels"] * vol, "thickness": p["thickness"]}
                      for p in parts]
        if parts:
            total = sum(p["voxels"] for p in parts) * vol
            frac = total / max(float(mask.sum()) * vol, 1e-30)
            findings.append(Finding(code, f"{len(parts)} {kind}{'s' if len(parts) > 1 else ''} narrower than the "
                                          f"printer's {limit:g} mm ({100 * frac:.2f} % of the {'solid' if kind == 'wall' else 'pore space'}), "
                                          f"the first at {info[code][0]['at']} mm",
                                    {"count": len(parts), "limit": limit, "volume": total, "fraction": frac,
                                     "at": [p["at"] for p in info[code]]}))
    findings += _coarse(voxel, printer, pixel)
    labels, n = ndimage.label(~solid)
    outside = np.unique(np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(),
                                        labels[:, :, [0, -1]].ravel()]))
    closed = [i for i in range(1, n + 1) if i not in set(outside.tolist())]
    cav = []
    if closed:
        coms = ndimage.center_of_mass(~solid, labels, closed)
        sizes = ndimage.sum(~solid, labels, closed)
        cav = [{"at": where(c), "volume": float(s) * vol} for c, s in zip(coms, sizes)]
        findings.append(Finding("closed-pore", f"{len(cav)} closed pore{'s' if len(cav) > 1 else ''} trap resin or "
                                               f"powder (the first at {cav[0]['at']} mm, {cav[0]['volume']:.3g} mm³)",
                                {"count": len(cav), "volume": sum(c["volume"] for c in cav),
                                 "at": [c["at"] for c in cav]}))
    info["closed-pore"] = cav
    return findings, info


def _coarse(voxel: float, printer, pixel: float) -> list:
    """The ``check-coarse`` caveat when the model's voxel is coarser than the limits need (a third of the smallest,
    or the print's own pixel where that is coarser): then finding no thin wall or narrow channel does not mean
    there is none."""
    limits = [x for x in (printer.min_feature, printer.min_channel) if x > 0]
    need = max(min(limits, default=0.0) / SAMPLES_ACROSS_LIMIT, float(pixel))
    if not limits or voxel <= need * (1 + 1e-9):
        return []
    return [Finding("check-coarse", f"walls and channels were checked on {voxel:.3g} mm voxels, coarser than the "
                                    f"{need:.3g} mm the printer's {min(limits):g} mm limit needs (the model is "
                                    f"bounded to {MAX_CHECK_VOXELS:,} voxels): thinner ones may have gone unfound",
                    {"voxel": voxel, "needed": need, "limit": min(limits)})]


class IslandTracker:
    """Mid-air starts on the print layers: pieces of a layer with no solid under them (layer 0 rests on the plate)."""

    def __init__(self, grid, min_area: float | None = None):
        self.grid = grid
        self.starts = []
        self.min_pixels = max(1, int((min_area or 0) / (grid.px * grid.py)))

    def add(self, k: int, found):
        """Record layer ``k``'s pieces resting on nothing: ``(counts, row, column)`` of :func:`_kernels.new_islands`."""
        if found is None:
            return
        g = self.grid
        for n, cy, cx in zip(*found):
            if n >= self.min_pixels:
                self.starts.append({"layer": int(k), "z": round(float(g.z(k) - g.layer / 2), 6),
                                    "area": float(n) * g.px * g.py,
                                    "at": [round(float(g.lo[0] + (cx + 0.5) * g.px), 4),
                                           round(float(g.lo[1] + (cy + 0.5) * g.py), 4)]})

    def findings(self) -> list:
        if not self.starts:
            return []
        s = self.starts
        return [Finding("mid-air-start", f"{len(s)} piece{'s' if len(s) > 1 else ''} of the part start{'' if len(s) > 1 else 's'} "
                                         f"in mid-air and need supports (the first at z = {s[0]['z']:g} mm, "
                                         f"{s[0]['area']:.3g} mm²)",
                        {"count": len(s), "z": [x["z"] for x in s], "area": [x["area"] for x in s],
                         "at": [x["at"] for x in s]})]


#: the bins of the overhang report: angle of a down-facing surface from the horizontal (degrees)
OVERHANG_BINS = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0)


def overhangs(vertices, faces, max_overhang: float, floor: float) -> dict:
    """Down-facing area by angle from the horizontal and the unsupported area (triangles above ``floor``)."""
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    nz = n[:, 2] / np.maximum(2 * area, 1e-300)
    zc = tri[:, :, 2].mean(axis=1)
    down = (nz < -1e-9) & (zc > floor)
    angle = np.degrees(np.arccos(np.clip(-nz, -1, 1)))  # 0: a flat ceiling, 90: a vertical wall
    hist, _ = np.histogram(angle[down], bins=OVERHANG_BINS, weights=area[down])
    unsupported = float(area[down & (-nz > np.sin(np.radians(max_overhang)) - 1e-9)].sum())
    return {"bins_deg": list(OVERHANG_BINS), "area_by_angle": [float(a) for a in hist],
            "unsupported_area": unsupported}
