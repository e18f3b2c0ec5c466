"""The ``tis`` job: tetrahedral implicit surfaces over a tet mesh (documents 002 and 000 ch.4).

Steps (002 Fig. 4): a tet domain (one regular tetrahedron, a built-in shape, a
tet-mesh file, or a closed body tetrahedralised on a BCC lattice), the TIS
field in every tetrahedron, polygonised per tetrahedron on its barycentric
lattice (``method = "lattice"``) or on a Cartesian grid through point location
(``method = "grid"``), optional smoothing (Laplacian, then curvature-based),
the intersection with the body, validation, and the outputs.

A recipe is a plain dict::

    job = "tis"
    [domain]  kind = "regular-tet" | "two-tets" | "icosahedron" | "tet-mesh" | "body", path, size, tets
    [tis]     type = "P", lambda = 1.0, relative = 0.176 | threshold = 0.3, structure = "pore"
    [mesh]    resolution = 17 (samples per tet edge), method = "lattice", smooth = 0
    [output]  mesh, report, tets
"""

from __future__ import annotations

import time

import numpy as np

from . import __version__
from .errors import InputError

BUILTIN_DOMAINS = ("regular-tet", "two-tets", "icosahedron")


def tet_domain(spec: dict):
    """Build the tet domain of a recipe: ``(points, tets, colors, body, info)``.

    ``body`` is ``(vertices, faces)`` of the closed body the scaffold is cut to
    (None for a tet domain given directly); ``colors`` a rainbow vertex
    colouring or None.
    """
    from . import volmesh as vm

    kind = spec.get("kind", "regular-tet")
    size = float(spec.get("size", 10.0))
    if not np.isfinite(size) or size <= 0:
        raise InputError(f"--size must be a positive length in mm, got {spec.get('size')!r}")
    body = None
    info = {"kind": kind}
    t0 = time.perf_counter()
    if kind == "regular-tet":
        points, tets = vm.regular_tetrahedron(size)
    elif kind == "two-tets":
        points, tets = vm.two_tetrahedra(size)
    elif kind == "icosahedron":
        points, tets = vm.icosahedron_tets(size)
    elif kind == "tet-mesh":
        points, tets = vm.read_tet_mesh(spec["path"])
        info["path"] = str(spec["path"])
    elif kind == "body":
        points, tets, body, colors, binfo = vm.tetrahedralise_body(spec["path"], spec.get("tets", 1000))
        info.update(binfo)
        info["time_s"] = time.perf_counter() - t0
        return points, tets, colors, body, info
    else:
        raise InputError(f"unknown tet domain {kind!r}; use regular-tet, two-tets, icosahedron, a tet-mesh "
                         "file or a closed body")
    points, tets = vm.check_tet_mesh(points, tets)
    info["time_s"] = time.perf_counter() - t0
    return points, tets, vm.rainbow_coloring(tets), body, info


