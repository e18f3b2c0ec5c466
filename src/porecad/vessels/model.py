"""The blended vessel field: truncated segment fields joined by a blending union (003 §3.3–3.4).

Field of the vessel lumen (negative inside)::

    F_b = min_{s in branch b} f̄_s                    (segments of one branch)
    F   = g_uni(... g_uni(g_uni(F_0, F_1), F_2) ..., F_{B-1})   (branches, 003 Eq. 2.12)

``f̄_s`` is segment ``s``'s local field inside its box and ``c`` outside
(the truncated implicit function). Branches are ordered breadth-first from
the first end node, so every new branch meets the part already built at a
junction, where Li's shape-preserving union ``g_uni_{n,δ}`` blends them; in
*local* evaluation a branch's union is applied inside the branch's box only
(elsewhere the branch field is the constant ``c`` and the union would be
``c``-dominated anyway). Pieces of the *same* branch are joined by ``min``:
they are pieces of one swept tube, whose overlaps coincide exactly (``f_0 = f_1``),
where any blend that is not idempotent would bulge the tube (Li's union by
``δ/6`` for n = 2); ``min`` of the pieces' distances is the distance to their
union, so no crease arises. This is a deliberate deviation from 003, whose
RBF segment fits differ slightly in the overlaps; ``inner_blend`` switches it.

Evaluation (:func:`evaluate_grid`) is per segment on the segment's box
(``local``) or over the whole grid (``global``, 003's "globalised"
evaluation, for the Table 3.4 comparison; it blends the constant ``c`` with
itself far from the vessel, lowering it by ``δ/6`` per branch there, so the
two agree exactly only within ``c − δ`` of the surface — the same solid), serially or on a pool of
``workers`` threads (the numba kernels release the GIL) or processes.
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np

from ..fields.blends import Blend
from .local_fields import box_slices, tube_grid


def _segment_values(P, R, xs, ys, zs):
    out = np.empty((len(zs), len(ys), len(xs)), dtype=np.float32)
    if len(P) == 1:
        X, Y, Z = np.meshgrid(xs, ys, zs, indexing="xy")
        return (np.sqrt((X - P[0, 0]) ** 2 + (Y - P[0, 1]) ** 2 + (Z - P[0, 2]) ** 2) - R[0]).transpose(2, 0, 1)
    return tube_grid(xs, ys, zs, P, R, out)


def _task(args):
    """One segment on its box (local) or the whole grid (global): ``(slices, values, fitted)``.

    With boundary points in its box the segment is an RBF fit to them (:mod:`porecad.vessels.rbf_fit`, or
    :mod:`porecad.vessels.ellipsoid_fit` for ``kind = "ellipsoid"``), else a swept-radius tube.
    """
    P, R, xs, ys, zs, lo, hi, local, boundary, kind = args
    fit = None
    if boundary is not None:
        if kind == "ellipsoid":
            from .ellipsoid_fit import fit_segment
        else:
            from .rbf_fit import fit_segment
        fit = fit_segment(P, R, boundary)

    def values(ax, ay, az):
        tube = _segment_values(P, R, ax, ay, az)
        if fit is None:
            return tube
        from .rbf_fit import segment_values
        return _axis_component(np.maximum(segment_values(fit, ax, ay, az, radius=float(np.min(R))),
                                          tube - np.float32(0.5 * np.mean(R))), P, ax, ay, az)

    if local:
        sl = box_slices((xs, ys, zs), lo, hi)
        if sl is None:
            return None, None, False
        sx, sy, sz = sl
        return sl, values(xs[sx], ys[sy], zs[sz]), fit is not None
    return (slice(None),) * 3, values(xs, ys, zs), fit is not None


def _axis_component(val, P, ax, ay, az):
    """A fitted segment's solid is the part of ``{val ≤ 0}`` joined to its axis: any other piece (a blob of
    the interpolant within the tube's guard band) is turned outside (``|val|``)."""
    from scipy import ndimage
    inside = val <= 0
    lab, n = ndimage.label(inside)
    if n <= 1:
        return val
    idx = [np.clip(np.searchsorted(a, P[:, k]), 0, len(a) - 1) for k, a in enumerate((ax, ay, az))]
    keep = np.unique(lab[idx[2], idx[1], idx[0]])
    drop = inside & ~np.isin(lab, keep[keep > 0])
    val[drop] = -val[drop]
    return val


