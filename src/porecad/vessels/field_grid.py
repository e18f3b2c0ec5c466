"""A vessel model on a grid (document 003): its size up front, its field, and what is measured on it.

:func:`build_field` samples the lumen's implicit field (the blended union of
the centreline's segments, :mod:`porecad.vessels.model`) and, with a wall,
the layered wall (:mod:`porecad.vessels.walls`) on a regular grid, after
:func:`vessel_estimate` has sized it (:func:`vessel_area`: the surface from the
centreline). :func:`porous_layer_connectivity`, :func:`labelmap` and
:func:`wall_domain` measure that grid for the ``vessel`` job's report and
outputs (:mod:`porecad.jobs.vessel_job`).
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import ResourceError
from ..fields.blends import Blend
from ..resources import require_fits
from .walls import PorousLayer

#: the most grid samples of one vessel model
MAX_SAMPLES = 120_000_000


#: bytes per grid sample of a vessel model: the lumen's field alone, or with a wall its distance and layer values
#: too (max RSS less the base and the mesh, bench/estimates.md: lumens 13-32, a three-layer porous wall 54)
VESSEL_SAMPLE_BYTES = {"lumen": 24, "wall": 56}


def vessel_estimate(samples: float, area: float | None = None, spacing: float | None = None,
                    wall: bool | None = None) -> dict:
    """The up-front estimate of a vessel grid: :data:`VESSEL_SAMPLE_BYTES` a sample (40 when ``wall`` is not
    given) and a surface of ``area`` (mm², :func:`vessel_area`) sampled at ``spacing``, or without them four times
    the grid box's area (:data:`porecad.resources.TRIS_PER_AREA` per voxel face; 10-16 times the triangles of a
    lumen, bench/estimates.md)."""
    from ..resources import TRIS_PER_AREA, work_estimate
    if area is not None and spacing:
        tris = TRIS_PER_AREA * float(area) / float(spacing) ** 2
    else:
        tris = 4 * 6 * TRIS_PER_AREA * float(samples) ** (2 / 3)
    per = 40 if wall is None else VESSEL_SAMPLE_BYTES["wall" if wall else "lumen"]
    return work_estimate(samples, tris, sample_bytes=per)


#: area of a porous wall layer's pores per volume, per cell size (the area bound of :func:`porecad.resources.estimate`)
POROUS_AREA_PER_CELL = 4.0


def vessel_area(graph, wall=None, porous: PorousLayer | None = None) -> float:
    """The surface (mm²) a vessel model meshes, from its centreline before sampling: the lumen's tubes and open
    ends (2πrL per edge, πr² per end), or a wall's inner and outer tubes and, for a porous layer, the pores' walls
    (:data:`POROUS_AREA_PER_CELL` per cell size per mm³ of the layer). Measured 0.91-1.12 of the area meshed
    (bench/estimates.md: the tree and Y phantoms' lumens, a curved tube's three-layer wall with a G layer)."""
    p, r, e = np.asarray(graph.points, float), np.asarray(graph.radii, float), np.asarray(graph.edges)
    if not len(e):
        return 0.0
    length = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1)
    rbar = 0.5 * (r[e[:, 0]] + r[e[:, 1]])
    ends = r[graph.degrees() == 1]

    def tube(off):
        return float((2 * np.pi * (rbar + off) * length).sum() + (np.pi * (ends + off) ** 2).sum())

    if not wall:
        return tube(0.0)
    wall = [float(t) for t in wall]
    area = tube(0.0) + tube(sum(wall))
    if porous:
        k = porous.layer - 1
        if 0 <= k < len(wall):
            off = sum(wall[:k]) + wall[k] / 2
            volume = float((2 * np.pi * (rbar + off) * length).sum()) * wall[k]
            area += POROUS_AREA_PER_CELL / float(porous.cell_size) * volume
    return area


def build_field(graph, voxel: float, blend: Blend, wall=None, porous: PorousLayer | None = None, trim=False,
                segment_length=None, segment_angle=45.0, workers=1, executor="thread", local=True, timings=None,
                boundary=None, progress=None, fit="rbf", memory_limit=None):
    """Sample the vessel solid on a grid; return ``(values, grid, extras)``: ``extras`` the segments, the blend's
    reach ``c``, the lumen's field, the evaluation's figures, the estimate (s) and, with a wall, the approximate
    distance and the porous layers' values.

    ``boundary``: boundary points (pooled), or a callable ``segments -> [cloud per segment]``.
    ``progress(stage, done, total)``: per segment of the field, the stage named with its up-front estimate
    (``field ~N s``, also ``extras["estimate_s"]``).
    """
    from ..mesh.polygonise import Grid
    from .model import estimate_seconds, evaluate_grid
    from .segments import march
    from . import walls as W
    timings = {} if timings is None else timings
    h = float(voxel)
    T = float(sum(wall)) if wall else 0.0
    pad = T + blend.span + 3.0 * h
    c = pad
    lo, hi = graph.bounds()
    lo, hi = lo - (T + 3 * h), hi + (T + 3 * h)
    grid = Grid.from_box(lo, hi, spacing=h)
    if grid.n_samples > MAX_SAMPLES:
        raise ResourceError(f"the grid would have {grid.n_samples:,} samples (limit {MAX_SAMPLES:,}); "
                            "use a larger voxel")
    est = vessel_estimate(grid.n_samples, vessel_area(graph, wall, porous), h, wall=bool(wall))
    require_fits(est, memory_limit, "use a larger `voxel`", "the vessel model")
    t = time.perf_counter()
    segs = march(graph, length=segment_length, angle_deg=segment_angle, pad=pad)
    timings["march_s"] = time.perf_counter() - t
    if callable(boundary):  # one cloud per segment (the image's local segmentations)
        t = time.perf_counter()
        boundary = boundary(segs)
        timings["segmentation_s"] = time.perf_counter() - t
    t = time.perf_counter()
    stats = {}
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    est = estimate_seconds(segs, xs, ys, zs, boundary=boundary, local=local) / max(int(workers), 1)
    F = evaluate_grid(segs, graph, xs, ys, zs, c, blend, local=local, workers=workers, executor=executor,
                      stats=stats, boundary=boundary, fit=fit, progress=_stage(progress, f"field ~{est:.0f} s"))
    timings["field_s"] = time.perf_counter() - t
    extras = {"segments": segs, "c": c, "lumen": F, "eval": stats, "estimate_s": est}
    out = F
    if wall:
        t = time.perf_counter()
        d = W.approximate_distance(F, grid.spacing)
        phis = {}
        if porous:
            phis[porous.layer] = W.porous_values(porous.type, porous.cell_size, xs, ys, zs)
        out = W.wall_field(d, wall, phis)
        extras.update(distance=d, porous_values=phis)
        timings["wall_s"] = time.perf_counter() - t
    if trim:
        out = W.trim_ends(out, xs, ys, zs, graph.ends(), T)
    return out, grid, extras


def porous_layer_connectivity(d, wall, layer, phi, spacing, trim_mask=None, min_voxels: int = 27) -> dict:
    """Connected components of the material of porous layer ``layer`` on the grid (26-connectivity).

    The layer's material is ``{d_{k-1} ≤ d̃ ≤ d_k} ∩ {φ ≤ 0}`` (within the trimmed solid).
    ``components`` counts pieces of at least ``min_voxels`` samples (3³: smaller
    ones are below the grid's resolution); ``components_all`` counts every piece;
    ``largest_fraction`` is the share of the layer's material in the largest.
    """
    from scipy import ndimage
    from .walls import band
    off = np.concatenate([[0.0], np.cumsum(wall)])
    mat = (band(d, off[layer - 1], off[layer]) <= 0) & (phi <= 0)
    if trim_mask is not None:
        mat &= trim_mask
    lab, n = ndimage.label(mat, structure=np.ones((3, 3, 3)))
    sizes = np.bincount(lab.ravel())[1:] if n else np.zeros(0)
    layer_vox = int((band(d, off[layer - 1], off[layer]) <= 0).sum())
    return {"components": int((sizes >= min_voxels).sum()), "components_all": int(n),
            "largest_fraction": float(sizes.max() / sizes.sum()) if n else 0.0,
            "material_fraction": float(mat.sum() / max(layer_vox, 1))}


def labelmap(values, grid, vol) -> np.ndarray:
    """1 where the model's field (on ``grid``, LPS; trilinear) is ≤ 0 at the image's voxel centres, else 0."""
    from scipy import ndimage
    lo = np.asarray(grid.origin, float)  # values are indexed [z, y, x]
    hi = lo + (np.asarray(values.shape[::-1]) - 1) * np.asarray(grid.spacing, float)
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    ci = vol.index(corners)
    i0 = np.clip(np.floor(ci.min(0)).astype(int), 0, vol.shape - 1)
    i1 = np.clip(np.ceil(ci.max(0)).astype(int) + 1, 1, vol.shape)
    idx = np.stack(np.meshgrid(*[np.arange(i0[a], i1[a]) for a in range(3)], indexing="ij"), -1).reshape(-1, 3)
    X = (idx * vol.h) @ vol.D.T + vol.origin
    g = (X - lo) / np.asarray(grid.spacing, float)
    f = ndimage.map_coordinates(values, g[:, ::-1].T, order=1, mode="constant", cval=1.0)
    out = np.zeros(tuple(vol.shape), np.uint8)
    out[i0[0]:i1[0], i0[1]:i1[1], i0[2]:i1[2]] = (f <= 0).reshape(i1 - i0)
    return out


def wall_domain(distance, wall, ends, grid, flip=(1.0, 1.0, 1.0)):
    """The closed surface of a vessel wall without its pores (the design domain of its porous layer).

    The band ``0 ≤ d̃ ≤ T`` of the approximate distance (003 Eqs. 4.13–4.16,
    :func:`porecad.vessels.walls.wall_field` without porous layers), trimmed
    at the open ends like the model, polygonised on the model's grid.
    """
    from ..mesh.polygonise import polygonise
    from . import walls as W
    from ..mesh.polygonise import GridArraySampler
    values = W.wall_field(distance, wall)
    if ends is not None:
        xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
        values = W.trim_ends(values, xs, ys, zs, ends, float(sum(wall)))
    res = polygonise(GridArraySampler(values, grid), grid, caps=True)
    return res.vertices * np.asarray(flip), res.faces.astype(np.int64)


def _stage(progress, stage: str):
    """``progress(stage, done, total)`` as a ``(done, total)`` callback (None without one)."""
    return None if progress is None else (lambda done, total: progress(stage, done, total))
