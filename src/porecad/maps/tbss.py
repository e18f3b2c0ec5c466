"""TPMS designed in the parameter domain of a TBSS and mapped into it (document 001, §3.1 and §3.3).

The volume TPMS structure is built in the unit cube ``[0, 1]^3`` with the
threshold given by the TDF ``C(u, v, w)`` (a scalar trivariate B-spline) and
``A, B, C`` whole periods along ``u, v, w`` (001's *period coefficients*):

* pore:  material where ``φ(A u, B v, C w) ≥ C(u, v, w)``
* rod:   material where ``φ ≤ C``
* sheet: material where ``|φ - m| ≤ C``

with ``φ`` of period 1 (001 eq. 4). It is polygonised on a regular grid of the
cube and closed on the cube's faces by their "outside triangles" (001 §3.1;
:func:`porecad.mesh.polygonise.polygonise` with caps), then every vertex is
mapped through the TBSS ``P(u, v, w) = Σ N_i(u) N_j(v) N_k(w) P_ijk`` (001
eq. 2). Because the cube holds whole periods, every cell is complete, and
because one field is polygonised at once, neighbouring cells are continuous.
With a positive Jacobian the map preserves orientation, so the closed,
outward mesh stays closed and outward.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from ..fields.base import Field, lattice_values
from ..fields.tpms import TPMSField
from ..mesh.polygonise import Grid, polygonise
from ..solids import StructureField, check_structure


class SplineField(Field):
    """A scalar trivariate B-spline (e.g. a TDF) as a field over the parameter cube."""

    def __init__(self, volume):
        self.volume = volume

    def evaluate(self, points):
        p = np.asarray(points, dtype=np.float64)
        return self.volume.evaluate(p[:, 0], p[:, 1], p[:, 2])[:, 0]

    def sample_grid(self, xs, ys, zs):
        g = self.volume.evaluate_grid(np.clip(xs, 0.0, 1.0), np.clip(ys, 0.0, 1.0), np.clip(zs, 0.0, 1.0))
        return np.ascontiguousarray(g[..., 0].transpose(2, 1, 0), dtype=np.float32)


def check_periods(periods) -> np.ndarray:
    """Period coefficients as 3 positive integers (whole periods: no cell is cut)."""
    try:
        p = np.broadcast_to(np.asarray(periods, dtype=np.float64), (3,))
    except (TypeError, ValueError):
        raise InputError(f"periods must be one or three whole numbers, got {str(periods)[:60]}") from None
    shown = tuple(float(x) for x in p)
    if not np.all(np.isfinite(p)) or np.any(p < 1) or np.any(p > 1e6):
        raise InputError(f"periods must be three whole numbers from 1 to 1e6, got {shown}")
    if np.any(np.abs(p - np.round(p)) > 1e-9):
        raise InputError(f"periods must be whole numbers so that no cell is cut, got {shown}")
    return np.round(p).astype(np.int64)


def periods_for_cell(tbss, cell_size: float, samples: int = 17):
    """Whole periods along u, v, w that make cells about ``cell_size`` (mm) long in the solid.

    The length of the solid along each parameter direction is the mean
    length of its ``samples²`` parameter lines along it (polylines through
    ``samples`` points each); periods are those lengths / ``cell_size``,
    rounded, at least 1 and at most 1000. Returns ``(periods, lengths)``.
    """
    cell = float(cell_size)
    if not (np.isfinite(cell) and cell > 0):
        raise InputError(f"the cell size must be a positive length (mm), got {cell_size!r}")
    s = np.linspace(0.0, 1.0, int(samples))
    pts = np.asarray(tbss.evaluate_grid(s, s, s))[..., :3]
    lengths = np.array([np.linalg.norm(np.diff(pts, axis=a), axis=-1).sum(axis=a).mean() for a in range(3)])
    want = lengths / cell
    if np.any(want > 1000):
        raise InputError(f"a {cell:g} mm cell in a solid {' x '.join(f'{x:.4g}' for x in lengths)} mm long makes "
                         "more than 1000 periods along a direction; raise the cell size")
    return np.maximum(np.round(want), 1).astype(np.int64), lengths


def parametric_grid(periods, resolution: int, box=((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))) -> Grid:
    """Sampling grid of the parameter cube: ``resolution`` samples per period edge (ends included).

    ``box`` may be a sub-box whose faces lie on grid planes of the full cube
    (per-layer measurements polygonise exactly the same samples).
    """
    n = int(resolution)
    if n < 4:
        raise InputError(f"`resolution` must be at least 4 samples per period, got {resolution}")
    p = check_periods(periods)
    full = p * (n - 1)
    lo, hi = np.asarray(box[0], dtype=np.float64), np.asarray(box[1], dtype=np.float64)
    i0, i1 = np.round(lo * full).astype(np.int64), np.round(hi * full).astype(np.int64)
    if np.any(np.abs(i0 - lo * full) > 1e-6) or np.any(np.abs(i1 - hi * full) > 1e-6) or np.any(i1 <= i0):
        raise InputError("a parametric sub-box must lie on the sampling grid")
    spacing = 1.0 / full
    return Grid(origin=tuple(i0 * spacing), spacing=tuple(spacing), shape=tuple(int(s) for s in i1 - i0 + 1))


def parametric_structure(tpms_type: str, structure: str, tdf_volume, periods) -> StructureField:
    """The volume TPMS structure of 001 eq. 4 over the parameter cube."""
    p = check_periods(periods)
    phi = TPMSField(tpms_type, cell_size=1.0 / p)
    s = check_structure(structure)
    if s == "surface":
        raise InputError("a TBSS scaffold needs a solid structure: pore, rod or sheet")
    return StructureField(phi, s, threshold=SplineField(tdf_volume))


def parametric_scaffold(tpms_type, structure, tdf_volume, periods, resolution, box=None, threads=None,
                        progress=None, periodic=(False, False, False), cut=None):
    """Polygonise the structure in the parameter cube (or a grid-aligned sub-box); closed, outward.

    ``periodic[a]``: the faces ``a = 0`` and ``a = 1`` are one surface of the
    solid (a tube's seam). The samples of the last plane along ``a`` are
    replaced by those of the first (the TPMS has whole periods; the TDF is made
    to agree), the two faces get no caps, and the vertices of the last plane
    are welded to the identical ones of the first: the seam disappears.

    ``cut(xs, ys, zs, s)``, optional: the structure's samples ``s`` (z, y, x)
    replaced by ``max(s, cut term)`` (:func:`tbss_scaffold` with ``clip``).

    Returns ``(params (n, 3), faces (m, 3), result)`` with the polygonisation result.
    """
    grid = parametric_grid(periods, resolution, box) if box is not None else parametric_grid(periods, resolution)
    field = parametric_structure(tpms_type, structure, tdf_volume, periods)
    lo = np.asarray(grid.origin)
    hi = lo + (np.asarray(grid.shape) - 1) * np.asarray(grid.spacing)
    seams = [a for a in range(3) if periodic[a] and lo[a] <= 1e-12 and hi[a] >= 1.0 - 1e-9]
    if 2 in seams:
        raise InputError("a TBSS periodic in w is not supported (slabs run along w); make u the periodic axis")
    sample = _seamed(field.sample_grid, seams) if seams else field.sample_grid
    if cut is not None:
        inner = sample

        def sample(xs, ys, zs):
            return cut(xs, ys, zs, inner(xs, ys, zs))
    caps = [True] * 6
    for a in seams:
        caps[2 * a] = caps[2 * a + 1] = False
    res = polygonise(sample, grid, caps=tuple(caps), threads=threads, progress=progress)
    vertices, faces = res.vertices, res.faces
    for a in seams:
        vertices, faces = weld_seam(vertices, faces, a, lo[a], hi[a])
    params = np.clip(vertices, 0.0, 1.0)
    return params, faces, res


def _seamed(sample_grid, seams):
    """A sampler whose last plane along each seam axis repeats its first (sample arrays are (z, y, x))."""
    def sample(xs, ys, zs):
        f = np.array(sample_grid(xs, ys, zs))
        for a in seams:
            if a == 0:
                f[:, :, -1] = f[:, :, 0]
            else:
                f[:, -1, :] = f[:, 0, :]
        return f
    return sample


def weld_seam(vertices, faces, axis: int, lo: float, hi: float):
    """Merge the vertices on the plane ``axis = hi`` into those at identical positions on ``axis = lo``."""
    v = np.asarray(vertices)
    on_lo = np.nonzero(np.abs(v[:, axis] - lo) <= 1e-12)[0]
    on_hi = np.nonzero(np.abs(v[:, axis] - hi) <= 1e-9 * max(1.0, abs(hi)))[0]
    others = [b for b in range(3) if b != axis]
    key_lo = {tuple(v[i, others]): i for i in on_lo}
    remap = np.arange(len(v))
    for i in on_hi:
        j = key_lo.get(tuple(v[i, others]))
        if j is None:
            raise RuntimeError("periodic seam mismatch: a vertex of the last plane has no twin on the first")
        remap[i] = j
    keep = np.ones(len(v), dtype=bool)
    keep[on_hi] = False
    new_index = np.cumsum(keep) - 1
    return v[keep], new_index[remap[faces]].astype(faces.dtype)



def sample_spacing(tbss, periods, resolution, coarsest: bool = False) -> float:
    """The mean physical spacing (mm) of a scaffold's parameter samples, ``vol(TBSS)^(1/3) / (period count x
    (resolution - 1))`` with the mean period count (``coarsest``: the smallest, the widest spacing)."""
    p = check_periods(periods)
    n = float(np.min(p)) if coarsest else float(np.mean(p))
    return float(abs(tbss.volume())) ** (1.0 / 3.0) / (n * (int(resolution) - 1))


def _clip_term(tbss, clip, periods, resolution, field, body_only=False, skin=0.0):
    """``cut(xs, ys, zs, s) = max(s, k clip(P(u)))`` over the parameter samples (see :func:`tbss_scaffold`);
    ``k clip(P(u))`` alone with ``body_only`` (the domain ``TBSS ∩ body``); with a ``skin`` (mm)
    ``k clip(P(u))`` within ``skin`` of the surface and the cut structure deeper: a shell that deep."""
    delta = sample_spacing(tbss, periods, resolution)
    probe = np.linspace(0.0, 1.0, 33)
    top = float(np.max(np.abs(field.sample_grid(probe, probe, probe))))
    k = 4.0 * max(top, 1e-12) / delta  # one k for every slab: the slabs' shared planes must agree

    def cut(xs, ys, zs, s):
        if isinstance(clip, SampleClip) and clip.tbss is tbss:
            raw = clip.at_samples(xs, ys, zs)
        else:
            raw = _sample_values(tbss, clip, xs, ys, zs)
        d = np.float32(k) * raw
        if body_only:
            return d
        if skin > 0:
            # within the skin the body term itself (so that the outer surface is the body's as without a
            # skin: ``max(min(s, -d - k skin), d)`` differs from ``d`` deeper than half the skin and moved a
            # coarse sampling's surface inwards, 1.2 mm at a blob's tip); deeper, the structure
            ks = np.float32(k * skin)
            return np.where(d > -ks, d, np.minimum(np.maximum(s, d), -d - ks))
        return np.maximum(s, d)

    return cut


def tbss_scaffold(tbss, tpms_type, structure, tdf_volume, periods, resolution, box=None, threads=None,
                  progress=None, clip=None, skin: float = 0.0, domain: bool = True) -> dict:
    """The scaffold mapped into the TBSS: ``{'vertices', 'faces', 'params', 'timings', 'inside_fraction'}``.

    ``clip`` (optional): a body's signed distance field (negative inside,
    exact to a few samples, e.g. :class:`porecad.bodies.MeshBody`). The
    solid is cut to the body in field space: at every parameter sample the
    structure value ``s(u)`` becomes ``max(s(u), k clip(P(u)))`` with ``k``
    four times the structure's largest value over the mean physical sample
    spacing (the body term is inactive one sample inside the body), so one
    marching-cubes pass gives ``scaffold ∩ body`` (the R-function
    intersection) and the cut surface is mapped marching-cubes triangles
    like the rest. The TBSS should then cover the body (a fit inflated by a
    margin, :func:`porecad.splines.meshfit.fit_tbss_to_mesh`).

    ``skin`` (mm, with ``clip``): the scaffold is wrapped in a solid shell
    that deep inside the body's surface (the value is the body term
    ``k clip`` within ``skin`` of the surface, the cut structure deeper),
    so that its outside is the body's; ``clip`` must then be exact ``skin`` deeper
    (:func:`body_clip` with ``skin``). With ``clip``, ``out["domain"]`` is the
    cut domain (:func:`clipped_domain`) unless ``domain`` is False.
    """
    t = time.perf_counter()
    cut = None
    if clip is not None:
        field = parametric_structure(tpms_type, structure, tdf_volume, periods)
        cut = _clip_term(tbss, clip, periods, resolution, field, skin=float(skin))
    params, faces, res = parametric_scaffold(tpms_type, structure, tdf_volume, periods, resolution, box,
                                             threads, progress, periodic=tuple(getattr(tbss, "periodic", (False,) * 3)),
                                             cut=cut)
    t_param = time.perf_counter() - t
    if len(faces) == 0:
        raise InputError("the structure is empty at these thresholds: nothing to map")
    t = time.perf_counter()
    vertices = tbss.map_points(params)
    t_map = time.perf_counter() - t
    out = {"vertices": vertices, "faces": faces, "params": params, "inside_fraction": res.inside_fraction,
           "timings": {"tpms_s": t_param, "map_s": t_map}}
    if clip is not None and domain:
        t = time.perf_counter()
        out["domain"] = clipped_domain(tbss, clip, tpms_type, structure, tdf_volume, periods, resolution, box,
                                       threads)
        out["timings"]["domain_s"] = time.perf_counter() - t
    return out


def _sample_values(tbss, clip, xs, ys, zs):
    """``clip`` at the TBSS images of the parameter samples ``zs x ys x xs``, ``(nz, ny, nx)`` float32 (as the
    samples are)."""
    c = [np.clip(np.asarray(a, dtype=np.float64), 0.0, 1.0) for a in (xs, ys, zs)]
    P = np.ascontiguousarray(np.asarray(tbss.evaluate_grid(*c))[..., :3].transpose(2, 1, 0, 3))
    return lattice_values(clip, P).astype(np.float32)


#: the most parameter samples whose body distances a :class:`SampleClip` keeps (4 bytes each)
SAMPLE_CLIP_KEEP = 100_000_000


class SampleClip(Field):
    """A body's signed distance (``body``, e.g. a :class:`porecad.bodies.mesh.MeshBody`) for a scaffold cut in
    one TBSS, keeping its values at the parameter samples for the job's later passes.

    The cut term of :func:`tbss_scaffold` does not depend on the TDF or the
    structure, only on where the samples map to; a job polygonises the same
    samples again for the cut domain (:func:`clipped_domain`) and for every
    porosity calibration pass. The values of each slab of samples are kept
    (up to :data:`SAMPLE_CLIP_KEEP` samples in all, then computed again), so
    the body's distance at a sample is computed once per job.
    """

    def __init__(self, body, tbss, keep: int = SAMPLE_CLIP_KEEP):
        import threading
        self.body, self.tbss, self.keep = body, tbss, int(keep)
        self._kept, self._size, self._lock = {}, 0, threading.Lock()

    def evaluate(self, points):
        return self.body(points)

    def evaluate_lattice(self, points):
        return lattice_values(self.body, points)

    def at_samples(self, xs, ys, zs):
        """The body's signed distance at the TBSS images of the parameter samples ``zs x ys x xs``."""
        key = tuple(np.asarray(a, dtype=np.float64).tobytes() for a in (xs, ys, zs))
        with self._lock:
            got = self._kept.get(key)
        if got is not None:
            return got
        vals = _sample_values(self.tbss, self.body, xs, ys, zs)
        with self._lock:
            if key not in self._kept and self._size + vals.size <= self.keep:
                self._kept[key] = vals
                self._size += vals.size
        return vals


