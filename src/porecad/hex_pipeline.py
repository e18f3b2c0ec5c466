"""The ``hex`` job: TPMS cells mapped into a structured hex mesh (documents 000 ch.3 and 004).

Steps: a structured hex mesh (a generated frustum/prismoid or cylinder, 004
§4; or the hexahedral parameterisation of a closed body, 000 ch.3), one TPMS
period per cell polygonised in the parameter box and mapped by 8-node or
20-node isoparametric shape functions, optional Laplacian smoothing (004 eqs.
4–5), optional Boolean with the body (004 §4), validation and the outputs.
"""

from __future__ import annotations

import time

import numpy as np

from . import __version__
from .errors import InputError

GENERATED = ("frustum", "cylinder")
#: A mapped scaffold is searched for self-intersections up to this size (a nearly folding cell shows up
#: there first; 8.7 M triangles take about 9 s on 2 cores).
MAX_CHECKED_TRIANGLES = 12_000_000


def _cells(grid):
    if grid is None or len(grid) != 3:
        raise InputError("--grid takes three cell counts NU NV NW")
    out = []
    for g in grid:
        if isinstance(g, bool) or int(g) != g or int(g) < 1:
            raise InputError(f"--grid cell counts must be positive integers, got {g!r}")
        out.append(int(g))
    return tuple(out)


def hex_nodes(body: dict, cells, element, progress=None):
    """The node grid of the hex mesh (hex8: corners; hex20: half-step nodes), the body mesh or None, facts."""
    from .maps.hexmesh import cylinder_nodes, frustum_nodes
    kind = body.get("kind")
    t = time.perf_counter()
    if kind == "frustum":
        nodes = frustum_nodes(cells, element=element, **{k: body[k] for k in ("bottom", "top", "height") if k in body})
        return nodes, None, {"kind": kind, "time_s": time.perf_counter() - t}
    if kind == "cylinder":
        nodes = cylinder_nodes(cells, element=element, **{k: body[k] for k in ("radius", "height") if k in body})
        return nodes, None, {"kind": kind, "time_s": time.perf_counter() - t}
    if kind == "mesh":
        from .bodies import load_body
        from .param.hexcube import hex_parameterisation
        v, f, rep = load_body(body["path"])
        fine = tuple(2 * c for c in cells) if element == "hex20" else cells
        from .param.hexcube import UNTANGLE_LIMIT
        limit = body.get("untangle_limit", UNTANGLE_LIMIT)
        nodes, info = hex_parameterisation(v, f, grid=fine, corners=body.get("corners"), progress=progress,
                                           untangle_limit=None if limit in (None, 0) else limit)
        facts = {"kind": "mesh", "path": str(body["path"]), "body_volume": float(rep["volume"]),
                 "parameterisation": {k: v_ for k, v_ in info.items() if k not in ("corners",)},
                 "corners": [int(c) for c in info.get("corners", [])], "time_s": time.perf_counter() - t}
        return nodes, (v, f), facts
    raise InputError(f"unknown hex body {kind!r}; use frustum, cylinder or a closed surface mesh")


def _boundary_distance(vertices, params, cells, body, body_kind, body_spec):
    """Distance of the vertices on the mesh's lateral boundary (u or v at its ends) to the body surface."""
    c = np.asarray(cells, dtype=np.float64)
    on = np.zeros(len(params), bool)
    for a in (0, 1):
        on |= np.isclose(params[:, a], 0.0) | np.isclose(params[:, a], c[a])
    if not on.any():
        return None
    v = vertices[on]
    if body_kind == "cylinder":
        d = np.abs(np.hypot(v[:, 0], v[:, 1]) - float(body_spec.get("radius", 10.0)))
    elif body is not None:
        from .bodies.mesh import MeshBody
        ext = float(np.ptp(body[0], axis=0).max())
        d = np.abs(MeshBody(body[0], body[1], band=0.25 * ext)(v))
    else:
        return None
    return {"max": float(d.max()), "mean": float(d.mean()), "vertices": int(on.sum())}


