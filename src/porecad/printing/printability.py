"""Printability of a part against a printer: thin walls, narrow channels, closed pores, mid-air starts, overhangs.

Walls, channels and closed pores are judged on a voxel model of the part
(:func:`check_layers`, voxel about a third of the smallest limit, a band of
layers at a time: :mod:`porecad.printing.banded`; bounded by time, not
memory): a wall is thin where no ball of the printer's minimum feature fits
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

from ..findings import Finding

#: the most voxels of the checks' model (the voxel grows to fit; beyond, the ``check-coarse`` caveat): judged a band
#: at a time in bounded memory (:mod:`porecad.printing.banded`), at about 1 µs of CPU per voxel for walls and channels
MAX_CHECK_VOXELS = 250_000_000
#: the most voxels of the whole model a field's proxy mesh (overhangs, orientation) is made from
MAX_MODEL_VOXELS = 20_000_000
#: voxels across the printer's smallest limit that the wall and channel checks need
SAMPLES_ACROSS_LIMIT = 3


def check_layers(layers, shape, lo, voxel: float, printer, pixel: float = 0.0, progress=None) -> tuple[list, dict]:
    """Findings of a voxel model that arrives a layer at a time (bool ``(ny, nx)``, True = material; padded with
    void; ``shape`` ``(n_layers, ny, nx)``, cubic ``voxel``, corner ``lo``) and their numbers.

    ``pixel``: the print's; the checks need no voxel finer than it (see :func:`_coarse`)."""
    from .banded import judge
    lo = np.asarray(lo, dtype=float)

    def where(row):  # a piece's centre (voxel z, y, x) -> mm (x, y, z)
        return [round(float(lo[a] + (row[3 - a] + 0.5) * voxel), 4) for a in range(3)]

    def counted(stream):
        for k, layer in enumerate(stream):
            if progress is not None and ((k + 1) % 64 == 0 or k + 1 == shape[0]):
                progress("printability", k + 1, shape[0])
            yield layer

    found = judge(counted(layers), shape, voxel, printer.min_feature / 2, printer.min_channel / 2)
    vol = voxel ** 3
    void = found["void"]
    void_voxels = float(void[:, 0].sum())
    findings, info = [], {"voxel": voxel, "voxels": int(np.prod(shape)),
                          "solid_voxels": int(np.prod(shape) - void_voxels)}
    for kind, code, limit, total in (("wall", "thin-wall", printer.min_feature, np.prod(shape) - void_voxels),
                                     ("channel", "narrow-channel", printer.min_channel, void_voxels)):
        rows = found.get(code, np.zeros((0, 7)))
        info[code] = [{"at": where(r), "volume": float(r[0]) * vol, "thickness": float(r[5])} for r in rows]
        if len(rows):
            frac = float(rows[:, 0].sum()) / max(float(total), 1e-30)
            findings.append(Finding(code, f"{len(rows)} {kind}{'s' if len(rows) > 1 else ''} narrower than the "
                                          f"printer's {limit:g} mm ({100 * frac:.2f} % of the "
                                          f"{'solid' if kind == 'wall' else 'pore space'}), "
                                          f"the first at {info[code][0]['at']} mm",
                                    {"count": len(rows), "limit": limit, "volume": float(rows[:, 0].sum()) * vol,
                                     "fraction": frac, "at": [p["at"] for p in info[code]]}))
    findings += _coarse(voxel, printer, pixel)
    closed = void[void[:, 6] == 0]
    cav = [{"at": where(r), "volume": float(r[0]) * vol} for r in closed]
    if cav:
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
                                    f"{need:.3g} mm the printer's {min(limits):g} mm limit needs (the checks are "
                                    f"bounded to {MAX_CHECK_VOXELS:,} voxels for their time): thinner ones may have "
                                    "gone unfound",
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


def overhangs(vertices, faces, max_overhang: float, floor: float, up=(0.0, 0.0, 1.0), facets=None,
              by_angle: bool = True) -> dict:
    """Down-facing area by angle from the horizontal and the unsupported area (triangles above ``floor``).

    ``up``: the build direction (a unit vector; heights and ``floor`` are measured along it), so that one
    mesh is judged in any orientation without rotating it; ``facets``: its :func:`mesh_facets`, when made
    already; ``by_angle`` False: the unsupported area only (ranking orientations).
    """
    n, area, centre = facets if facets is not None else mesh_facets(vertices, faces)
    up = np.asarray(up, dtype=np.float64)
    nz = (n @ up) / np.maximum(2 * area, 1e-300)
    down = (nz < -1e-9) & (centre @ up > floor)
    out = {"unsupported_area": float(area[down & (-nz > np.sin(np.radians(max_overhang)) - 1e-9)].sum())}
    if by_angle:
        angle = np.degrees(np.arccos(np.clip(-nz[down], -1, 1)))  # 0: a flat ceiling, 90: a vertical wall
        hist, _ = np.histogram(angle, bins=OVERHANG_BINS, weights=area[down])
        out = {"bins_deg": list(OVERHANG_BINS), "area_by_angle": [float(a) for a in hist], **out}
    return out


def mesh_facets(vertices, faces):
    """``(normals (F, 3) of length twice the area, areas (F,), centroids (F, 3))`` of a triangle mesh."""
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n, 0.5 * np.linalg.norm(n, axis=1), tri.mean(axis=1)
