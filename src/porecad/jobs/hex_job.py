"""The ``hex`` job: TPMS cells mapped into a structured hex mesh (documents 000 ch.3 and 004).

Steps: a structured hex mesh (a generated frustum/prismoid or cylinder, 004
§4; or the hexahedral parameterisation of a closed body, 000 ch.3), one TPMS
period per cell polygonised in the parameter box and mapped by 8-node or
20-node isoparametric shape functions, optional Laplacian smoothing (004 eqs.
4–5), the cut to the body (in field space, or by a Boolean, 004 §4), validation.

Recipe::

    job = "hex"
    [body]     kind = "frustum" | "cylinder" | "mesh" | "hexfile", path, corners = [8 vertex ids],
               untangle_limit = 60 (seconds for untangling a body's parameterisation; 0: none)
               bottom = [20, 20], top = [10, 10], height = 20 (frustum); radius = 10, height = 20 (cylinder)
    [tpms]     type = "P", structure = "pore", threshold = 0.0 | porosity = 0.6,
               allow_closed_pores = false (build outside the valid range)
    grid = [4, 4, 6], element = "hex8" | "hex20", cut = "field" | "boolean" | "none"
    refine = [[i, j, k], ...] | refine_box = [i0, j0, k0, i1, j1, k1]
    [mesh]     resolution = 16 (samples per cell edge), smooth = 0
    [analysis] pore_sizes = true (refined cells vs unrefined)
    [output]   mesh, report, recipe
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError, ResourceError
from ..resources import mapped_estimate, require_fits, require_param_samples
from ..maps.hex_grid import HexBody, hex_nodes, mapped_volume
from .contract import DeferredDomain, Job, Result, RunOptions, Timer, Validation, stage_progress

#: A mapped scaffold is searched for self-intersections up to this size (a nearly folding cell shows up
#: there first; 8.7 M triangles take about 9 s on 2 cores).
MAX_CHECKED_TRIANGLES = 12_000_000


#: what to change when a hex scaffold is too large
FEWER = "lower the `resolution` or use fewer cells (`grid`)"


def estimated_cells(spec) -> float:
    """Cells a structured hex job meshes (the templates of :mod:`porecad.volmesh.refine_region`).

    A refinement point splits each of its (up to 8) hexahedra into 4 (the point template; no two points share
    one). A box of cells turns each cell inside into 27 and those around it by how many of their corners it
    marks: a face's 22, an edge's 11, a corner's 4 (measured: a 4³ frustum refined at one point, 64 → 88).
    """
    cells = np.asarray(spec.cells, dtype=np.float64)
    total = float(np.prod(cells))
    for p in spec.refine:
        total += 3.0 * float(np.prod([max(min(int(q), int(n) - 1) - max(int(q) - 1, 0) + 1, 0)
                                      for q, n in zip(p, spec.cells)]))
    if spec.refine_box:
        lo, hi = np.asarray(spec.refine_box[:3], float), np.asarray(spec.refine_box[3:], float)
        extra = {8: 26.0, 4: 21.0, 2: 10.0, 1: 3.0}
        # per axis: the cells whose two corner planes both lie in [lo, hi] (2 marked) and the one each side (1)
        axes = []
        for a in range(3):
            inside = max(hi[a] - lo[a], 0.0)
            side = float(lo[a] > 0) + float(hi[a] < cells[a])
            axes.append(((2, inside), (1, side)))
        for (m0, n0) in axes[0]:
            for (m1, n1) in axes[1]:
                for (m2, n2) in axes[2]:
                    total += extra[m0 * m1 * m2] * n0 * n1 * n2
    return total


def _refine_crossings(vertices, params, faces, nodes, cells, element, timer, report):
    """The crossing triangles of a mapped scaffold split in the parameter box (:func:`refine_mapped_crossings`).

    Returns ``vertices, params, faces, pairs``: ``pairs`` is an empty array
    when none cross any more (the repair need not search again); else the
    input mesh unchanged and None (measured: the segmented body's hex20, whose
    crossings the local repair of the unrefined mesh removes).
    """
    from ..maps.hexmesh import map_params
    from ..maps.mapped_refine import refine_mapped_crossings
    c = np.asarray(cells, dtype=np.float64)

    def map_points(q):
        return map_params(nodes, np.clip(q, 0.0, 1.0) * c, element)

    with timer("crossing_refinement"):
        v2, p01, f2, fix = refine_mapped_crossings(vertices, params / c, faces, map_points, give_up=2.0)
    report.pop("crossing_refinement", None)
    if fix["pairs_before"]:
        report["crossing_refinement"] = fix
    if fix["pairs_after"]:  # not all split apart: the local repair works on the unrefined mesh, as before
        fix["kept"] = False
        return vertices, params, faces, None
    return v2, p01 * c, f2, np.empty((0, 2), np.int64)


def _boundary_distance(vertices, params, cells, body, body_kind, nodes):
    """Distance of the vertices on the mesh's lateral boundary (u or v at its ends) to the body surface (a
    cylinder's: the circle its grid's outer nodes lie on)."""
    c = np.asarray(cells, dtype=np.float64)
    on = np.zeros(len(params), bool)
    for a in (0, 1):
        on |= np.isclose(params[:, a], 0.0) | np.isclose(params[:, a], c[a])
    if not on.any():
        return None
    v = vertices[on]
    if body_kind == "cylinder":
        d = np.abs(np.hypot(v[:, 0], v[:, 1]) - float(np.hypot(nodes[..., 0], nodes[..., 1]).max()))
    elif body is not None:
        from ..bodies.mesh import MeshBody
        ext = float(np.ptp(body[0], axis=0).max())
        d = np.abs(MeshBody(body[0], body[1], band=0.25 * ext)(v))
    else:
        return None
    return {"max": float(d.max()), "mean": float(d.mean()), "vertices": int(on.sum())}


def _refined_scaffold(nodes, cells, element, refine, tpms_type, structure, threshold, resolution, report,
                      box=None):
    """Template refinement (points or a box of cells), then one TPMS cell per hexahedron (unstructured path)."""
    from ..maps.hexcells import hex_cells_scaffold
    from ..maps.hexmesh import check_jacobian, corner_grid, grid_hexes
    from ..volmesh.refine import refine_points
    from ..volmesh.refine_region import refine_region
    if element != "hex8":
        raise InputError("refinement works on 8-node hexahedra; use `element` hex8")
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
            raise InputError(f"refinement box cells {tuple(lo.tolist())}..{tuple(hi.tolist())} must satisfy "
                             f"0 <= lo < hi <= {tuple(int(c) for c in cells)}")
        if refine:
            raise InputError("give either `refine_point` or `refine_box`, not both")
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
    from ..maps.hexmesh import region_pore_sizes
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
    from ..volmesh.hexshapes import hex_volumes
    small = float(np.cbrt(hex_volumes(p2, h2[at_v]).mean()))
    large = float(np.cbrt(hex_volumes(gp, gh[block]).mean()))
    ext = np.ptp(np.asarray(vertices), axis=0)
    spacing = max(small / 12.0, float(np.cbrt(np.prod(ext) / 1.2e7)))  # voxels: at most ~12 M
    sizes = region_pore_sizes(vertices, faces, [box_ref, best], spacing=spacing)
    return {"pore_size_refined": sizes[0], "pore_size_unrefined": sizes[1],
            "pore_size_ratio": sizes[0] / sizes[1], "cell_size_refined": small, "cell_size_unrefined": large,
            "cell_size_ratio": small / large}


@dataclasses.dataclass(frozen=True)
class HexSpec:
    """A checked ``hex`` recipe (see the module docstring for the keys)."""

    body: HexBody
    type: str
    structure: str
    threshold: float | None
    porosity: float | None
    cells: tuple | None
    element: str
    resolution: int
    smooth: int
    cut: str
    refine: tuple
    refine_box: tuple | None
    pore_sizes: bool
    allow_closed_pores: bool = False

    @classmethod
    def from_recipe(cls, r):
        from ..fields.tpms import get_type
        from ..solids import check_structure
        b = r.table("body")
        kind = b.get("kind")
        path = b.get("path") if kind in ("mesh", "hexfile") else None
        keys = {"mesh": ("corners", "untangle_limit"), "frustum": ("bottom", "top", "height"),
                "cylinder": ("height", "radius")}.get(kind, ())
        body = HexBody(kind, path, **{k: b.get(k) for k in keys})
        b.done()
        t = r.table("tpms")
        ttype = t.get("type", check=lambda v: get_type(str(v)).name)
        structure = t.get("structure", check=check_structure)
        if structure == "surface":
            raise t.error("structure", "a hex scaffold needs a solid structure: pore, rod or sheet")
        threshold = t.get("threshold")
        porosity = t.get("porosity")
        t.one_of("threshold")
        allow = t.get("allow_closed_pores")
        t.done()
        element = r.get("element")
        cells = r.get("grid")
        if kind != "hexfile" and cells is None:
            raise r.error("grid", "three cell counts NU NV NW are required (except for a hex-mesh file body)")
        m = r.table("mesh")
        resolution = m.get("resolution")
        smooth = m.get("smooth")
        m.done()
        intersect = r.get("intersect")
        cut = r.get("cut", "field" if intersect else "none")
        if not intersect:
            cut = "none"
        raw = r.get("refine")
        if not isinstance(raw, (list, tuple)) or len(raw) > 10_000:
            raise r.error("refine", "takes a list of at most 10,000 grid vertices [i, j, k]")
        refine = tuple(_ints(x, 3, r.key("refine")) for x in raw)
        refine_box = r.get("refine_box")
        a = r.table("analysis")
        pore_sizes = a.get("pore_sizes")
        a.done()
        if cells is not None:
            require_param_samples(cells, resolution)
            mult = 2 if element == "hex20" else 1
            nodes = float(np.prod([mult * c + 1 for c in cells]))
            from ..param.hexcube import MAX_NODES  # the parameterisation's own bound, checked before loading
            if kind == "mesh" and nodes > MAX_NODES:
                raise ResourceError(f"a {' x '.join(map(str, cells))} {element} parameterisation has {nodes:,.0f} "
                                    f"nodes (at most {MAX_NODES:,}); use fewer cells")
        return cls(body, ttype, structure, threshold, porosity, tuple(cells) if cells else None, element,
                   resolution, smooth, cut, tuple(refine), tuple(refine_box) if refine_box else None, pore_sizes,
                   allow)

    def asked_porosity(self):
        """The porosity the recipe asks for (None: a threshold)."""
        return self.porosity

    def inputs(self) -> list:
        return [self.body.path] if self.body.path else []


def _ints(v, n, key):
    from ..errors import RecipeError
    from ..recipes.table import check_int
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise RecipeError(key, f"takes lists of {n} integers, got {v!r}")
    return tuple(check_int(x, 0, 100_000, key) for x in v)


def run(spec: HexSpec, progress=None, options=None, prepared=None) -> Result:
    """Build the hex scaffold of ``spec`` (nothing written).

    ``prepared`` may carry the ``(nodes, body, facts)`` of :func:`hex_nodes` for this
    spec's body, grid and element (benchmarks reuse one parameterisation for several types).

    The stages: the threshold (:func:`porecad.calibration.constant_threshold`) → the hex grid
    (:func:`hex_nodes`: nodes, body, its facts) → the cut chain: ``field`` (the scaffold cut by the
    body's distance field while it is meshed), falling back to ``boolean`` (the uncut scaffold
    intersected with the body by manifold3d) where folds survive the local repair; each try is
    :func:`_scaffold` (mesh, smooth, cut: vertices, faces, parameters) then :func:`_repair_folds`
    (the self-intersecting pairs left); the runner then checks the solid.
    """
    from ..calibration import constant_threshold

    timer = (options or RunOptions()).stages  # the runner's stage clock: it reports the timings
    threshold, _ = constant_threshold(spec.type, spec.structure, spec.threshold, spec.porosity, spec.allow_closed_pores)
    if spec.body.kind == "hexfile":
        return _run_hex_file(spec, threshold, timer, options)
    require_fits(mapped_estimate([estimated_cells(spec)], spec.resolution, spec.structure),
                 getattr(options, "memory_limit", None), FEWER, "the hex scaffold")
    with timer("hex_mesh"):
        nodes, body, facts = prepared if prepared is not None else hex_nodes(spec.body, spec.cells, spec.element,
                                                                             progress)
    facts = dict(facts)
    facts.pop("time_s", None)
    report = {"type": spec.type, "structure": spec.structure, "threshold": threshold, "element": spec.element,
              "grid": list(spec.cells), "resolution": spec.resolution, "body": facts}
    refined = bool(spec.refine or spec.refine_box)
    cut = "none" if body is None else ("boolean" if spec.cut == "field" and refined else spec.cut)
    hex_volume = mapped_volume(nodes, spec.element, spec.cells)
    domain_volume = hex_volume if cut == "none" else float(facts["body_volume"])
    attempts = ["field", "boolean"] if cut == "field" else [cut]
    known_pairs = None
    for attempt, mode in enumerate(attempts):
        vertices, faces, params, unstructured = _scaffold(spec, mode, nodes, body, threshold, report, timer,
                                                          progress, measure_boundary=attempt == 0 or mode != "field")
        check = len(faces) <= MAX_CHECKED_TRIANGLES
        if not check:
            break
        vertices, faces, known_pairs = _repair_folds(spec, mode, vertices, params, faces, nodes, timer, report)
        if known_pairs == 0 or attempt == len(attempts) - 1:
            break
        report["cut_fallback"] = (f"the field cut left {known_pairs} self-intersecting face pairs after "
                                  "the local repair; cut by the mesh Boolean instead")
    if refined and spec.pore_sizes:
        with timer("pore_sizes"):
            report["refinement"].update(_refined_pore_sizes(vertices, faces, unstructured))
    report["hex_volume"] = hex_volume
    from ..maps.domain_surface import hex_map_surface
    domain = body if cut != "none" else DeferredDomain(hex_map_surface, nodes, spec.element, spec.cells)
    validation = Validation("the hex scaffold", domain_volume, intersections=check,
                       known_pairs=known_pairs if check else None,
                       hint="the map folds the lattice where the grid's cells are nearly flat: another `grid`, "
                            "`element` hex8 or a finer `resolution` may avoid them")
    return Result(report, vertices, faces, domain_volume=domain_volume, domain=domain, body=body,
                  validation=validation)


def _scaffold(spec: HexSpec, mode: str, nodes, body, threshold, report: dict, timer: Timer, progress,
              measure_boundary: bool):
    """One try of the cut chain: the mapped scaffold, smoothed, cut by ``mode``.

    Returns ``(vertices, faces, params, unstructured)``: ``params`` the vertices' parameter-box
    coordinates (None for a refined scaffold), ``unstructured`` the refined scaffold's mesh facts.
    """
    from ..maps.hexmesh import hex_scaffold
    from ..mesh.smooth import laplacian_smooth
    cells = spec.cells
    clip = unstructured = None
    if mode == "field":
        from ..bodies.mesh import MeshBody
        from ..maps.hexmesh import cut_band
        ext = float(np.max(body[0].max(axis=0) - body[0].min(axis=0)))
        # exact a few sample steps from the surface (farther, the cut cannot change the mesh)
        clip = MeshBody(body[0], body[1], band=min(0.05 * ext, cut_band(nodes, spec.element, spec.resolution)))
    with timer("scaffold"):
        if spec.refine or spec.refine_box:
            vertices, faces, unstructured = _refined_scaffold(nodes, cells, spec.element, list(spec.refine), spec.type,
                                                              spec.structure, threshold, spec.resolution, report,
                                                              box=spec.refine_box)
            params = None
        else:
            res = hex_scaffold(nodes, spec.type, spec.structure, threshold, spec.resolution,
                               element=spec.element, progress=stage_progress(progress, "mesh"), clip=clip)
            vertices, faces, params = res["vertices"], res["faces"], res["params"]
            report.update(res["jacobian"])
            report["porosity_parametric"] = 1.0 - res["inside_fraction"]
    if spec.smooth and params is None:
        raise InputError("smoothing is available for unrefined structured meshes")
    if spec.smooth:
        with timer("smooth"):
            c = np.asarray(cells, dtype=np.float64)
            fixed = np.any(np.isclose(params, 0.0) | np.isclose(params, c), axis=1)
            vertices = laplacian_smooth(vertices, faces, iterations=spec.smooth, lam=0.5, fixed=fixed)
        report["smooth_iterations"] = spec.smooth
    if params is not None and measure_boundary:
        dist = _boundary_distance(vertices, params, cells, body, report["body"]["kind"], nodes)
        if dist is not None:
            report["boundary_distance"] = dist
    if mode == "boolean":
        from ..mesh.boolean import intersect
        with timer("intersect"):
            vertices, faces = intersect(vertices, faces, *body)
    if mode != "none":
        report["intersected_with_body"] = True
        report["cut"] = mode
    return vertices, faces, params, unstructured


def _repair_folds(spec: HexSpec, mode: str, vertices, params, faces, nodes, timer: Timer, report: dict):
    """Split the cut's slivers where the map bends, relax the folds left: ``(vertices, faces, pairs left)``."""
    from ..mesh.repair import relax_self_intersections
    pairs = None
    if params is not None and mode != "boolean" and not spec.smooth:
        # flat triangles crossing where the map bends strongly (slivers of the cut): split them in
        # the parameter box, new vertices mapped exactly, before any vertex is moved off the map
        vertices, params, faces, pairs = _refine_crossings(vertices, params, faces, nodes, spec.cells,
                                                           spec.element, timer, report)
    with timer("fold_repair"):
        vertices, fix = relax_self_intersections(vertices, faces, pairs=pairs)
    report.pop("fold_repair", None)
    if fix["pairs_before"]:
        report["fold_repair"] = fix
    return vertices, faces, fix["pairs_after"]  # counted on the final vertices: validation need not search again