def run_hex(recipe: dict, force: bool = False, progress=None, prepared=None) -> dict:
    """Run a ``hex`` recipe; write its outputs atomically; return the report.

    ``prepared`` may carry the ``(nodes, body, facts)`` of :func:`hex_nodes` for this
    recipe's body, grid and element (benchmarks reuse one parameterisation for several types).
    """
    from .calibration import check_threshold, threshold_for_porosity
    from .fields.tpms import get_type
    from .maps.hexmesh import hex_scaffold
    from .mesh.smooth import laplacian_smooth
    from .mesh.validate import signed_volume
    from .outputs import check_outputs, finish_job, validated_report
    from .pipeline import _Stage
    from .solids import check_structure

    t0 = time.perf_counter()
    out = dict(recipe.get("output", {}))
    check_outputs(out, ("mesh", "report"), force)
    tp = dict(recipe.get("tpms", {}))
    tpms_type = get_type(str(tp.get("type", "P"))).name
    structure = check_structure(str(tp.get("structure", "pore")))
    if (tp.get("threshold") is None) == (tp.get("porosity") is None):
        raise InputError("give exactly one of --threshold C or --porosity P")
    if tp.get("porosity") is not None:
        threshold = float(threshold_for_porosity(tpms_type, structure, float(tp["porosity"])))
    else:
        threshold = check_threshold(tpms_type, structure, float(tp["threshold"]))
    element = str(recipe.get("element", "hex8"))
    if element not in ("hex8", "hex20"):
        raise InputError(f"unsupported element type {element!r}; use hex8 or hex20")
    body_spec = dict(recipe.get("body", {}))
    if body_spec.get("kind") == "hexfile":
        return _run_hex_file(recipe, body_spec, tpms_type, structure, threshold, element, out, force, t0)
    cells = _cells(recipe.get("grid"))
    mesh_spec = dict(recipe.get("mesh", {}))
    resolution = mesh_spec.get("resolution", 16)
    smooth = int(mesh_spec.get("smooth", 0))
    if smooth < 0:
        raise InputError(f"--smooth must be ≥ 0, got {smooth}")
    timings = {}
    nodes, body, facts = prepared if prepared is not None else hex_nodes(body_spec, cells, element, progress)
    facts = dict(facts)
    timings["hex_mesh_s"] = facts.pop("time_s")
    refine = [tuple(int(x) for x in r) for r in recipe.get("refine", [])]
    refine_box = recipe.get("refine_box")
    report = {"job": "hex", "porecad_version": __version__, "type": tpms_type, "structure": structure,
              "threshold": threshold, "element": element, "grid": list(cells), "resolution": int(resolution),
              "body": facts}
    cut = str(recipe.get("cut", "field" if recipe.get("intersect", True) else "none"))
    if cut not in ("field", "boolean", "none"):
        raise InputError(f"unknown cut {cut!r}; use field, boolean or none")
    if body is None:
        cut = "none"
    elif cut == "field" and (refine or refine_box):
        cut = "boolean"  # the refined (unstructured) scaffold is cut by the mesh Boolean
    hex_volume = mapped_volume(nodes, element, cells)
    domain_volume = hex_volume if cut == "none" else float(facts["body_volume"])
    # the field cut first; where folds near nearly flat parameter-box edges survive the local repair,
    # the mesh Boolean (manifold3d) of the uncut scaffold
    attempts = ["field", "boolean"] if cut == "field" else [cut]
    for attempt, mode in enumerate(attempts):
        clip = None
        if mode == "field":
            from .bodies.mesh import MeshBody
            ext = float(np.max(body[0].max(axis=0) - body[0].min(axis=0)))
            clip = MeshBody(body[0], body[1], band=0.05 * ext)
        t = time.perf_counter()
        if refine or refine_box:
            vertices, faces, unstructured = _refined_scaffold(nodes, cells, element, refine, tpms_type, structure,
                                                              threshold, resolution, report, box=refine_box)
            params = None
        else:
            res = hex_scaffold(nodes, tpms_type, structure, threshold, resolution, element=element,
                               progress=_Stage(progress)("mesh"), clip=clip)
            vertices, faces, params = res["vertices"], res["faces"], res["params"]
            report.update(res["jacobian"])
            report["porosity_parametric"] = 1.0 - res["inside_fraction"]
        timings["scaffold_s"] = timings.get("scaffold_s", 0.0) + time.perf_counter() - t
        if smooth and params is None:
            raise InputError("--smooth is available for unrefined structured meshes")
        if smooth:
            t = time.perf_counter()
            c = np.asarray(cells, dtype=np.float64)
            fixed = np.any(np.isclose(params, 0.0) | np.isclose(params, c), axis=1)
            vertices = laplacian_smooth(vertices, faces, iterations=smooth, lam=0.5, fixed=fixed)
            timings["smooth_s"] = time.perf_counter() - t
            report["smooth_iterations"] = smooth
        if params is not None and (mode != "field" or attempt == 0):
            dist = _boundary_distance(vertices, params, cells, body, facts["kind"], body_spec)
            if dist is not None:
                report["boundary_distance"] = dist
        if mode == "boolean":
            from .mesh.boolean import intersect
            t = time.perf_counter()
            vertices, faces = intersect(vertices, faces, *body)
            timings["intersect_s"] = time.perf_counter() - t
        if mode != "none":
            report["intersected_with_body"] = True
            report["cut"] = mode
        check = len(faces) <= MAX_CHECKED_TRIANGLES
        if not check:
            break
        from .mesh.repair import relax_self_intersections
        t = time.perf_counter()
        vertices, fix = relax_self_intersections(vertices, faces)
        timings["fold_repair_s"] = timings.get("fold_repair_s", 0.0) + time.perf_counter() - t
        report.pop("fold_repair", None)
        known_pairs = fix["pairs_after"]  # counted on the final vertices: validation need not search again
        if fix["pairs_before"]:
            report["fold_repair"] = fix
        if fix["pairs_after"] == 0 or attempt == len(attempts) - 1:
            break
        report["cut_fallback"] = (f"the field cut left {fix['pairs_after']} self-intersecting face pairs after "
                                  "the local repair; cut by the mesh Boolean instead")
    t = time.perf_counter()
    mesh_rep, _ = validated_report(vertices, faces, domain_volume, check_intersections=check,
                                   what="the hex scaffold", self_intersections=known_pairs if check else None)
    report.update(mesh_rep)
    timings["validate_s"] = time.perf_counter() - t
    if (refine or refine_box) and recipe.get("analysis", {}).get("pore_sizes", True):
        t = time.perf_counter()
        report["refinement"].update(_refined_pore_sizes(vertices, faces, unstructured))
        timings["pore_sizes_s"] = time.perf_counter() - t
    report["hex_volume"] = hex_volume
    report["porosity"] = 1.0 - float(signed_volume(vertices, faces)) / domain_volume
    return finish_job(report, vertices, faces, out, force, timings, t0, domain_volume=domain_volume)


