"""Hexahedral parameterisation of a closed body: one structured ``nu × nv × nw`` hex grid (000 ch.3).

The body is treated as a deformed cube (000 §3.0, Fig. 3.1):

1. **Corners**: eight mesh vertices, given, or chosen automatically
   (:func:`porecad.param.cube.choose_corners`: the principal-axis box; or,
   where that folds, corners around the two ends of the body,
   :mod:`porecad.param.cube_ends`).
2. **Cube edges** (:mod:`porecad.param.cube_edges`, 000 §3.2–3.3, Table 3.1
   with the erratum edge 10 = 2→6): twelve geodesic edge paths from four
   heat sources, by the heat method (:mod:`porecad.param.heat`).
3. **Faces** (:func:`porecad.param.cube.label_patches`, 000 §3.4, Table 3.2):
   the paths cut the surface into six patches.
4. **Surface grid** (000 §3.5, :mod:`porecad.param.patch_maps`): each patch
   is mapped to the unit square and the patch's structured grid is pulled
   back to the surface.
5. **Volume grid** (000 §3.6): interior nodes by the discrete Laplace
   equation (000 eq. 3.2.3), ``x_ijk = (x_{i±1,j,k} + x_{i,j±1,k} + x_{i,j,k±1}) / 6``,
   with the surface nodes fixed; one sparse solve. *Also* with axis weights
   ``1 / h_a²`` (``h_a`` the surface grid's mean spacing along each axis:
   the box with the body's proportions instead of the unit cube), a second
   candidate whose untangling energy uses the same weights: on a long bone
   at 8×8×8 it folds 4 of 512 cells where the cube's folds 100.
6. **Untangling** (not in 000, :mod:`porecad.param.grid_untangle`): where a
   Jacobian is below 0.05, the grid Laplace energy plus barriers on low
   Jacobians is minimised, interior nodes moving freely and surface nodes
   sliding inside their face or along their cube edge. For 20-node
   elements (``element="hex20"``, a grid of twice the cells) the barriers
   act on the serendipity map of every 2×2×2 block, so the 20-node
   hexahedra built from the grid are valid, not only its 8-node cells.

Node ``nodes[i, j, k]`` sits at ``(u, v, w) = (i/nu, j/nv, k/nw)`` (cube
labelling in :mod:`porecad.param.cube`).

Deviations from the dissertation, and why:

* **Surface nodes** (000 §3.5 places them by "evenly offset interception" of
  level curves of three harmonic fields). Here every patch gets its own
  harmonic map to the unit square (cotangent weights clipped to be
  positive, falling back to mean-value weights, Floater 2003, when a
  triangle flips), with its four boundary paths laid on the square's sides
  by arc length. A convex-boundary map with positive weights is bijective
  (Tutte, Floater), so every node lands on its patch exactly once; each
  cube edge is sampled by arc length once and reused by both of its
  patches, so the six face grids close up into the exact boundary of the
  node array. Level-curve interception needs closed iso-lines that cross
  each side edge once, which fails on bodies with bulges.
* **Guided side edges.** On a long, bowed body (the femur) the four geodesic
  side edges e8–e11 all hug the concave side of the shaft and touch. When
  the geodesic edges fail the checks, the side edges are instead shortest
  paths in disjoint corridors around straight lines of the conformal
  coordinates ``(w, θ)`` of the annulus between the two end loops.
* **Automatic corners at the ends** of long bodies
  (:mod:`porecad.param.cube_ends`), where the principal-axis box folds a face.
* **Untangling** (step 6) and midpoint subdivision of meshes that are coarse
  compared with the grid (the geometry is unchanged).

Sources: 000 = seed-000 dissertation notes §3; Crane, Weischedel, Wardetzky,
"Geodesics in heat", ACM TOG 32(5), 2013; Floater, "Mean value coordinates",
CAGD 20, 2003; Knupp, "Achieving finite element mesh quality via
optimization of the Jacobian matrix norm and associated quantities", IJNME
48, 2000 (corner scaled Jacobians).
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from ..mesh.operators import face_areas
from .cube import check_corners, check_grid, check_paths, choose_corners, closed_mesh, label_patches, pca_frame
from .cube_edges import edges_for_corners, guide_sides, mesh_edges
from .cube_ends import Cylinder, end_corners, end_regions, guided_caps
from .grid_untangle import SJ_TARGET, UNTANGLE_LIMIT, element_quality, untangle_estimate, untangle_grid
from .half_grid import refine_grid, straighten_folded
from .heat import HeatGeodesics
from .patch_maps import axis_spacing, laplace_volume, surface_grid
from .sphere_map import conformal_sphere, sphere_corners

__all__ = ["MAX_NODES", "SJ_POOR", "UNTANGLE_LIMIT", "hex_parameterisation"]

#: scaled Jacobian below which a cell counts as poor in ``info``
SJ_POOR = 0.2
#: the largest node grid parameterised (bounds memory and time before work starts)
MAX_NODES = 200_000


def _refine(v, f, grid, max_faces=200_000):
    """Midpoint-subdivide while the mean edge is longer than ⅖ of the mean boundary-cell side.

    The boundary cell side is ``√(area / n_quads)`` with
    ``n_quads = 2 (n_u n_v + n_v n_w + n_w n_u)``; subdivision keeps the
    geometry (and the original vertices first) and gives the cube edges and
    corridors room on coarse meshes.
    """
    nu_, nv_, nw_ = grid
    side = np.sqrt(face_areas(v, f).sum() / (2.0 * (nu_ * nv_ + nv_ * nw_ + nw_ * nu_)))
    k = 0
    while len(f) * 4 <= max_faces:
        _, ln = mesh_edges(v, f)
        if ln.mean() <= 0.4 * side:
            break
        v, f = _subdivide(v, f)
        k += 1
    return v, f, k


def _laplace_grids(surface):
    """The interior by the discrete Laplace equation: with equal axis weights, and with the body's proportions.

    Returns ``[(label, spacing, nodes), ...]``: equal weights (000 eq. 3.2.3)
    and weights ``1 / h_a²`` (:func:`porecad.param.patch_maps.axis_spacing`);
    the second only when the spacings differ by more than 10 %. On long
    bodies the proportional weights fold far fewer cells (a long bone at
    8×8×8: 4 of 512 instead of 100, and the untangling then succeeds); on
    compact bodies with protrusions the equal ones can untangle better (the
    bunny), so both are candidates.
    """
    h = axis_spacing(surface)
    kinds = [("", np.full(3, np.sqrt(np.mean(h ** 2))))] + ([(", proportional", h)] if h.max() >= 1.1 * h.min() else [])
    return [(label, spacing, laplace_volume(surface, 1.0 / spacing ** 2)) for label, spacing in kinds]


def _subdivide(v, f):
    """Midpoint subdivision (the input's vertices first, so their indices stay valid)."""
    import trimesh.remesh

    v, f = trimesh.remesh.subdivide(v, f)
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


def hex_parameterisation(vertices, faces, grid=(5, 7, 20), corners=None, weights: str = "cotangent",
                         untangle: bool = True, subdivide: bool = True, untangle_limit: float | None = UNTANGLE_LIMIT,
                         progress=None, element: str = "hex8", keep_locators: bool = False, balance: int = 0):
    """Structured hexahedral grid of a closed body (000 ch.3, §3.0–3.6).

    Stages: corners → 12 cube edges → six face patches → surface grid
    (per-patch harmonic map to the unit square; *deviates* from the "evenly
    offset interception" of 000 §3.5, see the module docstring) → interior
    nodes by the discrete Laplace equation ``x_ijk = Σ_{6 neighbours} x / 6``
    (000 eq. 3.2.3) in one sparse solve → untangling where a corner scaled
    Jacobian is below 0.05.

    Automatic corners (``corners=None``) build the Laplace grids of the
    principal-axis box (:func:`choose_corners`, Table 3.1 geodesics, guided
    side edges where the geodesic ones fail), of the cube inscribed in the
    body's conformal sphere (:mod:`porecad.param.sphere_map`) and of corners
    just outside the two ends of the body at three distances (module
    docstring) — stopping at the first that needs no untangling —, then
    untangle them, fewest folded elements first, until one is valid; the
    first grid whose every element is valid is returned, else the best one
    found.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
        Closed, edge-manifold, genus-0 triangle mesh.
    grid : (nu, nv, nw)
        Elements along u, v, w (000: the femur at 5×7×20 and 5×10×60).
    corners : (8,) int, optional
        Cube corner vertices (000 Fig. 3.2 order, right-handed, indices of
        ``vertices``); default automatic.
    weights : {"cotangent", "mean-value"}
        Patch map weights: clipped cotangent (falls back to mean-value for a
        patch where a triangle flips) or mean-value.
    untangle : bool
        Run the untangling step (:func:`untangle_grid`) when a corner scaled
        Jacobian is below 0.05.
    subdivide : bool
        Midpoint-subdivide meshes that are coarse compared with the grid
        (:func:`_refine`); vertex indices of the input stay valid.
    untangle_limit : float or None
        Seconds for all untangling (every corner choice tried shares them;
        default :data:`UNTANGLE_LIMIT`; ``None``: no limit). A choice whose
        untangling the limit stops is kept only if its grid is valid, and its
        rejection says so.
    element : {"hex8", "hex20"}
        What the grid is for. ``hex8``: the node grid has ``grid`` cells and
        every cell is valid (corners and inside). ``hex20``: the node grid
        has half-cell steps, ``2 grid`` cells (the layout
        :func:`porecad.maps.hexmesh.map_hex20` reads), and every 20-node
        serendipity element of a 2×2×2 block is valid (and so is its
        straight 8-node corner cell), which the cells of the finer grid
        alone do not guarantee.
    keep_locators : bool
        Also return ``info["locators"]``: the six face patches' maps
        (:class:`porecad.param.patch_maps.PatchLocator`, not JSON).
    balance : int
        Rounds of stretch balancing of the patch maps
        (:func:`porecad.param.patch_maps.harmonic_map`; 0: the harmonic maps),
        which give a protrusion that the harmonic map squeezes toward a
        corner (an ear) its share of the face grid.
    progress : callable, optional
        ``progress(stage, done, total)`` per stage (``setup``, ``corners``,
        ``geodesics``, ``surface grid``, ``volume``, ``untangle``); before the
        untangling, the stage name carries the estimated time
        (``untangle ~N s``, also in ``info["estimates"]``).

    Returns
    -------
    nodes : (nu+1, nv+1, nw+1, 3) float64, or (2nu+1, 2nv+1, 2nw+1, 3) for hex20
        ``nodes[i, j, k]`` at ``(u, v, w) = (i/nu, j/nv, k/nw)`` (half steps
        for hex20); the six boundary slices lie on the surface.
    info : dict
        ``corners``; ``corner_choice`` ("given", "box", "sphere" or "ends (offset …)",
        followed by ", proportional" when the Laplace grid with the body's
        proportions was kept); ``grid``; ``vertices``, ``faces`` (the mesh the paths and labels
        refer to: the input, or its subdivision; subdivided once more when no
        corner choice found its paths), ``subdivisions``; ``paths``
        (12 vertex paths); ``patch_labels`` (per face of ``faces``);
        ``patch_maps`` (weights used per face); ``path_fallbacks`` (Dijkstra
        paths in the heat runs); ``times`` (s: ``setup`` (mesh checks and
        subdivision), ``corners`` (corner choices tried and not kept),
        ``geodesics`` (corners and cube edges of the kept choice, heat
        factorisation included), ``patches``, ``surface_grid``, ``volume``,
        ``untangle``, ``total``);
        ``element``; ``min_scaled_jacobian`` (corner scaled Jacobian of the
        elements' corner cells), ``min_scaled_jacobian_inside`` (smallest
        det / mean |det| of the element maps,
        :func:`porecad.maps.hexmesh.sampled_jacobians`), ``fraction_below_0.2``
        (elements with corner scaled Jacobian < 0.2),
        ``min_scaled_jacobian_laplace`` (before untangling),
        ``untangle_iterations``; ``straightened`` (hex20: when curved
        elements still folded after the untangling, the
        :func:`porecad.param.half_grid.straighten_folded` facts, else None);
        ``boundary_lift`` (``max_lift``: how far
        the untangling lifted boundary nodes off the surface, outwards, in
        mean grid edges; ``lifted_nodes``); ``nodes``, ``boundary_nodes``,
        ``interior_nodes``, ``hexes`` (elements); ``rejected`` (corner
        choices that failed, with their reason); ``laplace_grids`` (every
        choice's grid before untangling: folded elements and the smallest
        quality, by which they are tried); ``conformal_sphere`` (when that
        choice was built: :func:`porecad.param.sphere_map.conformal_sphere`).

    Raises
    ------
    InputError
        Bad mesh, grid or corners; given corners whose cube edges touch,
        cross or fold a face; no automatic corner choice that works.
    """
    if weights not in ("cotangent", "mean-value"):
        raise InputError(f"weights must be 'cotangent' or 'mean-value'; got {weights!r}")
    if element not in ("hex8", "hex20"):
        raise InputError(f"element must be 'hex8' or 'hex20'; got {element!r}")
    cells = check_grid(grid)
    N = tuple(2 * c for c in cells) if element == "hex20" else cells  # the node grid's cells
    if int(np.prod(np.array(N) + 1)) > MAX_NODES:
        raise InputError(f"a {cells[0]}x{cells[1]}x{cells[2]} {element} grid has more than {MAX_NODES:,} nodes; "
                         "use a coarser grid")
    if untangle_limit is not None and not (isinstance(untangle_limit, (int, float)) and np.isfinite(untangle_limit)
                                           and untangle_limit > 0):
        raise InputError(f"the untangle time limit must be a positive number of seconds, got {untangle_limit!r}")

    def report(stage, done=1, total=1):
        if progress is not None:
            progress(stage, done, total)

    t_start = time.perf_counter()
    deadline = None if untangle_limit is None else float(untangle_limit)  # seconds left for untangling
    estimates = {}
    report("setup", 0, 1)
    v, f = closed_mesh(vertices, faces)
    given = None if corners is None else check_corners(corners, len(v))
    nsub = 0
    if subdivide:
        # for the element grid (also for hex20: the half-step nodes are placed on the same surface, and the
        # 8-node stage then matches the hex8 job's; subdividing for the half-step grid made the bunny's
        # 8-node untangling fail where the hex8 job's succeeds)
        v, f, nsub = _refine(v, f, cells)
    frame = pca_frame(v, f)
    lazy = {}
    t_setup = time.perf_counter() - t_start
    report("setup", 1, 1)

    def box_edges(c):
        if "heat" not in lazy:
            lazy["heat"] = HeatGeodesics(v, f)
        paths, labels, fb = edges_for_corners(v, f, c, "auto", lazy["heat"])
        return c, paths, labels, fb

    def sphere_edges():
        if "sphere" not in lazy:
            xs, lazy["sphere_info"] = conformal_sphere(v, f)
            lazy["sphere"] = (xs, HeatGeodesics(xs, f))
        xs, heat = lazy["sphere"]
        c = sphere_corners(xs, f, frame)
        paths, labels, fb = edges_for_corners(xs, f, c, "auto", heat)
        return c, paths, labels, fb

    def end_edges(offset):
        if "cyl" not in lazy:
            side = np.sqrt(face_areas(v, f).sum() / (2.0 * (N[0] * N[1] + N[1] * N[2] + N[2] * N[0])))
            lazy["cyl"] = Cylinder(v, f, *end_regions(v, f, frame, length=0.4 * side))
        c = end_corners(v, f, N, lazy["cyl"], frame, offset)
        paths = guided_caps(v, f, c, lazy["cyl"]) + [None] * 4
        paths = guide_sides(v, f, c, paths)
        check_paths(paths, c, len(v))
        return c, paths, label_patches(v, f, paths), 0

    if given is not None:
        tries = [("given", lambda: box_edges(given))]
    else:
        tries = [("box", lambda: box_edges(choose_corners(v, f))), ("sphere", sphere_edges)]
        tries += [(f"ends (offset {o:g})", lambda o=o: end_edges(o)) for o in (0.01, 0.005, 0.02)]
    rejected, cands = [], []
    t_tried = 0.0  # time of the corner choices that were tried and not kept
    # 1. every corner choice's Laplace grid (a few seconds each); stop early at one that needs no untangling.
    # Where no choice gives paths (corridors narrower than the triangles), subdivide once more and try again.
    for _ in range(2):
        for n_try, (name, make) in enumerate(tries):
            report("corners", n_try, len(tries))
            t0 = time.perf_counter()
            try:
                c, paths, labels, fb = make()
                t1 = time.perf_counter()
                report("geodesics", 1, 1)
                nodes, kinds, locators, taus = surface_grid(v, f, labels, paths, cells, weights, balance)
            except InputError as err:
                if given is not None:
                    raise
                rejected.append((name, str(err)))
                t_tried += time.perf_counter() - t0
                continue
            t2 = time.perf_counter()
            report("surface grid", 1, 1)
            grids, stop = _laplace_grids(nodes), False
            t_vol = (time.perf_counter() - t2) / len(grids)
            for label, spacing, nodes in grids:
                t3 = time.perf_counter()
                sj0, si0 = element_quality(nodes, "hex8")
                q0 = np.minimum(sj0, si0)
                cands.append(dict(name=name + label, spacing=spacing, corners=c, paths=paths, labels=labels,
                                  fallbacks=fb, kinds=kinds, nodes=nodes, locators=locators, taus=taus,
                                  sj0=float(sj0.min()), q0=float(q0.min()), bad0=int(np.sum(q0 <= 0)),
                                  times={"geodesics": t1 - t0, "surface_grid": t2 - t1,
                                         "volume": t_vol + time.perf_counter() - t3, "untangle": 0.0}))
                report("volume", 1, 1)
                stop = stop or cands[-1]["q0"] >= SJ_TARGET or not untangle
            if stop:
                break
        if cands or given is not None or not subdivide or 4 * len(f) > 200_000:
            break
        rejected = [(n_ + " (before subdividing once more)", m_) for n_, m_ in rejected]
        v, f = _subdivide(v, f)
        nsub += 1
        lazy.clear()
        frame = pca_frame(v, f)
    # 2. untangle them, fewest folded elements first, until one is valid or the time is spent
    cands.sort(key=lambda c_: (c_["q0"] < SJ_TARGET, c_["bad0"], -c_["q0"]))
    best = None

    def run(cand, nodes, name, elem, start=None):
        nonlocal deadline
        t_ = time.perf_counter()
        est = untangle_estimate(nodes, cand["locators"], v, elem)
        left = None if deadline is None else max(deadline, 0.0)
        estimates[name] = est if left is None else min(est, left)
        stage = f"untangle ~{estimates[name]:.0f} s"
        out = untangle_grid(nodes, cand["locators"], cand["paths"], cand["taus"], v, elem, start=start,
                            spacing=cand["spacing"] * (0.5 if elem == "hex20" else 1.0),  # half steps
                            deadline=None if left is None else time.perf_counter() + left,
                            progress=(lambda d, t, s_=stage: report(s_, d, t)))
        if deadline is not None:
            deadline -= time.perf_counter() - t_
        return out

    def element_grid(cand):
        """The candidate's 8-node grid, untangled where needed (once): (nodes, iterations, stopped, lift, coords)."""
        if "grid8" not in cand:
            t_ = time.perf_counter()
            out = (cand["nodes"], 0, False, {"max_lift": 0.0, "lifted_nodes": 0}, None)
            if untangle and cand["q0"] < SJ_TARGET and (deadline is None or deadline > 0):
                nodes, nit, stopped, lift = run(cand, cand["nodes"], cand["name"], "hex8")
                out = (nodes, nit, stopped, lift, lift.pop("coords"))
            cand["grid8"] = out
            cand["times"]["untangle"] += time.perf_counter() - t_
        return cand["grid8"]

    if element == "hex20" and untangle:
        # the 20-node untangling is the long stage: start it from a valid 8-node grid (those untangle in seconds)
        for cand in cands:
            cand["q8"] = float(np.min(np.minimum(*element_quality(element_grid(cand)[0], "hex8"))))
            if cand["q8"] > 0:
                break
        cands.sort(key=lambda c_: -c_.get("q8", -np.inf))
    for cand in cands:
        nodes, nit, stopped, lift, coords = element_grid(cand)
        t3 = time.perf_counter()
        if element == "hex20":  # the half-step grid from the element grid, then its 20-node elements untangled
            coarse = nodes
            nodes, start = refine_grid(nodes, coords, cand["locators"], cand["paths"], cand["taus"], v)
            sj, si = element_quality(nodes, element)
            if untangle and min(float(sj.min()), float(si.min())) < SJ_TARGET and not stopped and \
                    (deadline is None or deadline > 0):
                nodes, it2, stopped, lift = run(cand, nodes, cand["name"] + " (hex20)", "hex20", start)
                lift.pop("coords")
                nit += it2
                sj, si = element_quality(nodes, element)
            if min(float(sj.min()), float(si.min())) <= 0:
                # curved elements still fold (or the untangling stopped): straighten them toward their corner
                # cells; where those fold too, from the untangled 8-node grid's corners
                fixed, fact = straighten_folded(nodes)
                if fact.get("corner_cells_fold"):
                    fixed = nodes.copy()
                    fixed[::2, ::2, ::2] = coarse
                    fixed, fact = straighten_folded(fixed)
                    fact["from"] = "the untangled 8-node grid"
                cand["straightened"] = fact
                if fact["quality"] is not None and fact["quality"] > 0:
                    nodes = fixed
                    sj, si = element_quality(nodes, element)
        else:
            sj, si = element_quality(nodes, element)
        si = float(si.min())  # inside the elements
        cand.update(nodes=nodes, sj=sj, si=si, q=min(float(sj.min()), si), nit=nit, stopped=stopped, lift=lift)
        cand["times"]["untangle"] += time.perf_counter() - t3
        if best is None or cand["q"] > best["q"]:
            best = cand
        if best["q"] > 0:
            break
        why = f"min scaled Jacobian {float(sj.min()):.3g} (corners), {si:.3g} (inside)"
        if stopped:
            why += f" when the untangling stopped at its time limit ({untangle_limit:g} s in all)"
        rejected.append((cand["name"], why))
    for cand in cands:
        if cand is not best:
            t_tried += sum(cand["times"].values())
    report("corners", len(tries), len(tries))
    if best is None:
        raise InputError("no automatic corner choice gives a valid cube: "
                         + "; ".join(f"{n}: {m}" for n, m in rejected) + "; pass corners explicitly")
    tp = time.perf_counter()
    label_patches(v, f, best["paths"])  # timed once for the report (the check ran inside the corner stage)
    t_patches = time.perf_counter() - tp
    nodes, sj = best["nodes"], best["sj"]
    N_arr = np.array(N)
    n_all = int(np.prod(N_arr + 1))
    n_in = int(np.prod(np.maximum(N_arr - 1, 0)))
    times = {"setup": t_setup, "corners": t_tried, **best["times"], "patches": t_patches}
    times["geodesics"] = max(times["geodesics"] - t_patches, 0.0)
    times["total"] = time.perf_counter() - t_start
    info = {
        "corners": best["corners"],
        "corner_choice": best["name"],
        "grid": cells,
        "element": element,
        "vertices": v,
        "faces": f,
        "subdivisions": nsub,
        "paths": best["paths"],
        "patch_labels": best["labels"],
        "patch_maps": best["kinds"], "patch_balance": int(balance),
        "path_fallbacks": int(best["fallbacks"]),
        "times": times,
        "min_scaled_jacobian": float(sj.min()),
        "min_scaled_jacobian_inside": best["si"],
        f"fraction_below_{SJ_POOR:g}": float(np.mean(sj < SJ_POOR)),
        "min_scaled_jacobian_laplace": best["sj0"],
        "untangle_iterations": best["nit"],
        "untangle_stopped": bool(best.get("stopped", False)),
        "straightened": best.get("straightened"),
        "boundary_lift": best["lift"],
        "estimates": estimates,
        "nodes": n_all,
        "boundary_nodes": n_all - n_in,
        "interior_nodes": n_in,
        "hexes": int(sj.size),
        "rejected": [r for r in rejected if r[0] != best["name"]],
        "laplace_grids": [{"choice": c_["name"], "folded_elements": c_["bad0"], "min_quality": c_["q0"]}
                          for c_ in cands],
    }
    if "sphere_info" in lazy:
        info["conformal_sphere"] = lazy["sphere_info"]
    if keep_locators:  # not JSON: for fits that need every surface vertex's cube parameters
        info["locators"] = best["locators"]
    return nodes, info
