"""Porosity held in any body: the threshold calibrated against samples inside the body (issue 20, item 6).

The calibration curve of :mod:`porecad.calibration` holds for *whole cells*:
a body whose parts are thinner than a cell, or cut through cells, or wrapped
in a solid skin, samples the lattice unevenly, and its porosity drifts from
the one asked for (a gyroid at 0.6 in a figurine with limbs thinner than a
cell: 0.656). Here the threshold is solved on the body itself.

**Samples.** A regular grid over the body's box whose spacing along each
axis is the cell size divided by ``k + f`` (``k`` a whole number, ``f`` an
irrational fraction: 0.382, 0.618, 0.236 per axis), so that the samples,
taken modulo the cell, are equidistributed over it (Weyl's theorem; a
spacing that divides the cell would see the same few points of every cell).
About :data:`TARGET_INSIDE` samples fall inside the body (at most
:data:`MAX_GRID` grid points in all, visited slab by slab). For each inside
sample we keep the structure variable ``k`` (void where ``k < c``: ``k = φ``
for a pore, ``−φ`` for a rod, ``−|φ − m|`` for a sheet, with the
threshold ``C = c`` or ``−c``) and whether the lattice decides it (the
*core*: the whole body for ``cut``, the body deeper than the skin ``T``
for ``skin``, where the shell ``{−T ≤ d ≤ 0}`` is solid).

**Uniform target p.** The body's void fraction is
``#(core ∧ k < c) / #inside``, so ``c`` is the ``q = p · #inside / #core``
quantile of ``k`` over the core (unreachable when ``q ≥ 1``: the skin alone
holds more than ``1 − p`` of the body; the job then keeps the lattice at the
edge of its valid range and says so).

**Graded target p(x).** The threshold field becomes
``C(x) = C_cells(p(x) + δ(x))`` with ``C_cells`` the whole-cell curve and
``δ(x) = a(d(x)) + b(s(x))`` a correction, piecewise linear in the depth
``d`` below the surface (nodes at the centres of the depth shells) and in the
coordinate ``s`` along the slab axis (nodes at the slab centres) — the
regions the job's report uses (:mod:`porecad.analysis.regions`). The nodes are
solved by damped Jacobi sweeps, shells then slabs, until every region's void
fraction over its samples is within :data:`REGION_TOL` of its mean requested
porosity.
"""

from __future__ import annotations

import numpy as np

from ..calibration import threshold_for_porosity
from ..errors import RangeError
from ..fields.base import Field

#: inside samples aimed at (the quantile's sampling error is then about 0.5 / sqrt(N) ≈ 4e-4)
TARGET_INSIDE = 1_500_000
#: the most grid points visited (a body filling 5 % of its box still gets about 600,000 inside samples)
MAX_GRID = 12_000_000
#: irrational fractions of the cell per axis (see the module docstring)
FRACTIONS = (0.3819660112501051, 0.6180339887498949, 0.2360679774997897)
#: fewer inside samples than this: no calibration (a body of a few voxels)
MIN_SAMPLES = 1000
#: the per-region tolerance the graded solve stops at (porosity units)
REGION_TOL = 0.002
#: the porosity range of the correction (that of :class:`porecad.grading.PorosityToThreshold`)
P_RANGE = (0.005, 0.995)


def structure_key(phi: np.ndarray, structure: str, sheet_level: float = 0.0) -> np.ndarray:
    """The structure variable ``k`` (void where ``k < c``) of TPMS values ``φ`` (module docstring)."""
    if structure == "pore":
        return phi
    if structure == "rod":
        return -phi
    return -np.abs(phi - np.float32(sheet_level))


def key_threshold(c: float, structure: str) -> float:
    """The threshold ``C`` of the structure from the key threshold ``c``."""
    return float(c) if structure == "pore" else -float(c)