def _hex_volume(corners):
    """Volume of a structured hex mesh: its boundary quads split into triangles (divergence theorem)."""
    g = np.asarray(corners, dtype=np.float64)
    total = 0.0
    for a in range(3):
        for end, sign in ((0, -1.0), (-1, 1.0)):
            face = np.take(g, end, axis=a)  # (n1, n2, 3) in the order of the remaining axes
            p00, p10 = face[:-1, :-1], face[1:, :-1]
            p11, p01 = face[1:, 1:], face[:-1, 1:]
            # outward orientation: remaining axes (b, c) in cyclic order after a give +a normals
            s = sign if a != 1 else -sign
            tri = np.einsum("...i,...i->...", p00, np.cross(p10, p11)) + \
                np.einsum("...i,...i->...", p00, np.cross(p11, p01))
            total += s * tri.sum() / 6.0
    return total


def mapped_volume(nodes, element, cells, samples_per_cell: int = 8) -> float:
    """Volume of the mapped parameter box (curved for hex20), from its boundary at 8 samples per cell edge."""
    from .maps.hexmesh import map_params
    axes = [np.linspace(0.0, c, c * samples_per_cell + 1) for c in cells]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    X = map_params(nodes, P.reshape(-1, 3), element).reshape(P.shape)
    return float(_hex_volume(X))