def body_clip(vertices, faces, tbss, periods, resolution, samples: float = 3.0, skin: float = 0.0):
    """The signed distance of a closed mesh body for ``tbss_scaffold(clip=...)``, exact ``samples`` deep.

    The cut needs exact distances only within a few samples of the surface
    (beyond, the clamped value keeps the body term inactive inside and the
    solid cut away outside), so the band is ``samples`` times the mean
    physical sample spacing ``vol(TBSS)^(1/3) / (mean period x (resolution - 1))``,
    which keeps the distance queries local; a ``skin`` (mm) deepens it by as much.
    Returned as a :class:`SampleClip` of ``tbss``: the values at the
    scaffold's samples are computed once for all of a job's passes.
    """
    from ..bodies.mesh import MeshBody
    delta = sample_spacing(tbss, periods, resolution, coarsest=True)
    return SampleClip(MeshBody(vertices, faces, band=float(samples) * delta + float(skin)), tbss)


def clipped_domain(tbss, clip, tpms_type, structure, tdf_volume, periods, resolution, box=None,
                   threads=None) -> dict:
    """The domain ``TBSS ∩ body`` of a clipped scaffold, polygonised on the same samples and mapped.

    Marching cubes of ``k clip(P(u))`` alone over the scaffold's parameter
    samples (the cut term of :func:`tbss_scaffold`, so the domain's cut
    surface is the scaffold's): ``{'volume', 'lo', 'hi', 'triangles'}``,
    the mapped mesh's enclosed volume and bounding box (mm). The domain
    volume over the body's volume is the fraction of the body the scaffold
    covers; its box against the body's box the extents error.
    """
    field = parametric_structure(tpms_type, structure, tdf_volume, periods)
    cut = _clip_term(tbss, clip, periods, resolution, field, body_only=True)
    params, faces, _ = parametric_scaffold(tpms_type, structure, tdf_volume, periods, resolution, box, threads,
                                           periodic=tuple(getattr(tbss, "periodic", (False,) * 3)), cut=cut)
    if len(faces) == 0:
        raise InputError("the TBSS does not overlap the body: nothing to cut")
    from ..mesh.validate import signed_volume
    v = tbss.map_points(params)
    return {"volume": float(abs(signed_volume(v, faces))), "lo": v.min(axis=0).tolist(),
            "hi": v.max(axis=0).tolist(), "triangles": int(len(faces))}


