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

Automatic corner choices (``corners=None`` in :func:`hex_parameterisation`):
the Laplace grids of the principal-axis box (:func:`choose_corners`, Table
3.1 geodesics, guided side edges where the geodesic ones fail), of the cube
inscribed in the body's conformal sphere (:mod:`porecad.param.sphere_map`)
and of corners just outside the two ends of the body at three distances
(:mod:`porecad.param.cube_ends`) are built — stopping at the first that needs no untangling —, then
untangled, fewest folded elements first, until one is valid; the first grid
whose every element is valid is returned, else the best one found.

The facts of the run (second value returned by :func:`hex_parameterisation`):
a :class:`porecad.param.hexgrid_info.HexGridInfo` — the corner choice, the
grid's quality before and after untangling, times and rejected choices, and
the mesh, corners, cube-edge paths and patch labels the grid was built on
(each field described there); :meth:`~porecad.param.hexgrid_info.HexGridInfo.report`
gives them as the hex job reports them.

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
from .hexgrid_info import SJ_POOR, HexGridInfo
from .patch_maps import axis_spacing, laplace_volume, surface_grid
from .sphere_map import conformal_sphere, sphere_corners
from .work_budget import WorkBudget

__all__ = ["MAX_NODES", "SJ_POOR", "UNTANGLE_LIMIT", "hex_parameterisation"]

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
                         progress=None, element: str = "hex8", keep_locators: bool = False, balance: int = 0,
                         prefer: str | None = None):
    """Structured hexahedral grid of a closed body (000 ch.3, §3.0–3.6).

    Stages: corners → 12 cube edges → six face patches → surface grid
    (per-patch harmonic map to the unit square; *deviates* from the "evenly
    offset interception" of 000 §3.5, see the module docstring) → interior
    nodes by the discrete Laplace equation ``x_ijk = Σ_{6 neighbours} x / 6``
    (000 eq. 3.2.3) in one sparse solve → untangling where a corner scaled
    Jacobian is below 0.05.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
        Closed, edge-manifold, genus-0 triangle mesh.
    grid : (nu, nv, nw)
        Elements along u, v, w (000: the femur at 5×7×20 and 5×10×60).
    corners : (8,) int, optional
        Cube corner vertices (000 Fig. 3.2 order, right-handed, indices of
        ``vertices``); default automatic (module docstring, *Automatic
        corner choices*).
    weights : {"cotangent", "mean-value"}
        Patch map weights: clipped cotangent (mean-value for a patch where a
        triangle flips) or mean-value.
    untangle : bool
        Run the untangling step (:func:`untangle_grid`) when a corner scaled Jacobian is below 0.05.
    subdivide : bool
        Midpoint-subdivide meshes coarse for the grid (:func:`_refine`; input vertex indices stay valid).
    untangle_limit : float or None
        Seconds for all untangling (shared by the corner choices; default :data:`UNTANGLE_LIMIT`;
        ``None``: none), modelled from the work (:class:`~porecad.param.work_budget.WorkBudget`: the grid
        does not depend on the machine's load). A choice it stops is kept only if valid (its rejection says so).
    element : {"hex8", "hex20"}
        What the grid is for. ``hex8``: the node grid has ``grid`` cells and
        every cell is valid (corners and inside). ``hex20``: the node grid
        has half-cell steps, ``2 grid`` cells (the layout
        :func:`porecad.maps.hexmesh.map_hex20` reads), and every 20-node
        serendipity element of a 2×2×2 block is valid (and so is its
        straight 8-node corner cell), which the cells of the finer grid
        alone do not guarantee.
    keep_locators : bool
        Also return ``info.locators``: the six patches' maps (:class:`porecad.param.patch_maps.PatchLocator`).
    balance : int
        Rounds of stretch balancing of the patch maps
        (:func:`porecad.param.patch_maps.harmonic_map`; 0: the harmonic maps),
        which give a protrusion that the harmonic map squeezes toward a
        corner (an ear) its share of the face grid.
    prefer : str, optional
        A corner choice to try first (``info.corner_choice`` of a run on the same body at another grid).
    progress : callable, optional
        ``progress(stage, done, total)`` per stage (``setup``, ``corners``,
        ``geodesics``, ``surface grid``, ``volume``, ``untangle``); before the
        untangling, the stage name carries the estimated time
        (``untangle ~N s``, also in ``info.estimates``).

    Returns
    -------
    nodes : (nu+1, nv+1, nw+1, 3) float64, or (2nu+1, 2nv+1, 2nw+1, 3) for hex20
        ``nodes[i, j, k]`` at ``(u, v, w) = (i/nu, j/nv, k/nw)`` (half steps
        for hex20); the six boundary slices lie on the surface.
    info : HexGridInfo
        The facts of the run (:class:`porecad.param.hexgrid_info.HexGridInfo`).

    Raises
    ------
    InputError
        Bad mesh, grid or corners; given corners whose cube edges touch,
        cross or fold a face; no automatic corner choice that works.
    """
    cells, N = _check_arguments(grid, element, weights, untangle_limit)
    t_start = time.perf_counter()
    run = _Search(vertices, faces, cells, N, corners, weights, balance, untangle, untangle_limit, subdivide,
                  element, progress, prefer)
    cands = run.laplace_candidates()       # stage 1: corner choices -> cube edges -> surface grid -> Laplace volume
    best = run.untangle_until_valid(cands)  # stage 2: untangle them, fewest folds first, until one is valid
    return best["nodes"], run.info(best, cands, keep_locators, t_start)