def sample_axes(lo, hi, cell, volume: float, target_inside: int = TARGET_INSIDE, max_grid: int = MAX_GRID,
                min_spacing: float = 0.0):
    """Axes of the calibration grid over the box ``lo..hi`` (spacing incommensurate with ``cell``).

    The spacing gives about ``target_inside`` samples in a body of ``volume``, at most ``max_grid`` in the
    box, and is not below ``min_spacing`` (half the job's voxel: finer samples see nothing the mesh does).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ext = np.maximum(hi - lo, 1e-9)
    box = float(np.prod(ext))
    h = max((max(volume, 1e-12 * box) / target_inside) ** (1 / 3), (box / max_grid) ** (1 / 3), min_spacing)
    axes = []
    for a in range(3):
        L = float(cell[a])
        step = L / (max(np.floor(L / h - FRACTIONS[a]), 0.0) + FRACTIONS[a])  # >= h
        n = max(int(np.floor(ext[a] / step)), 1)
        start = lo[a] + 0.5 * (ext[a] - (n - 1) * step)
        axes.append(start + step * np.arange(n))
    return axes


def _inside(body, xs, ys, zs, skin: float):
    """Inside flags on the grid and, with a ``skin``, the depth of the inside samples below the surface.

    A mesh body answers inside/outside from its winding numbers alone (25 times cheaper than its signed
    distance on a grid) and the distance is computed at the inside samples only: a thin body fills a
    small part of its box, where nearly every grid point lies within the distance band.
    """
    if not hasattr(body, "inside_grid"):
        d = body.sample_grid(xs, ys, zs)
        return d < 0, -d[d < 0]
    inside = body.inside_grid(xs, ys, zs)
    if skin <= 0:
        return inside, None
    k, j, i = np.nonzero(inside)
    points = np.stack([np.asarray(xs, float)[i], np.asarray(ys, float)[j], np.asarray(zs, float)[k]], axis=1)
    return inside, body.distance(points)


class BodySamples:
    """Calibration samples of a planned body job (see the module docstring).

    ``plan``: its :class:`~porecad.lattice.plan.LatticePlan` (``body``, ``material``, ``domain_volume``,
    ``cell_size``, ``grid``, ``boundary``, ``body_info``).

    Attributes
    ----------
    key : (N,) float32
        Structure variable of each inside sample.
    core : (N,) bool
        Whether the lattice decides the sample (not in the skin).
    porosity : (N,) float32 or None
        The requested porosity at the sample (graded targets).
    depth, along : (N,) float32 or None
        Depth below the surface and coordinate along the slab axis (graded targets).
    grid_points : int
        Grid points visited.
    """

    def __init__(self, plan, requested: Field | None = None, slab_axis: int | None = None, depth=None,
                 target_inside: int = TARGET_INSIDE, max_grid: int = MAX_GRID, progress=None):
        body = plan.body
        material = plan.material
        lo, hi = body.bounds
        volume = plan.domain_volume
        xs, ys, zs = sample_axes(lo, hi, plan.cell_size, volume, target_inside, max_grid,
                                 min_spacing=0.5 * float(np.min(plan.grid.spacing)))
        skin = float((plan.body_info or {}).get("skin", 0.0)) if plan.boundary == "skin" else 0.0
        phi, structure, level = material.phi, material.structure, material.sheet_level
        planes = max(1, int(1_000_000 // max(len(xs) * len(ys), 1)))
        parts = {k: [] for k in ("key", "core", "porosity", "depth", "along")}
        for k0 in range(0, len(zs), planes):
            z = zs[k0:k0 + planes]
            inside, depth_in = _inside(body, xs, ys, z, skin)
            if inside.any():
                parts["key"].append(structure_key(phi.sample_grid(xs, ys, z)[inside], structure, level))
                parts["core"].append(depth_in > skin if skin > 0 else np.ones(int(inside.sum()), bool))
                if requested is not None:
                    parts["porosity"].append(requested.sample_grid(xs, ys, z)[inside].astype(np.float32))
                if depth is not None:
                    parts["depth"].append(depth.sample_grid(xs, ys, z)[inside].astype(np.float32))
                if slab_axis is not None:
                    along = (xs[None, None, :], ys[None, :, None], z[:, None, None])[slab_axis]
                    parts["along"].append(np.broadcast_to(along, inside.shape)[inside].astype(np.float32))
            if progress is not None:
                progress(min(k0 + planes, len(zs)), len(zs))
        join = {k: (np.concatenate(v) if v else None) for k, v in parts.items()}
        self.key = join["key"] if join["key"] is not None else np.zeros(0, np.float32)
        self.core = join["core"] if join["core"] is not None else np.zeros(0, bool)
        self.porosity, self.depth, self.along = join["porosity"], join["depth"], join["along"]
        self.structure = structure
        self.skin = skin
        self.grid_points = int(len(xs) * len(ys) * len(zs))
        self.spacing = [float(a[1] - a[0]) if len(a) > 1 else 0.0 for a in (xs, ys, zs)]

    @property
    def n_inside(self) -> int:
        return int(self.key.size)


def fit_uniform(samples: BodySamples, porosity: float) -> tuple[float, dict]:
    """The threshold ``C`` whose solid has void fraction ``porosity`` over the body's samples.

    Returns ``(C, info)`` with ``info``: ``samples`` (inside), ``core_fraction``,
    ``reachable`` (False when the skin alone holds more than ``1 − porosity`` of
    the body: ``C`` then makes the whole core void).

    Raises
    ------
    RangeError
        When the body holds too few samples for its cells.
    """
    n = samples.n_inside
    if n < MIN_SAMPLES:
        raise RangeError(f"the body holds only {n} calibration samples; it is too small for its cells")
    core = samples.key[samples.core]
    q = float(porosity) * n / max(core.size, 1)
    info = {"samples": n, "core_fraction": core.size / n, "reachable": q < 1.0}
    c = float(np.quantile(core, min(q, 1.0))) if core.size else 0.0
    return key_threshold(c, samples.structure), info


#: finer than this many samples per cell, the mesh's bias is below 0.001 (not computed)
BIAS_MAX_SAMPLES_PER_CELL = 40


def mesh_bias(tpms_type: str, structure: str, threshold: float, cell, spacing: float) -> float:
    """How much more porous the marching-cubes mesh of whole cells is than the cells themselves.

    Marching cubes cuts the curved walls by chords: a thin wall (a sheet at
    high porosity, a pore lattice near its most open) loses a good part of
    its volume at 15–20 samples per cell. Two cells per axis of the lattice
    at the threshold are meshed at the spacing nearest to ``spacing`` that
    divides the cell (at two phases of the grid: at the lattice's origin and
    half a spacing off), and their porosity by mesh volume is compared with
    the whole-cell porosity of :func:`porecad.calibration.porosity_of_threshold`.
    Returns the mean difference (0 when the cell holds more than
    :data:`BIAS_MAX_SAMPLES_PER_CELL` samples per edge).
    """
    from ..calibration import porosity_of_threshold
    from ..fields.tpms import TPMSField
    from ..mesh.polygonise import Grid, polygonise
    from ..mesh.validate import signed_volume
    from ..solids import StructureField
    L = np.broadcast_to(np.asarray(cell, dtype=float), (3,))
    n = np.maximum(np.rint(L / float(spacing)).astype(int), 2)
    if np.any(n > BIAS_MAX_SAMPLES_PER_CELL):
        return 0.0
    hh = L / n
    material = StructureField(TPMSField(tpms_type, L), structure, float(threshold))
    exact = float(porosity_of_threshold(tpms_type, structure, threshold))
    out = []
    for phase in (0.0, 0.5):
        grid = Grid(tuple((phase * hh).tolist()), tuple(hh.tolist()), tuple((2 * n + 1).tolist()))
        res = polygonise(material.sample_grid, grid, caps=True, threads=1)
        volume = float(signed_volume(res.vertices, res.faces)) if len(res.faces) else 0.0
        out.append(1.0 - volume / float(np.prod(2 * L)) - exact)
    return float(np.mean(out))


def achieved(samples: BodySamples, threshold: float) -> float:
    """Void fraction over the samples of the solid with a constant threshold ``C``."""
    c = threshold if samples.structure == "pore" else -threshold
    return float(np.count_nonzero(samples.core & (samples.key < c)) / max(samples.n_inside, 1))


class CalibratedPorosity(Field):
    """``p(x) + a(d(x)) + b(s(x))``, clipped to :data:`P_RANGE` (the graded correction of the module docstring).

    Parameters
    ----------
    requested : Field
        The porosity asked for (kept as :attr:`requested` for reports).
    depth : Field or None
        Depth below the body surface (mm), for the shell correction ``a``.
    shell_nodes, shell_values : arrays
        Nodes (depths) and values of ``a`` (linear between, constant beyond).
    axis : int
        Slab axis of ``b``.
    slab_nodes, slab_values : arrays
    limits : (lo, hi), optional
        The porosity range the result is clipped to (default :data:`P_RANGE`; the structure's valid
        range keeps the lattice connected).
    """

    def __init__(self, requested, depth, shell_nodes, shell_values, axis, slab_nodes, slab_values, limits=None):
        self.requested = requested
        self.depth = depth
        self.shell_nodes, self.shell_values = np.asarray(shell_nodes, float), np.asarray(shell_values, float)
        self.axis = int(axis)
        self.slab_nodes, self.slab_values = np.asarray(slab_nodes, float), np.asarray(slab_values, float)
        self.limits = tuple(P_RANGE if limits is None else (max(limits[0], P_RANGE[0]), min(limits[1], P_RANGE[1])))

    def unclipped(self, p, d, s):
        """``p + a(d) + b(s)`` before the clip to :attr:`limits`."""
        out = np.asarray(p, np.float64)
        if self.depth is not None and self.shell_values.size:
            out = out + np.interp(d, self.shell_nodes, self.shell_values)
        if self.slab_values.size:
            out = out + np.interp(s, self.slab_nodes, self.slab_values)
        return out

    def _correct(self, p, d, s):
        return np.clip(self.unclipped(p, d, s), *self.limits)

    def evaluate(self, points):
        p = self.requested(points)
        d = self.depth(points) if self.depth is not None else None
        return self._correct(p, d, points[:, self.axis])

    def sample_grid(self, xs, ys, zs):
        p = self.requested.sample_grid(xs, ys, zs)
        d = self.depth.sample_grid(xs, ys, zs) if self.depth is not None else None
        s = (np.asarray(xs, float)[None, None, :], np.asarray(ys, float)[None, :, None],
             np.asarray(zs, float)[:, None, None])[self.axis]
        return self._correct(p, d, np.broadcast_to(s, p.shape)).astype(np.float32)


def clipped_fraction(samples: BodySamples, field: CalibratedPorosity, axis: int) -> float:
    """The fraction of the core samples where ``field``'s correction was clipped to its limits."""
    if samples.porosity is None or not samples.core.any():
        return 0.0
    along = samples.along if samples.along is not None else np.zeros_like(samples.porosity)
    raw = field.unclipped(samples.porosity, samples.depth, along)[samples.core]
    lo, hi = field.limits
    return float(np.mean((raw < lo) | (raw > hi)))