def _refined_scaffold(nodes, cells, element, refine, tpms_type, structure, threshold, resolution, report,
                      box=None):
    """Template refinement (points or a box of cells), then one TPMS cell per hexahedron (unstructured path)."""
    from .maps.hexcells import hex_cells_scaffold
    from .maps.hexmesh import check_jacobian, corner_grid, grid_hexes
    from .volmesh.refine import refine_points
    from .volmesh.refine_region import refine_region
    if element != "hex8":
        raise InputError("refinement works on 8-node hexahedra; use --element hex8")
    corners = corner_grid(nodes, element)
    report.update(check_jacobian(corners))
    points, hexes = grid_hexes(corners)
    nu, nv, nw = cells

    def vid(i, j, k):
        return (i * (nv + 1) + j) * (nw + 1) + k

    ids = []
    for (i, j, k) in refine:
        if not (0 <= i <= nu and 0 <= j <= nv and 0 <= k <= nw):
            raise InputError(f"refinement point ({i}, {j}, {k}) is outside the node grid 0..{nu} x 0..{nv} x 0..{nw}")
        ids.append(vid(i, j, k))
    if box is not None:
        lo, hi = np.asarray(box[:3], dtype=np.int64), np.asarray(box[3:], dtype=np.int64)
        if np.any(lo < 0) or np.any(hi > np.asarray(cells)) or np.any(hi <= lo):
            raise InputError(f"refinement box cells {tuple(lo)}..{tuple(hi)} must satisfy 0 <= lo < hi <= "
                             f"{tuple(cells)}")
        if refine:
            raise InputError("give either --refine-point or --refine-box, not both")
        box_ids = [vid(i, j, k) for i in range(lo[0], hi[0] + 1) for j in range(lo[1], hi[1] + 1)
                   for k in range(lo[2], hi[2] + 1)]
        p2, h2 = refine_region(points, hexes, box_ids)
        template = "full, face, edge and point 3-refinement templates (004 Fig. 6)"
        marked = [points[i] for i in box_ids]
    else:
        p2, h2 = refine_points(points, hexes, ids)
        template = "point (004 Fig. 6)"
        marked = [points[i] for i in ids]
    res = hex_cells_scaffold(p2, h2, tpms_type, structure, threshold, resolution)
    report["refinement"] = {"template": template, "points": [list(r) for r in refine],
                            "box": list(box) if box is not None else None,
                            "hexahedra_before": int(len(hexes)), "hexahedra": int(len(h2))}
    return res["vertices"], res["faces"], {"points": p2, "hexes": h2, "marked": marked, "box": box,
                                           "grid_points": points, "grid_hexes": hexes, "cells": cells}