def _check_arguments(grid, element, weights, untangle_limit):
    """The element grid's cells and the node grid's cells (hex20: half steps); every bound before any work."""
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
    return cells, N


class _Search:
    """The search of :func:`hex_parameterisation`: its mesh, corner choices, time left and what was rejected.

    ``laplace_candidates`` (stage 1) takes nothing and returns candidate dicts
    (corners, paths, patch labels, surface grid maps, Laplace ``nodes``, their
    quality ``q0`` and folded count ``bad0``, ``times``);
    ``untangle_until_valid`` (stage 2) takes them and returns the best one,
    its ``nodes`` untangled (and, for hex20, refined to half steps);
    ``info`` gathers the returned facts (a :class:`HexGridInfo`).
    """

    def __init__(self, vertices, faces, cells, N, corners, weights, balance, untangle, untangle_limit, subdivide,
                 element, progress, prefer=None):
        self.cells, self.N, self.weights, self.balance = cells, N, weights, balance
        self.untangle, self.untangle_limit, self.subdivide, self.element = untangle, untangle_limit, subdivide, element
        self.progress = progress
        self.prefer = None if prefer is None else str(prefer).split(", ")[0]  # a choice's name, without its spacing
        t0 = time.perf_counter()
        # the untangling's seconds, counted by a model of its work (the same grid on any machine, at any load)
        self.budget = None if untangle_limit is None else WorkBudget(untangle_limit)
        self.estimates, self.rejected, self.lazy, self.t_tried = {}, [], {}, 0.0
        self.report("setup", 0, 1)
        v, f = closed_mesh(vertices, faces)
        self.given = None if corners is None else check_corners(corners, len(v))
        self.nsub = 0
        if subdivide:
            # for the element grid (also for hex20: the half-step nodes are placed on the same surface, and the
            # 8-node stage then matches the hex8 job's; subdividing for the half-step grid made the bunny's
            # 8-node untangling fail where the hex8 job's succeeds)
            v, f, self.nsub = _refine(v, f, cells)
        self.v, self.f, self.frame = v, f, pca_frame(v, f)
        self.t_setup = time.perf_counter() - t0
        self.report("setup", 1, 1)

    def report(self, stage, done=1, total=1):
        if self.progress is not None:
            self.progress(stage, done, total)

    # -- corner choices: each returns (corners, 12 paths, patch labels, heat-path fallbacks) ----------------------
    def box_edges(self, c):
        if "heat" not in self.lazy:
            self.lazy["heat"] = HeatGeodesics(self.v, self.f)
        paths, labels, fb = edges_for_corners(self.v, self.f, c, "auto", self.lazy["heat"])
        return c, paths, labels, fb

    def sphere_edges(self):
        v, f, lazy = self.v, self.f, self.lazy
        if "sphere" not in lazy:
            xs, lazy["sphere_info"] = conformal_sphere(v, f)
            lazy["sphere"] = (xs, HeatGeodesics(xs, f))
        xs, heat = lazy["sphere"]
        c = sphere_corners(xs, f, self.frame)
        paths, labels, fb = edges_for_corners(xs, f, c, "auto", heat)
        return c, paths, labels, fb

    def end_edges(self, offset):
        v, f, N, lazy = self.v, self.f, self.N, self.lazy
        if "cyl" not in lazy:
            side = np.sqrt(face_areas(v, f).sum() / (2.0 * (N[0] * N[1] + N[1] * N[2] + N[2] * N[0])))
            lazy["cyl"] = Cylinder(v, f, *end_regions(v, f, self.frame, length=0.4 * side))
        c = end_corners(v, f, N, lazy["cyl"], self.frame, offset)
        paths = guided_caps(v, f, c, lazy["cyl"]) + [None] * 4
        paths = guide_sides(v, f, c, paths)
        check_paths(paths, c, len(v))
        return c, paths, label_patches(v, f, paths), 0

    def tries(self):
        if self.given is not None:
            return [("given", lambda: self.box_edges(self.given))]
        out = [("box", lambda: self.box_edges(choose_corners(self.v, self.f))), ("sphere", self.sphere_edges)]
        out += [(f"ends (offset {o:g})", lambda o=o: self.end_edges(o)) for o in (0.01, 0.005, 0.02)]
        return sorted(out, key=lambda t: t[0] != self.prefer)  # the preferred choice first, the others in order

    # -- stage 1 ------------------------------------------------------------------------------------------------
    def laplace_candidates(self) -> list[dict]:
        """Every corner choice's Laplace grids (a few seconds each), stopping at one that needs no untangling.

        Where no choice gives paths (corridors narrower than the triangles),
        the mesh is subdivided once more and the choices tried again.
        """
        cands = []
        for _ in range(2):
            tries = self.tries()
            for n_try, (name, make) in enumerate(tries):
                self.report("corners", n_try, len(tries))
                found = self.candidates_of(name, make)
                cands += found
                if any(c["q0"] >= SJ_TARGET for c in found) or (found and not self.untangle):
                    break
            self.n_tries = len(tries)
            if cands or self.given is not None or not self.subdivide or 4 * len(self.f) > 200_000:
                return cands
            self.rejected = [(n_ + " (before subdividing once more)", m_) for n_, m_ in self.rejected]
            self.v, self.f = _subdivide(self.v, self.f)
            self.nsub += 1
            self.lazy.clear()
            self.frame = pca_frame(self.v, self.f)
        return cands

    def candidates_of(self, name, make) -> list[dict]:
        """The Laplace grids of one corner choice (none when its edges or surface grid fail: rejected)."""
        t0 = time.perf_counter()
        try:
            c, paths, labels, fb = make()
            t1 = time.perf_counter()
            self.report("geodesics", 1, 1)
            nodes, kinds, locators, taus = surface_grid(self.v, self.f, labels, paths, self.cells, self.weights,
                                                        self.balance)
        except InputError as err:
            if self.given is not None:
                raise
            self.rejected.append((name, str(err)))
            self.t_tried += time.perf_counter() - t0
            return []
        t2 = time.perf_counter()
        self.report("surface grid", 1, 1)
        grids, out = _laplace_grids(nodes), []
        t_vol = (time.perf_counter() - t2) / len(grids)
        for label, spacing, nodes in grids:
            t3 = time.perf_counter()
            sj0, si0 = element_quality(nodes, "hex8")
            q0 = np.minimum(sj0, si0)
            out.append(dict(name=name + label, spacing=spacing, corners=c, paths=paths, labels=labels,
                            fallbacks=fb, kinds=kinds, nodes=nodes, locators=locators, taus=taus,
                            sj0=float(sj0.min()), q0=float(q0.min()), bad0=int(np.sum(q0 <= 0)),
                            times={"geodesics": t1 - t0, "surface_grid": t2 - t1,
                                   "volume": t_vol + time.perf_counter() - t3, "untangle": 0.0}))
            self.report("volume", 1, 1)
        return out

    # -- stage 2 ------------------------------------------------------------------------------------------------
    def untangle_until_valid(self, cands: list[dict]) -> dict:
        """Untangle the candidates, fewest folded elements first, until one is valid or the time is spent."""
        cands.sort(key=lambda c_: (c_["q0"] < SJ_TARGET, c_["bad0"], -c_["q0"]))
        if self.element == "hex20" and self.untangle:
            # the 20-node untangling is the long stage: start it from a valid 8-node grid (those untangle in seconds)
            for cand in cands:
                cand["q8"] = float(np.min(np.minimum(*element_quality(self.element_grid(cand)[0], "hex8"))))
                if cand["q8"] > 0:
                    break
            cands.sort(key=lambda c_: -c_.get("q8", -np.inf))
        best = None
        for cand in cands:
            self.finish(cand)
            if best is None or cand["q"] > best["q"]:
                best = cand
            if best["q"] > 0:
                break
            why = f"min scaled Jacobian {float(cand['sj'].min()):.3g} (corners), {cand['si']:.3g} (inside)"
            if cand["stopped"]:
                why += f" when the untangling stopped at its time limit ({self.untangle_limit:g} s in all)"
            self.rejected.append((cand["name"], why))
        for cand in cands:
            if cand is not best:
                self.t_tried += sum(cand["times"].values())
        self.report("corners", self.n_tries, self.n_tries)
        if best is None:
            raise InputError("no automatic corner choice gives a valid cube: "
                             + "; ".join(f"{n}: {m}" for n, m in self.rejected) + "; pass corners explicitly")
        if self.untangle and best["q"] <= 0:  # one line with the cause, not a folded grid for the job to find
            folded = int(np.sum(best["sj"] <= 0))
            why = (f"the untangling stopped at its time limit ({self.untangle_limit:g} s): more `untangle_limit` "
                   "may unfold it, " if any(c.get("stopped") for c in cands) else "")
            raise InputError(f"the body's cube map folds: {folded} of {best['sj'].size} cells of the best corner "
                             f"choice ({best['name']}) stay inverted after untangling (min scaled Jacobian "
                             f"{best['q']:.3g}); {why}or give `corners`, another `grid`, or fill the body by "
                             "infill, TIS or ARBF")
        return best

    def untangled(self, cand, nodes, name, elem, start=None):
        """:func:`untangle_grid` of ``nodes`` within the budget left (the estimate shown in the stage's name)."""
        est = untangle_estimate(nodes, elem)
        self.estimates[name] = est if self.budget is None else min(est, max(self.budget.left, 0.0))
        stage = f"untangle ~{self.estimates[name]:.0f} s"
        out = untangle_grid(nodes, cand["locators"], cand["paths"], cand["taus"], self.v, elem, start=start,
                            spacing=cand["spacing"] * (0.5 if elem == "hex20" else 1.0),  # half steps
                            budget=self.budget, progress=(lambda d, t, s_=stage: self.report(s_, d, t)))
        return out

    def time_left(self) -> bool:
        return self.budget is None or not self.budget.spent

    def element_grid(self, cand):
        """The candidate's 8-node grid, untangled where needed (once): (nodes, iterations, stopped, lift, coords)."""
        if "grid8" not in cand:
            t_ = time.perf_counter()
            out = (cand["nodes"], 0, False, {"max_lift": 0.0, "lifted_nodes": 0}, None)
            if self.untangle and cand["q0"] < SJ_TARGET and self.time_left():
                nodes, nit, stopped, lift = self.untangled(cand, cand["nodes"], cand["name"], "hex8")
                out = (nodes, nit, stopped, lift, lift.pop("coords"))
            cand["grid8"] = out
            cand["times"]["untangle"] += time.perf_counter() - t_
        return cand["grid8"]

    def finish(self, cand) -> None:
        """The candidate's element grid and its quality (``nodes``, ``sj``, ``si``, ``q``, ``nit``, ``stopped``...)."""
        nodes, nit, stopped, lift, coords = self.element_grid(cand)
        t3 = time.perf_counter()
        if self.element == "hex20":
            nodes, nit, stopped, lift = self.hex20_grid(cand, nodes, coords, nit, stopped, lift)
        sj, si = element_quality(nodes, self.element)
        si = float(si.min())  # inside the elements
        cand.update(nodes=nodes, sj=sj, si=si, q=min(float(sj.min()), si), nit=nit, stopped=stopped, lift=lift)
        cand["times"]["untangle"] += time.perf_counter() - t3

    def hex20_grid(self, cand, coarse, coords, nit, stopped, lift):
        """The half-step grid from the 8-node grid ``coarse``, its 20-node elements untangled (or straightened)."""
        nodes, start = refine_grid(coarse, coords, cand["locators"], cand["paths"], cand["taus"], self.v)
        sj, si = element_quality(nodes, "hex20")
        if self.untangle and min(float(sj.min()), float(si.min())) < SJ_TARGET and not stopped and self.time_left():
            nodes, it2, stopped, lift = self.untangled(cand, nodes, cand["name"] + " (hex20)", "hex20", start)
            lift.pop("coords")
            nit += it2
            sj, si = element_quality(nodes, "hex20")
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
        return nodes, nit, stopped, lift

    # -- the facts ----------------------------------------------------------------------------------------------
    def info(self, best, cands, keep_locators, t_start) -> HexGridInfo:
        """The facts of :func:`hex_parameterisation` (:class:`~porecad.param.hexgrid_info.HexGridInfo`)."""
        tp = time.perf_counter()
        label_patches(self.v, self.f, best["paths"])  # timed once for the report (the check ran in the corner stage)
        t_patches = time.perf_counter() - tp
        sj = best["sj"]
        N_arr = np.array(self.N)
        n_all = int(np.prod(N_arr + 1))
        n_in = int(np.prod(np.maximum(N_arr - 1, 0)))
        times = {"setup": self.t_setup, "corners": self.t_tried, **best["times"], "patches": t_patches}
        times["geodesics"] = max(times["geodesics"] - t_patches, 0.0)
        times["total"] = time.perf_counter() - t_start
        return HexGridInfo(
            corner_choice=best["name"], grid=self.cells, element=self.element, subdivisions=self.nsub,
            patch_maps=best["kinds"], patch_balance=int(self.balance), path_fallbacks=int(best["fallbacks"]),
            times=times, min_scaled_jacobian=float(sj.min()), min_scaled_jacobian_inside=best["si"],
            fraction_below_poor=float(np.mean(sj < SJ_POOR)), min_scaled_jacobian_laplace=best["sj0"],
            untangle_iterations=best["nit"], untangle_stopped=bool(best.get("stopped", False)),
            straightened=best.get("straightened"), boundary_lift=best["lift"], estimates=self.estimates,
            nodes=n_all, boundary_nodes=n_all - n_in, interior_nodes=n_in, hexes=int(sj.size),
            rejected=[r for r in self.rejected if r[0] != best["name"]],
            laplace_grids=[{"choice": c_["name"], "folded_elements": c_["bad0"], "min_quality": c_["q0"]}
                           for c_ in cands],
            conformal_sphere=self.lazy.get("sphere_info"),
            corners=best["corners"], vertices=self.v, faces=self.f, paths=best["paths"], patch_labels=best["labels"],
            # not JSON: for fits that need every surface vertex's cube parameters
            locators=best["locators"] if keep_locators else None)