def _region_index(values, edges):
    return np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)


def fit_graded(samples: BodySamples, tpms_type: str, structure: str, shell_edges, slab_edges,
               max_sweeps: int = 60, tol: float = REGION_TOL, limits=None):
    """Nodes of the graded correction (module docstring) for the samples' regions.

    Parameters
    ----------
    samples : BodySamples
        With ``porosity``, and ``depth`` / ``along`` for the regions used.
    shell_edges, slab_edges : arrays or None
        Region edges in depth (mm) and along the slab axis (mm), as in :func:`porecad.analysis.regions.region_porosity`.
    limits : (lo, hi), optional
        The lattice porosity range (as :class:`CalibratedPorosity`'s).

    Returns
    -------
    shell_nodes, shell_values, slab_nodes, slab_values : arrays
    info : dict
        ``sweeps``, ``max_region_error`` (sample void fraction − requested, worst region), ``converged``.
    """
    ps = np.linspace(P_RANGE[0], P_RANGE[1], 397)
    cs = np.asarray(threshold_for_porosity(tpms_type, structure, ps))
    if structure != "pore":
        cs = -cs  # the key threshold c(p) is increasing for every structure
    key, core, p = samples.key, samples.core, samples.porosity.astype(np.float64)
    groups = []
    if shell_edges is not None and samples.depth is not None:
        e = np.asarray(shell_edges, float)
        groups.append(("shell", _region_index(samples.depth, e), 0.5 * (e[:-1] + e[1:]), samples.depth))
    if slab_edges is not None and samples.along is not None:
        e = np.asarray(slab_edges, float)
        groups.append(("slab", _region_index(samples.along, e), 0.5 * (e[:-1] + e[1:]), samples.along))
    values = {name: np.zeros(len(nodes)) for name, _, nodes, _ in groups}

    def delta():
        out = np.zeros_like(p)
        for name, _, nodes, coord in groups:
            out += np.interp(coord, nodes, values[name])
        return out

    lo, hi = P_RANGE if limits is None else (max(limits[0], P_RANGE[0]), min(limits[1], P_RANGE[1]))

    def void_of(dlt):
        c = np.interp(np.clip(p + dlt, lo, hi), ps, cs)
        return core & (key < c)

    stats = []
    for name, idx, nodes, _ in groups:
        n = np.bincount(idx, minlength=len(nodes)).astype(float)
        want = np.bincount(idx, weights=p, minlength=len(nodes))
        corefrac = np.bincount(idx, weights=core, minlength=len(nodes))
        stats.append((n, np.divide(want, n, out=np.zeros_like(n), where=n > 0),
                      np.maximum(np.divide(corefrac, n, out=np.zeros_like(n), where=n > 0), 0.05)))
    worst, sweeps = np.inf, 0
    for sweeps in range(1, max_sweeps + 1):
        worst = 0.0
        for (name, idx, nodes, _), (n, want, corefrac) in zip(groups, stats):
            void = void_of(delta())
            got = np.divide(np.bincount(idx, weights=void, minlength=len(nodes)), n, out=np.zeros_like(n),
                            where=n > 0)
            err = np.where(n > 0, got - want, 0.0)
            worst = max(worst, float(np.max(np.abs(err))))
            values[name] = np.clip(values[name] - 0.8 * err / corefrac, -0.99, 0.99)
        if worst < tol:
            break
    void = void_of(delta())
    final = 0.0
    for (name, idx, nodes, _), (n, want, _c) in zip(groups, stats):
        got = np.divide(np.bincount(idx, weights=void, minlength=len(nodes)), n, out=np.zeros_like(n), where=n > 0)
        final = max(final, float(np.max(np.abs(np.where(n > 0, got - want, 0.0)))))
    empty = np.zeros(0)
    shell = next(((nodes, values[name]) for name, _, nodes, _ in groups if name == "shell"), (empty, empty))
    slab = next(((nodes, values[name]) for name, _, nodes, _ in groups if name == "slab"), (empty, empty))
    info = {"sweeps": sweeps, "max_region_error": final, "converged": final < tol}
    return shell[0], shell[1], slab[0], slab[1], info
