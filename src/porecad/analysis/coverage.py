"""How much of a body a solid fills: the promise check's coverage (:mod:`porecad.jobs.promise`).

:func:`body_coverage` measures, from the solid and the body alone, the
fraction of the body's volume within a pore's reach of the solid
(:func:`filled`, on a regular grid of the body's inside, :func:`body_grid`)
and the fraction of each of the body's extents the solid's box spans.
"""

from __future__ import annotations

import numpy as np

#: body samples for the coverage (a regular grid over the body's box)
COVERAGE_SAMPLES = 40_000


def body_coverage(vertices, faces, domain_volume, body):
    """``(coverage, extent_coverage)`` of ``body`` by the solid (``coverage`` None for an empty body grid);
    None for a body with no bounds."""
    grid = body_grid(body)
    if grid is None:
        return None
    inside, lo, step = grid
    hi = lo + step * np.array(inside.shape[::-1])
    v = np.asarray(vertices, np.float64)
    span = (np.minimum(v.max(axis=0), hi) - np.maximum(v.min(axis=0), lo)).clip(0) / (hi - lo)
    if not inside.any():
        return None, span
    return float(np.mean(filled(v, faces, domain_volume, lo, step, inside)[inside])), span


def body_grid(body, n: int = COVERAGE_SAMPLES):
    """``(inside, lo, step)``: the body's inside on a regular grid of about ``n`` cells over its box.

    ``inside`` is indexed ``[z, y, x]``; cell ``(i, j, k)`` is centred at
    ``lo + (i + ½, j + ½, k + ½) · step``. ``body``: ``(vertices, faces)`` of
    a closed mesh, a :class:`~porecad.bodies.mesh.MeshBody` or a field
    negative inside with ``bounds`` (None: unbounded, no grid).
    """
    from ..bodies.mesh import MeshBody
    if isinstance(body, (tuple, list)):
        v = np.asarray(body[0], np.float64)
        body = MeshBody(v, np.asarray(body[1], np.int64), band=max(float(np.ptp(v, axis=0).max()) / 48, 1e-9))
    if body.bounds is None:
        return None
    lo, hi = (np.asarray(b, np.float64) for b in body.bounds)
    ext = np.maximum(hi - lo, 1e-12)
    counts = np.clip(np.ceil(ext / float((np.prod(ext) / n) ** (1 / 3))).astype(int), 4, 400)
    step = ext / counts
    axes = [lo[a] + (np.arange(counts[a]) + 0.5) * step[a] for a in range(3)]
    inside = body.inside_grid(*axes) if hasattr(body, "inside_grid") else body.sample_grid(*axes) < 0
    return np.asarray(inside, bool), lo, step


def filled(vertices, faces, domain_volume, lo, step, inside):
    """The cells of the body's grid the solid fills: those within a pore's reach of its surface, or inside it.

    The reach is 1.5 times the larger of the solid's void and material
    volume per unit surface area (a pore's or a strut's half width): the
    pores and the struts' insides count, the body beyond the solid's edge
    does not (a gap narrower than the reach does).
    """
    from scipy import ndimage

    from ..mesh.validate import signed_volume, surface_area
    v = np.asarray(vertices, np.float64)
    area = float(surface_area(v, faces))
    solid = float(signed_volume(v, faces))
    void = max(float(domain_volume or 0.0) - solid, 0.0)
    reach = 1.5 * max(void, solid) / max(area, 1e-300)
    dims = np.asarray(inside.shape)
    pts = np.concatenate([v, surface_points(v, faces, float(step.min()) / 4)])
    idx = np.floor((pts - lo) / step).astype(np.int64)[:, ::-1]  # (z, y, x)
    ok = np.all((idx >= -1) & (idx <= dims), axis=1)  # a vertex on the box's faces belongs to its cells
    idx = np.clip(idx[ok], 0, dims - 1)
    occ = np.zeros(inside.shape, bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    if not occ.any():
        return occ
    occ = ndimage.binary_fill_holes(occ)  # the inside of a solid part thicker than the reach
    return ndimage.distance_transform_edt(~occ, sampling=step[::-1]) <= reach


def surface_points(vertices, faces, spacing: float, most: int = 2_000_000) -> np.ndarray:
    """Points about ``spacing`` apart on the triangles with an edge longer than that (area-weighted, seeded;
    at most ``most``): with the vertices, every cell a triangle passes through holds a point."""
    v, f = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    big = np.maximum(np.maximum(np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1)),
                     np.linalg.norm(a - c, axis=1)) > spacing
    a, b, c = a[big], b[big], c[big]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    n = int(min(np.ceil(area.sum() / spacing ** 2), most))
    if n == 0 or area.sum() <= 0:
        return np.empty((0, 3))
    rng = np.random.default_rng(0)
    t = rng.choice(len(a), size=n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    return ((1 - r1)[:, None] * a[t] + (r1 * (1 - r2))[:, None] * b[t] + (r1 * r2)[:, None] * c[t])