def _segment_points(boundary, i, seg):
    """Segment ``i``'s boundary points: its own cloud (a list, one per segment) or the pooled cloud in its box."""
    if boundary is None:
        return None
    if isinstance(boundary, (list, tuple)):
        return boundary[i]
    from .rbf_fit import points_in_box
    return points_in_box(boundary, seg.box_min, seg.box_max)


def _clamped(val, c):
    np.minimum(val, np.float32(c), out=val)
    return val


def branch_order(segments) -> list[int]:
    """Branches in breadth-first order over shared nodes, starting at branch 0."""
    nb = max(s.branch for s in segments) + 1
    ends = {}
    for s in segments:
        ends.setdefault(s.branch, set()).update((int(s.nodes[0]), int(s.nodes[-1])))
    order, seen = [], set()
    for start in range(nb):
        if start in seen:
            continue
        queue = [start]
        seen.add(start)
        while queue:
            b = queue.pop(0)
            order.append(b)
            for c in range(nb):
                if c not in seen and ends.get(b, set()) & ends.get(c, set()):
                    seen.add(c)
                    queue.append(c)
    return order


#: CPU seconds per swept-tube sample, per thin-plate kernel (sample × centre) and per flop of an RBF solve
#: (measured on the development machine: scipy's RBFInterpolator, numba tube kernels)
TUBE_SECONDS, KERNEL_SECONDS, SOLVE_SECONDS = 0.1e-6, 15e-9, 0.2e-9


def estimate_seconds(segments, xs, ys, zs, boundary=None, local: bool = True) -> float:
    """Up-front CPU estimate of :func:`evaluate_grid` (tube samples, RBF kernels on the coarse grids, solves)."""
    from .rbf_fit import COARSE_FRACTION, MAX_STRIDE, MIN_POINTS
    axes = [np.asarray(a, dtype=np.float64) for a in (xs, ys, zs)]
    total = 0.0
    for i, s in enumerate(segments):
        sl = box_slices(axes, s.box_min, s.box_max) if local else tuple(slice(0, len(a)) for a in axes)
        if sl is None:
            continue
        lens = [len(range(*sl[a].indices(len(axes[a])))) for a in range(3)]
        total += TUBE_SECONDS * float(np.prod(lens))
        if boundary is None:
            continue
        k = len(_segment_points(boundary, i, s))
        if k < MIN_POINTS:
            continue
        centres = 4 * min(k, 600) + 40
        coarse = 1.0
        for a in range(3):
            h = float(abs(axes[a][1] - axes[a][0])) if len(axes[a]) > 1 else 1.0
            stride = int(max(1, min(MAX_STRIDE, np.floor(COARSE_FRACTION * float(np.min(s.radii)) / h))))
            coarse *= lens[a] // stride + 1
        total += KERNEL_SECONDS * coarse * centres + SOLVE_SECONDS * centres ** 3 / 3.0
    return total