def _run_hex_file(spec: HexSpec, threshold, timer, options):
    """A hex-mesh file: one cube-symmetric TPMS cell per hexahedron, welded (unstructured path)."""
    from ..maps.hexcells import hex_cells_scaffold
    from ..maps.hexmesh import scaled_jacobians_unstructured
    from ..volmesh.hexshapes import hex_corner_jacobians, hex_volumes
    from ..volmesh.tetio import read_hex_mesh
    if spec.element != "hex8":
        raise InputError("hex-mesh files are read as 8-node hexahedra; use element hex8")
    with timer("read"):
        points, hexes = read_hex_mesh(spec.body.path)
    require_param_samples([len(hexes)], spec.resolution)  # one cell per hexahedron
    require_fits(mapped_estimate([len(hexes)], spec.resolution, spec.structure), getattr(options, "memory_limit", None),
                 "lower the `resolution` or use a coarser hex mesh", "the hex scaffold")
    with timer("scaffold"):
        res = hex_cells_scaffold(points, hexes, spec.type, spec.structure, threshold, spec.resolution)
    vertices, faces = res["vertices"], res["faces"]
    domain_volume = float(hex_volumes(points, hexes).sum())
    jac = hex_corner_jacobians(points, hexes)
    report = {"type": spec.type, "structure": spec.structure, "threshold": threshold, "element": spec.element,
              "body": {"kind": "hexfile", "path": str(spec.body.path)}, "hexahedra": int(len(hexes)),
              "min_corner_jacobian": float(jac.min()),
              "min_scaled_jacobian": float(scaled_jacobians_unstructured(points, hexes).min()),
              "hex_volume": domain_volume}
    from ..maps.domain_surface import hex_mesh_surface
    return Result(report, vertices, faces, domain_volume=domain_volume,
                  domain=DeferredDomain(hex_mesh_surface, points, hexes),
                  validation=Validation("the hex scaffold", domain_volume,
                                        intersections=len(faces) <= MAX_CHECKED_TRIANGLES))


JOB = Job("hex", HexSpec, run, summary=("type", "structure", "threshold", "element", "min_scaled_jacobian"),
          title="TPMS cells mapped into hexahedral meshes (000 ch.3, 004)")
