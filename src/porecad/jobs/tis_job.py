"""The ``tis`` job: tetrahedral implicit surfaces over a tet mesh (documents 002 and 000 ch.4).

Steps (002 Fig. 4): a tet domain (one regular tetrahedron, a built-in shape, a
tet-mesh file, or a closed body tetrahedralised on a BCC lattice), the TIS
field in every tetrahedron, polygonised per tetrahedron on its barycentric
lattice (``method = "lattice"``) or on a Cartesian grid through point location
(``method = "grid"``) and, for a body, cut to it in field space (the body's
signed distance joins the TIS field as an R-function intersection, so the cut
surface is marched with the rest and cannot cross it), optional smoothing
(Laplacian, then curvature-based; the body's surface stays), a local repair
of any self-intersecting faces, validation.

Recipe::

    job = "tis"
    [domain]  kind = "regular-tet" | "two-tets" | "icosahedron" | "tet-mesh" | "body"
              path = "femur.stl", size = 10.0 (mm, built-in shapes), tets = 1000 (body)
    [tis]     type = "P", lambda = 1.0, structure = "pore", relative = 0.176 | threshold = 0.3
    [mesh]    resolution = 17 (samples per tet edge), method = "lattice", smooth = 0
    [output]  mesh, report, recipe, tets
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import InputError, ResourceError
from ..findings import Finding
from .contract import Job, Result, RunOptions, Timer, Validation

BUILTIN_DOMAINS = ("regular-tet", "two-tets", "icosahedron")
DOMAIN_KINDS = BUILTIN_DOMAINS + ("tet-mesh", "body")
#: largest number of lattice samples (tets x samples per tet)
MAX_LATTICE_SAMPLES = 600_000_000


@dataclasses.dataclass(frozen=True)
class TisSpec:
    """A checked ``tis`` recipe (see the module docstring for the keys)."""

    domain_kind: str
    domain_path: str | None
    size: float
    tets: int
    type: str
    lam: tuple
    structure: str
    relative: float | None
    threshold: float | None
    resolution: int
    method: str
    smooth: int

    @classmethod
    def from_recipe(cls, r):
        from ..fields.tis import check_lambda, check_type
        d = r.table("domain")
        kind = d.get("kind")
        path = d.get("path") if kind in ("tet-mesh", "body") else None
        if kind in ("tet-mesh", "body") and path is None:
            raise d.error("path", f"a {kind} domain needs a path")
        size = d.get("size")
        tets = d.get("tets")
        if d.has("tets") and kind != "body":
            raise d.error("tets", "sets the tet count of a tetrahedralised surface body; this domain is given")
        d.done()
        t = r.table("tis")
        kind_t = t.get("type", check=check_type)
        lam = t.get("lambda", check=check_lambda)
        if lam.size not in (1, 4) or float(lam.max()) > 1000:
            raise t.error("lambda", "takes one value or four (periods per tet coordinate), each ≤ 1000")
        structure = t.get("structure")
        relative = t.get("relative")
        threshold = t.get("threshold")
        t.one_of("relative")
        t.done()
        m = r.table("mesh")
        resolution = m.get("resolution", 200 if kind == "regular-tet" else 17)
        method = m.get("method")
        smooth = m.get("smooth")
        m.done()
        return cls(kind, path, size, tets, kind_t, tuple(np.atleast_1d(lam).tolist()), structure, relative,
                   threshold, resolution, method, smooth)

    def inputs(self) -> list:
        return [self.domain_path] if self.domain_path else []

    @property
    def lam_value(self):
        return float(self.lam[0]) if len(self.lam) == 1 else np.asarray(self.lam)


def tet_domain(kind: str, path=None, size: float = 10.0, tets: int = 1000):
    """The tet domain: ``(points, tets, colors, body, info)``.

    ``body`` is ``(vertices, faces)`` of the closed body the scaffold is cut to
    (None for a tet domain given directly); ``colors`` a rainbow vertex
    colouring or None.
    """
    from .. import volmesh as vm

    info = {"kind": kind}
    t0 = time.perf_counter()
    if kind == "regular-tet":
        points, cells = vm.regular_tetrahedron(size)
    elif kind == "two-tets":
        points, cells = vm.two_tetrahedra(size)
    elif kind == "icosahedron":
        points, cells = vm.icosahedron_tets(size)
    elif kind == "tet-mesh":
        points, cells = vm.read_tet_mesh(path)
        info["path"] = str(path)
    elif kind == "body":
        points, cells, body, colors, binfo = vm.tetrahedralise_body(path, tets)
        info.update(binfo)
        info["time_s"] = time.perf_counter() - t0
        return points, cells, colors, body, info
    else:
        raise InputError(f"unknown tet domain {kind!r}; use {', '.join(DOMAIN_KINDS)}")
    points, cells = vm.check_tet_mesh(points, cells)
    info["time_s"] = time.perf_counter() - t0
    return points, cells, vm.rainbow_coloring(cells), None, info


def run(spec: TisSpec, progress=None, options=None) -> Result:
    """Build the TIS scaffold of ``spec`` (nothing written).

    The stages: :func:`_domain` (the tet mesh, its body and figures) → :func:`_surface` (the TIS
    level set over the tets, cut to the body in field space: vertices, faces, the cut's facts) →
    :func:`_smooth` (Taubin then curvature smoothing, caps and the body's surface fixed) →
    :func:`_finish` (pinched vertices split, folds relaxed, validated, porosity of the domain).
    """
    timer = (options or RunOptions()).stages  # the runner's stage clock: it reports the timings
    lam = spec.lam_value
    report = {"type": spec.type, "lambda": lam.tolist() if isinstance(lam, np.ndarray) else lam,
              "structure": spec.structure, "method": spec.method, "resolution": spec.resolution}
    points, tets, colors, body = _domain(spec, report, timer, getattr(options, "memory_limit", None))
    warnings = _threshold_findings(spec)
    vertices, faces, n_caps, domain_mesh, cut_vertices = _surface(spec, points, tets, colors, body, report, timer)
    if spec.type == "G" and colors is None:
        warnings.append(Finding(
            "no-rainbow-colouring", "this tet mesh has no rainbow vertex colouring, so TIS-G (not symmetric in its "
            "four coordinates) takes its values on shared faces from one side: the surface is closed but only C0 "
            f"by sampling (largest jump between sides {report.get('face_jump', 0):.3g})",
            {"face_jump": report.get("face_jump")}))
    if len(faces) == 0:
        raise InputError(f"threshold {report['threshold']:.4g} leaves no material in the domain "
                         f"(TIS values span {report['value_range'][0]:.4g} … {report['value_range'][1]:.4g})")
    if spec.smooth:
        with timer("smooth"):
            vertices = _smooth(vertices, faces, spec.smooth, n_caps, cut_vertices)
        report["smooth_iterations"] = spec.smooth
    porous_volume = report["domain"]["volume"]
    if body is not None:
        from ..mesh.validate import signed_volume
        # cut in field space (tis_lattice_mesh / tis_grid_mesh with clip): the body on the same samples
        porous_volume = float(signed_volume(*domain_mesh))
        report["domain"]["body_volume_in_tets"] = porous_volume
        report["cut"] = "field"
    report["warnings"] = warnings
    from ..maps.domain_surface import tet_mesh_surface
    from ..volmesh import write_tet_mesh
    from .contract import DeferredDomain
    vertices, faces, validation = _finish(vertices, faces, porous_volume, options, report, timer)
    extra = {"tets": lambda path, force: write_tet_mesh(path, points, tets, force=force)}
    # the analysis domain: the tets cut to the body, else the tet mesh's boundary
    domain = domain_mesh if body is not None else DeferredDomain(tet_mesh_surface, points, tets)
    return Result(report, vertices, faces, domain_volume=porous_volume, domain=domain, design=False,
                  extra_outputs=extra, body=body, validation=validation)


def _domain(spec: TisSpec, report: dict, timer: Timer, memory_limit=None):
    """The tet domain, bounded before any TIS work: ``(points, tets, colours, body)``; its figures in ``report``.

    A surface body is sized from its target tet count before it is tetrahedralised, every domain again
    from its tets (:func:`require_size`).
    """
    from ..volmesh import signed_volumes, tet_quality
    if spec.domain_kind == "body":
        require_size(spec, spec.tets, memory_limit)
    with timer("domain"):
        points, tets, colors, body, dinfo = tet_domain(spec.domain_kind, spec.domain_path, spec.size, spec.tets)
    dinfo.pop("time_s", None)
    require_size(spec, len(tets), memory_limit, boundary_faces(tets))
    report["domain"] = {**dinfo, "volume": float(signed_volumes(points, tets).sum()),
                        "quality": tet_quality(points, tets), "rainbow_colouring": colors is not None}
    report["tets"] = int(len(tets))
    return points, tets, colors, body


#: what a tet domain costs besides its lattice (tetrahedralising, topology, quality; about 2.5 kB per tet measured)
BYTES_PER_TET = 3000
#: TIS triangles per tet and period at n samples per edge: about 4 n² (measured 3.3-3.9 n² at n = 17 and 34)
TRIS_PER_TET = 4.0
#: peak bytes and seconds per TIS triangle (tets of a ball at n = 17 and 34: 440-446 bytes, 4.8-9.8 us on 2 cores)
BYTES_PER_TIS_TRIANGLE = 450
SECONDS_PER_TIS_TRIANGLE = 8e-6


#: TIS triangles per boundary face of the domain at n samples per edge, the caps where the solid meets it (a
#: face's 0.43 a², about half of it solid): without them one regular tet (4 faces, G, λ 1) made 8.2 n² for 4.0 n²
#: counted, two tets (6 faces) 15.4 n² for 8.0 n², i.e. 1.05 and 1.22 n² a face (bench/estimates.md); the caps'
#: share is small in a tet mesh of a body (most faces inside)
TRIS_PER_BOUNDARY_FACE = 1.0


def boundary_faces(tets) -> int:
    """Faces of a tet mesh that belong to one tet only (its boundary)."""
    t = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    if not len(t):
        return 0
    f = np.sort(np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]]), axis=1)
    n = int(t.max()) + 1
    if n < 2 ** 21:  # one int64 key a face: a 1-D unique, fast
        _, counts = np.unique((f[:, 0] * n + f[:, 1]) * n + f[:, 2], return_counts=True)
    else:
        _, counts = np.unique(f, axis=0, return_counts=True)
    return int((counts == 1).sum())


def require_size(spec: TisSpec, n_tets: float, memory_limit=None, n_boundary: float = 0.0) -> None:
    """Refuse (ResourceError, one line with the estimate) a TIS job over the lattice-sample bound or the memory.

    ``n_boundary``: the domain's boundary faces where they are known (:func:`boundary_faces`)."""
    from ..resources import require_fits, work_estimate
    n = spec.resolution
    samples = n_tets * n ** 3 / 6.0
    change = "lower the `resolution` or the tet count (`tets`)"
    if spec.method == "lattice" and samples > MAX_LATTICE_SAMPLES:
        raise ResourceError(f"{n_tets:,.0f} tets at {n} samples per edge are {samples:,.0f} lattice samples (at most "
                            f"{MAX_LATTICE_SAMPLES:,}); {change}")
    tris = (TRIS_PER_TET * float(np.max(spec.lam_value)) * n_tets + TRIS_PER_BOUNDARY_FACE * n_boundary) * n * n
    est = work_estimate(samples, tris, sample_bytes=56, triangle_bytes=BYTES_PER_TIS_TRIANGLE,
                        triangle_seconds=SECONDS_PER_TIS_TRIANGLE, extra_bytes=BYTES_PER_TET * n_tets)
    require_fits(est, memory_limit, change, "the TIS scaffold")


def _threshold_findings(spec: TisSpec) -> list:
    """``threshold-disconnected`` for a relative threshold outside the type's connected range (002 §4)."""
    from ..fields.tis import RELATIVE_RANGES
    rel = spec.relative
    if rel is None:
        return []
    lo_r, hi_r = RELATIVE_RANGES[spec.type]
    if lo_r <= rel <= hi_r or float(np.max(spec.lam_value)) != 1.0:
        return []
    return [Finding("threshold-disconnected", f"relative threshold {rel:g} lies outside TIS-{spec.type}'s connected "
                    f"range {lo_r}–{hi_r} for one period (002 §4): pores may close or the surface break up",
                    {"relative": rel, "lo": lo_r, "hi": hi_r})]


def _surface(spec: TisSpec, points, tets, colors, body, report: dict, timer: Timer):
    """The TIS solid over the tets (lattice or grid sampling), cut to ``body`` in field space.

    Returns ``(vertices, faces, n_caps, domain_mesh, cut_vertices)``: ``n_caps`` the cap faces at the end
    of ``faces`` (lattice method; None for the grid), ``domain_mesh`` the body on the same samples,
    ``cut_vertices`` the vertices on the body's surface. The threshold and sample figures go in ``report``.
    """
    from ..maps.tis_mesh import body_clip, tis_grid_mesh, tis_lattice_mesh
    lam, rel, thr = spec.lam_value, spec.relative, spec.threshold
    clip = body_clip(body, points, tets, spec.resolution) if body is not None else None
    with timer("tis"):
        if spec.method == "lattice":
            res = tis_lattice_mesh(points, tets, spec.type, lam, threshold=thr, relative=rel,
                                   subdivisions=spec.resolution - 1, structure=spec.structure, colors=colors,
                                   clip=clip)
            report.update(threshold=res.threshold, value_range=list(res.value_range),
                          porosity_samples=res.sample_porosity, lattice_points=res.lattice_points,
                          slots=res.slots, face_jump=res.face_jump)
            out = res.vertices, res.faces, res.n_cap_faces, res.domain, res.cut_vertices
        else:
            g = tis_grid_mesh(points, tets, spec.type, lam, threshold=thr, relative=rel,
                              resolution=spec.resolution, structure=spec.structure, colors=colors, clip=clip)
            report.update(threshold=g["threshold"], value_range=list(g["value_range"]),
                          porosity_samples=g["sample_porosity"], grid=g["grid"], slots=g["slots"])
            out = g["vertices"], g["faces"], None, g.get("domain"), g.get("cut_vertices")
    if rel is not None:
        report["relative_threshold"] = float(rel)
    return out


def _smooth(vertices, faces, iterations: int, n_caps, cut_vertices):
    """Taubin then curvature smoothing; the cap faces' vertices and the body's surface stay where they are."""
    from ..mesh.smooth import curvature_smooth, taubin_smooth
    fixed = np.zeros(len(vertices), bool)
    if n_caps:
        fixed[np.unique(faces[len(faces) - n_caps:])] = True
    if cut_vertices is not None:
        fixed |= cut_vertices  # the body's surface stays where it is
    vertices = taubin_smooth(vertices, faces, iterations=iterations, fixed=fixed)
    return curvature_smooth(vertices, faces, iterations=iterations, lam=0.3, fixed=fixed)


def _finish(vertices, faces, porous_volume: float, options, report: dict, timer: Timer):
    """Split pinched vertices and relax folds; ``(vertices, faces, validation)`` (how the runner checks them)."""
    from ..mesh.pinch import split_pinched_vertices
    vertices, faces, pinched = split_pinched_vertices(vertices, faces)  # where the cut meets a sheet at a vertex
    if pinched:
        report["pinched_vertices_split"] = pinched
    check = options.check_intersections if options and options.check_intersections is not None \
        else len(faces) <= 2_000_000
    known = None
    if check:
        from ..mesh.repair import relax_self_intersections
        with timer("fold_repair"):
            vertices, fix = relax_self_intersections(vertices, faces)
        known = fix["pairs_after"]  # counted on the final vertices: validation need not search again
        if fix["pairs_before"]:
            report["fold_repair"] = fix
    return vertices, faces, Validation("the TIS scaffold", porous_volume, intersections=check, known_pairs=known)


JOB = Job("tis", TisSpec, run, outputs=("mesh", "report", "recipe", "tets"),
          summary=("type", "threshold", "porosity", "tets"),
          title="tetrahedral implicit surfaces over a tet mesh (002, 000 ch.4)")