def run_tis(recipe: dict, force: bool = False, progress=None, check_intersections=None) -> dict:
    """Run a ``tis`` recipe; write its outputs atomically; return the report."""
    from .fields.tis import RELATIVE_RANGES, check_lambda, check_type
    from .maps.tetmesh import tis_lattice_mesh
    from .mesh.boolean import intersect
    from .mesh.smooth import curvature_smooth, taubin_smooth
    from .mesh.validate import signed_volume
    from .outputs import check_outputs, finish_job, validated_report
    from .volmesh import signed_volumes, tet_quality, write_tet_mesh

    t_start = time.perf_counter()
    out = dict(recipe.get("output", {}))
    check_outputs(out, ("mesh", "report", "tets"), force)
    tis = dict(recipe.get("tis", {}))
    kind = check_type(tis.get("type", "P"))
    lam = check_lambda(tis.get("lambda", 1.0))
    structure = str(tis.get("structure", "pore"))
    if structure not in ("pore", "rod"):
        raise InputError(f"TIS structures are pore and rod, got {structure!r}")
    rel, thr = tis.get("relative"), tis.get("threshold")
    if (rel is None) == (thr is None):
        raise InputError("give exactly one of --relative-threshold R or --threshold C")
    mesh_spec = dict(recipe.get("mesh", {}))
    resolution = mesh_spec.get("resolution", 17)
    if isinstance(resolution, bool) or int(resolution) != resolution or int(resolution) < 3:
        raise InputError(f"--resolution (samples per tet edge) must be an integer ≥ 3, got {resolution!r}")
    resolution = int(resolution)
    smooth = int(mesh_spec.get("smooth", 0))
    if smooth < 0:
        raise InputError(f"--smooth must be ≥ 0, got {smooth}")
    method = mesh_spec.get("method", "lattice")
    if method not in ("lattice", "grid"):
        raise InputError(f"unknown method {method!r}; use lattice or grid")
    report = {"job": "tis", "porecad_version": __version__, "type": kind,
              "lambda": lam.tolist() if lam.ndim else float(lam), "structure": structure, "method": method,
              "resolution": resolution}
    warnings = []
    timings = {}

    points, tets, colors, body, dinfo = tet_domain(dict(recipe.get("domain", {})))
    timings["domain_s"] = dinfo.pop("time_s")
    domain_volume = float(signed_volumes(points, tets).sum())
    quality = tet_quality(points, tets)
    report["domain"] = {**dinfo, "volume": domain_volume, "quality": quality,
                        "rainbow_colouring": colors is not None}
    report["tets"] = int(len(tets))
    if rel is not None:
        lo_r, hi_r = RELATIVE_RANGES[kind]
        if not lo_r <= float(rel) <= hi_r and float(np.max(lam)) == 1.0:
            warnings.append(f"relative threshold {float(rel):g} lies outside TIS-{kind}'s connected range "
                            f"{lo_r}–{hi_r} for one period (002 §4): pores may close or the surface break up")

    t = time.perf_counter()
    if method == "lattice":
        res = tis_lattice_mesh(points, tets, kind, lam, threshold=thr, relative=rel,
                               subdivisions=resolution - 1, structure=structure, colors=colors)
        vertices, faces = res.vertices, res.faces
        report.update(threshold=res.threshold, value_range=list(res.value_range),
                      porosity_samples=res.sample_porosity, lattice_points=res.lattice_points,
                      slots=res.slots, face_jump=res.face_jump)
        n_caps = res.n_cap_faces
    else:
        from .maps.tetmesh import tis_grid_mesh
        g = tis_grid_mesh(points, tets, kind, lam, threshold=thr, relative=rel, resolution=resolution,
                          structure=structure, colors=colors)
        vertices, faces = g["vertices"], g["faces"]
        report.update(threshold=g["threshold"], value_range=list(g["value_range"]),
                      porosity_samples=g["sample_porosity"], grid=g["grid"], slots=g["slots"])
        n_caps = None
    if rel is not None:
        report["relative_threshold"] = float(rel)
    if kind == "G" and colors is None:
        warnings.append("this tet mesh has no rainbow vertex colouring, so TIS-G (not symmetric in its four "
                        "coordinates) takes its values on shared faces from one side: the surface is closed "
                        f"but only C0 by sampling (largest jump between sides {report.get('face_jump', 0):.3g})")
    timings["tis_s"] = time.perf_counter() - t
    if len(faces) == 0:
        raise InputError(f"threshold {report['threshold']:.4g} leaves no material in the domain "
                         f"(TIS values span {report['value_range'][0]:.4g} … {report['value_range'][1]:.4g})")

    if smooth:
        t = time.perf_counter()
        fixed = np.zeros(len(vertices), bool)
        if n_caps:
            fixed[np.unique(faces[len(faces) - n_caps:])] = True
        vertices = taubin_smooth(vertices, faces, iterations=smooth, fixed=fixed)
        vertices = curvature_smooth(vertices, faces, iterations=smooth, lam=0.3, fixed=fixed)
        timings["smooth_s"] = time.perf_counter() - t
        report["smooth_iterations"] = smooth

    porous_volume = domain_volume
    if body is not None:
        t = time.perf_counter()
        from .mesh.weld import compact
        from .volmesh import boundary_faces
        hull = compact(points, boundary_faces(tets)[0])  # the tet domain's outward boundary
        inside = intersect(*hull, *body)
        porous_volume = float(signed_volume(*inside))
        vertices, faces = intersect(vertices, faces, *body)
        timings["intersect_s"] = time.perf_counter() - t
        report["domain"]["body_volume_in_tets"] = porous_volume
        if len(faces) == 0:
            raise InputError("the scaffold does not meet the body")

    t = time.perf_counter()
    if check_intersections is None:
        check_intersections = len(faces) <= 2_000_000
    mesh_rep, _ = validated_report(vertices, faces, porous_volume, check_intersections=check_intersections,
                                   what="the TIS scaffold")
    report.update(mesh_rep)
    timings["validate_s"] = time.perf_counter() - t
    report["porosity"] = 1.0 - float(signed_volume(vertices, faces)) / porous_volume
    report["domain_volume"] = porous_volume

    if out.get("tets"):
        write_tet_mesh(out["tets"], points, tets, force=force)
        report["tets_file"] = str(out["tets"])
    if warnings:
        report["warnings"] = warnings
    return finish_job(report, vertices, faces, out, force, timings, t_start, domain_volume=porous_volume,
                      design=False)