def body_overlap(tbss, vertices, faces) -> dict:
    """How much of a closed body the TBSS solid covers: ``{'fraction', 'lo', 'hi'}`` or None.

    ``fraction`` is ``vol(body ∩ TBSS) / vol(body)`` and ``lo``, ``hi`` the
    box of ``body ∩ TBSS`` (mm), by the exact mesh Boolean (manifold3d) of
    the body with the TBSS's boundary surface
    (:func:`porecad.maps.domain_surface.tbss_surface`): the fit's own
    coverage, independent of the scaffold's sample resolution (the scaffold's
    cut domain, :func:`clipped_domain`, loses the parts of the body thinner
    than its samples). None when the Boolean cannot be formed (a TBSS
    surface that overlaps itself).
    """
    from ..mesh.boolean import intersect
    from ..mesh.validate import signed_volume
    from .domain_surface import tbss_surface
    try:
        sv, sf = tbss_surface(tbss)
        iv, i_f = intersect(vertices, faces, sv, sf)
    except Exception:  # noqa: BLE001 - a measurement only: manifold3d refuses some overlapping surfaces
        return None
    if len(i_f) == 0:
        return {"fraction": 0.0, "lo": None, "hi": None}
    return {"fraction": float(abs(signed_volume(iv, i_f)) / abs(signed_volume(vertices, faces))),
            "lo": iv.min(axis=0).tolist(), "hi": iv.max(axis=0).tolist()}


def boundary_band_intersections(vertices, faces, params) -> int:
    """Self-intersecting face pairs among the triangles that touch the parameter cube's faces.

    The parametric mesh does not intersect itself (marching-cubes patches
    never fold, for any edge parameters), and the TBSS map is smooth with a
    positive Jacobian, so what mapping can break is where flat cap triangles
    (chords of the curved boundary, sagitta ``~ L² κ / 8``) meet surface
    triangles at a grazing angle: the band of triangles with a vertex on a
    face. Checking that band costs a fraction of a full check.
    """
    from ..mesh.validate import self_intersections
    on_face = np.any((params <= 1e-12) | (params >= 1.0 - 1e-12), axis=1)
    band = np.any(on_face[faces], axis=1)
    if not band.any():
        return 0
    return int(self_intersections(vertices, faces[band])[1])