def _refined_pore_sizes(vertices, faces, u):
    """Mean pore size in the refined cubes at the first marked point vs a 2×2×2 block of unrefined cells."""
    from .maps.hexmesh import region_pore_sizes
    p2, h2 = u["points"], u["hexes"]
    if u.get("box") is not None:  # the hexahedra inside the refined box of cells (27 per cell)
        m = np.asarray(u["marked"])
        blo, bhi = m.min(axis=0), m.max(axis=0)
        centres = p2[h2].mean(axis=1)
        at_v = np.flatnonzero(np.all((centres > blo) & (centres < bhi), axis=1))
        box_ref = (blo, bhi)
    else:
        v = np.asarray(u["marked"][0])
        at_v = np.flatnonzero(np.any(np.all(np.isclose(p2[h2], v), axis=2), axis=1))  # the small cubes at v
        box_ref = (p2[h2[at_v]].reshape(-1, 3).min(axis=0), p2[h2[at_v]].reshape(-1, 3).max(axis=0))
    nu, nv, nw = u["cells"]
    marked = np.asarray(u["marked"])
    gp, gh = u["grid_points"], u["grid_hexes"]
    best = None
    for i in range(nu - 1):
        for j in range(nv - 1):
            for k in range(nw - 1):
                cells = [((i + a) * nv + (j + b)) * nw + (k + c) for a in (0, 1) for b in (0, 1) for c in (0, 1)]
                pts = gp[gh[cells]].reshape(-1, 3)
                if any(np.any(np.all(np.isclose(pts, m), axis=1)) for m in marked):
                    continue
                best = (pts.min(axis=0), pts.max(axis=0))
                block = cells
                break
            if best:
                break
        if best:
            break
    if best is None:
        return {"note": "no 2x2x2 block of unrefined cells to compare with"}
    from .volmesh.hexshapes import hex_volumes
    small = float(np.cbrt(hex_volumes(p2, h2[at_v]).mean()))
    large = float(np.cbrt(hex_volumes(gp, gh[block]).mean()))
    ext = np.ptp(np.asarray(vertices), axis=0)
    spacing = max(small / 12.0, float(np.cbrt(np.prod(ext) / 1.2e7)))  # voxels: at most ~12 M
    sizes = region_pore_sizes(vertices, faces, [box_ref, best], spacing=spacing)
    return {"pore_size_refined": sizes[0], "pore_size_unrefined": sizes[1],
            "pore_size_ratio": sizes[0] / sizes[1], "cell_size_refined": small, "cell_size_unrefined": large,
            "cell_size_ratio": small / large}


def _run_hex_file(recipe, body_spec, tpms_type, structure, threshold, element, out, force, t0):
    """A hex-mesh file: one cube-symmetric TPMS cell per hexahedron, welded (unstructured path)."""
    from .maps.hexcells import hex_cells_scaffold
    from .mesh.validate import signed_volume
    from .outputs import finish_job, validated_report
    from .volmesh.hexshapes import hex_corner_jacobians, hex_volumes, read_hex_mesh
    if element != "hex8":
        raise InputError("hex-mesh files are read as 8-node hexahedra; use --element hex8")
    timings = {}
    t = time.perf_counter()
    points, hexes = read_hex_mesh(body_spec["path"])
    timings["read_s"] = time.perf_counter() - t
    t = time.perf_counter()
    res = hex_cells_scaffold(points, hexes, tpms_type, structure, threshold,
                             recipe.get("mesh", {}).get("resolution", 16))
    timings["scaffold_s"] = time.perf_counter() - t
    vertices, faces = res["vertices"], res["faces"]
    domain_volume = float(hex_volumes(points, hexes).sum())
    jac = hex_corner_jacobians(points, hexes)
    report = {"job": "hex", "porecad_version": __version__, "type": tpms_type, "structure": structure,
              "threshold": threshold, "element": element, "body": {"kind": "hexfile", "path": str(body_spec["path"])},
              "hexahedra": int(len(hexes)), "min_corner_jacobian": float(jac.min())}
    from .maps.hexmesh import scaled_jacobians_unstructured
    report["min_scaled_jacobian"] = float(scaled_jacobians_unstructured(points, hexes).min())
    mesh_rep, _ = validated_report(vertices, faces, domain_volume,
                                   check_intersections=len(faces) <= MAX_CHECKED_TRIANGLES,
                                   what="the hex scaffold")
    report.update(mesh_rep)
    report["hex_volume"] = domain_volume
    report["porosity"] = 1.0 - float(signed_volume(vertices, faces)) / domain_volume
    return finish_job(report, vertices, faces, out, force, timings, t0, domain_volume=domain_volume)