def evaluate_grid(segments, graph, xs, ys, zs, c: float, blend: Blend, local: bool = True, workers: int = 1,
                  executor: str = "thread", inner_blend: str = "min", stats: dict | None = None,
                  boundary=None, progress=None, fit: str = "rbf") -> np.ndarray:
    """The vessel field on the tensor grid ``zs × ys × xs`` as ``(nz, ny, nx)`` float32 (module docstring).

    ``boundary`` (k, 3): boundary points; segments with enough of them in their box are RBF fits; or a
    list of one cloud per segment (the segment's own, e.g. from its local segmentation). ``fit``: ``rbf``
    (thin-plate with off-surface points, :mod:`~porecad.vessels.rbf_fit`) or ``ellipsoid`` (003's direct
    fit, :mod:`~porecad.vessels.ellipsoid_fit`).
    ``progress(done, total)``: after each segment.
    """
    xs, ys, zs = (np.ascontiguousarray(a, dtype=np.float64) for a in (xs, ys, zs))
    t0 = time.perf_counter()
    tasks = [(s.points, s.radii, xs, ys, zs, s.box_min, s.box_max, local, _segment_points(boundary, i, s), fit)
             for i, s in enumerate(segments)]
    results = []
    if workers > 1:
        Pool = ProcessPoolExecutor if executor == "process" else ThreadPoolExecutor
        with Pool(max_workers=workers) as pool:
            for r in pool.map(_task, tasks):
                results.append(r)
                if progress is not None:
                    progress(len(results), len(tasks))
    else:
        for t in tasks:
            results.append(_task(t))
            if progress is not None:
                progress(len(results), len(tasks))
    t1 = time.perf_counter()
    shape = (len(zs), len(ys), len(xs))
    F = np.full(shape, c, dtype=np.float32)
    by_branch = {}
    fitted = sum(1 for r in results if r[2])
    results = [r[:2] for r in results]
    for s, (sl, val) in zip(segments, results):
        if sl is not None:  # f̄ = min(f, c): the truncated field never exceeds its outside value
            by_branch.setdefault(s.branch, []).append((sl, _clamped(val, c)))
    first = True
    for b in branch_order(segments):
        parts = by_branch.get(b)
        if not parts:
            continue
        # the branch box: union of its segments' boxes (in index space)
        lo = [min(sl[a].indices(shape[2 - a])[0] for sl, _ in parts) for a in range(3)]
        hi = [max(sl[a].indices(shape[2 - a])[1] for sl, _ in parts) for a in range(3)]
        B = np.full((hi[2] - lo[2], hi[1] - lo[1], hi[0] - lo[0]), c, dtype=np.float32)
        for sl, val in parts:
            sub = (slice(sl[2].indices(shape[0])[0] - lo[2], sl[2].indices(shape[0])[1] - lo[2]),
                   slice(sl[1].indices(shape[1])[0] - lo[1], sl[1].indices(shape[1])[1] - lo[1]),
                   slice(sl[0].indices(shape[2])[0] - lo[0], sl[0].indices(shape[2])[1] - lo[0]))
            if inner_blend == "min":
                np.minimum(B[sub], val, out=B[sub])
            else:
                B[sub] = blend.union(B[sub], val)
        box = (slice(lo[2], hi[2]), slice(lo[1], hi[1]), slice(lo[0], hi[0]))
        if first:
            F[box] = B
            first = False
        else:
            F[box] = blend.union(F[box], B)
    if stats is not None:
        stats["segments_s"] = stats.get("segments_s", 0.0) + (t1 - t0)
        stats["blend_s"] = stats.get("blend_s", 0.0) + (time.perf_counter() - t1)
        stats["rbf_segments"] = stats.get("rbf_segments", 0) + fitted
        stats["evaluated_samples"] = stats.get("evaluated_samples", 0) + int(
            sum(v.size for _, v in results if v is not None))
    return F


class VesselField:
    """Point evaluation of the same blended vessel field as :func:`evaluate_grid` (local form).

    A :class:`~porecad.fields.base.Field` (built lazily to keep this module's
    imports light): ``VesselField(segments, graph, c, blend)(points)``.
    """

    def __new__(cls, segments, graph, c: float, blend: Blend, inner_blend: str = "min"):
        from ..fields.base import Field
        from .local_fields import tube_distance

        class _VF(Field):
            def evaluate(self, X):
                X = np.asarray(X, dtype=np.float64)
                F = np.full(len(X), float(c))
                first = True
                for b in branch_order(segments):
                    segs = [s for s in segments if s.branch == b]
                    if not segs:
                        continue
                    blo = np.min([s.box_min for s in segs], axis=0)
                    bhi = np.max([s.box_max for s in segs], axis=0)
                    inb = np.all((X >= blo) & (X <= bhi), axis=1)
                    B = np.full(int(inb.sum()), float(c))
                    Xb = X[inb]
                    for s in segs:
                        ins = np.all((Xb >= s.box_min) & (Xb <= s.box_max), axis=1)
                        if np.any(ins):
                            v = np.minimum(tube_distance(Xb[ins], s.points, s.radii), c)
                            B[ins] = np.minimum(B[ins], v) if inner_blend == "min" else blend.union(B[ins], v)
                    F[inb] = B if first else blend.union(F[inb], B)
                    first = False
                return F

        return _VF()
