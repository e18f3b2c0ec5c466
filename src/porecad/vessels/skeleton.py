"""Segmented images → centreline graphs with radii (skeletonisation + distance transform).

Steps of :func:`image_centreline`:

1. read the image (SimpleITK: NIfTI, MHA, NRRD, DICOM; :func:`porecad.bodies.image.read_image`);
2. Gaussian smoothing (``smooth`` voxels) against noise, then the foreground
   ``value > threshold``; by default the threshold is halfway between the
   plateau values (medians at least 2.5 voxels inside and in a ring outside
   Otsu's foreground, or a CT's ≥ 150 HU: :func:`default_threshold`), which
   is where a partial-volume edge crosses; the largest 26-connected component
   with its holes filled;
3. skeletonisation by TEASAR (:func:`skeleton_graph`: penalised shortest
   paths inside the mask, a tree by construction); terminal spurs shorter
   than 2.5 × the local radius are pruned (repeatedly);
4. radii from the Euclidean distance transform at the skeleton voxels
   (``edt − h/2``: the boundary lies half a voxel inside the background);
5. sub-voxel refinement on the image boundary itself: boundary points by
   marching cubes on the smoothed image at the threshold; each point that
   projects perpendicularly onto the centreline (``|cos| < 0.3`` with the
   tangent) is assigned to its nearest node; the node moves to the mean of
   its points projected on its normal plane, and its radius becomes their
   median distance (two passes; nodes with fewer than 8 points keep the EDT
   values); radii get the blur correction ``σ²/(2r)`` (a Gaussian of
   ``σ`` mm moves a cylinder's iso-surface inwards by that much); junctions
   are re-placed from the fitted branch axes (:func:`porecad.vessels.wall_fit.straighten_junctions`),
   the ends redone (:func:`trim_tips`), and the chains smoothed by a 3-point
   moving average (positions and radii, end and junction nodes fixed).

Errors (one line): an image that is not 3-D, one with no foreground ("empty
image") or whose foreground has no skeleton.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..errors import InputError
from .graph import CentrelineGraph
from .wall_fit import refine_on_boundary, straighten_junctions


def _largest_component(mask):
    lab, n = ndimage.label(mask, structure=np.ones((3, 3, 3)))
    if n == 0:
        return mask
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    return lab == int(np.argmax(sizes))


#: a grey image is taken for a CT in Hounsfield units when it holds air (at most this value) ...
CT_AIR_HU = -500.0
#: ... and then the lumen's first guess: contrast-enhanced blood lies at 200–500 HU, soft tissue below 100 HU
CT_LUMEN_HU = 150.0


def is_ct(values) -> bool:
    """Whether a grey image looks like a CT in Hounsfield units: some air (≤ −500) and something at ≥ 150."""
    v = np.asarray(values)
    return bool(v.min() <= CT_AIR_HU and v.max() >= CT_LUMEN_HU and np.count_nonzero(v <= CT_AIR_HU) > 0.001 * v.size)


def default_threshold(s) -> float:
    """The lumen threshold of a (smoothed) image: halfway between the lumen's plateau and its surroundings'.

    A first foreground: Otsu's threshold, or :data:`CT_LUMEN_HU` for a CT
    (:func:`is_ct`; Otsu would split air from the patient there). The
    plateaus are the medians at least 2.5 voxels inside that foreground and
    in the ring 2.5–6 voxels outside it (the tissue around the lumen, where
    a partial-volume edge ends; not the far background); the threshold is
    halfway between, where the edge crosses.
    """
    if is_ct(s):
        t0 = CT_LUMEN_HU
    else:
        from skimage.filters import threshold_otsu
        t0 = float(threshold_otsu(s))
    m0 = s > t0
    if not m0.any():
        return t0
    deep_in = ndimage.distance_transform_edt(m0) >= 2.5
    d_out = ndimage.distance_transform_edt(~m0)
    ring = (d_out >= 2.5) & (d_out <= 6.0)
    if deep_in.any() and ring.any():
        return 0.5 * (float(np.median(s[deep_in])) + float(np.median(s[ring])))
    return t0


def mask_from_array(arr, spacing, threshold=None, smooth: float = 1.0):
    """``(mask, smoothed, threshold)`` of a grey or label image (step 2)."""
    a = np.asarray(arr, dtype=np.float32)
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise InputError("the image is empty or has non-finite values")
    if float(a.max()) == float(a.min()):
        raise InputError("the image is empty: it is constant, there is no vessel to segment")
    s = ndimage.gaussian_filter(a, smooth) if smooth and smooth > 0 else a
    if threshold is None:
        threshold = default_threshold(s)
    mask = s > threshold
    if not mask.any():
        raise InputError(f"the image is empty: no voxel above the threshold {threshold:g}")
    mask = ndimage.binary_fill_holes(_largest_component(mask))
    return mask, s, float(threshold)


def skeleton_graph(mask, spacing, scale: float = 2.0, const: float | None = None):
    """Tree skeleton of a binary mask by TEASAR (steps 3–4); coordinates ``index × spacing``.

    TEASAR (Sato et al. 2000, "TEASAR: tree-structure extraction algorithm
    for accurate and robust skeletons"): the root is the voxel farthest (by
    geodesic distance inside the mask) from an arbitrary voxel; shortest paths
    from the root are taken in the *penalised* metric ``ℓ (1 + 5000 (1 − D/D_max)^16)``
    (``D`` the distance transform), which keeps them on the medial axis; the
    geodesically farthest voxel not yet covered is traced back to the tree, and
    the voxels within ``scale × D + const`` of the new path are covered; repeat
    until every voxel is covered. A new path joins the tree at its first voxel
    whose inscribed ball (radius ``D``, at least 1.5 voxels) holds a tree
    node: in a thick trunk a side branch's path would otherwise run beside
    the trunk's axis until it came within a voxel or two of it. The paths share their meeting voxels, so they
    join into a tree. (skimage's 3-D ``skeletonize`` returns an empty skeleton
    even for a solid box in scikit-image 0.26.0 as installed here, so it is not used.)
    """
    from .graph import from_polylines
    h = np.asarray(spacing, float)
    const = float(h.max()) if const is None else const
    idx = np.argwhere(mask)
    n = len(idx)
    if n < 8:
        raise InputError("the segmented image has no centreline (foreground too small)")
    edt = ndimage.distance_transform_edt(mask, sampling=h)
    D = edt[tuple(idx.T)]
    P = idx * h
    plain, pen = _voxel_graphs(mask, idx, D, h)
    paths = _teasar_paths(P, D, plain, pen, h, scale, const)
    if not paths:
        raise InputError("the segmented image has no centreline (foreground too small or not tubular)")
    rad = np.maximum(D - 0.5 * float(h.min()), 0.5 * float(h.min()))
    g = from_polylines([P[p] for p in paths], [rad[p] for p in paths], merge_tol=1e-9)
    g = prune_spurs(g)
    return g, edt


def _voxel_graphs(mask, idx, D, h):
    """The 26-neighbour graph of the mask's voxels ``idx`` (n, 3), as two symmetric CSR matrices (n, n).

    Takes the mask, its voxels, their distance transform ``D`` and the spacing ``h``; returns the plain
    graph (edge lengths) and the penalised one (lengths × the mean of ``(D_max / D)⁴`` at both ends).
    """
    from scipy.sparse import coo_matrix
    n = len(idx)
    lut = -np.ones(mask.shape, dtype=np.int64)
    lut[tuple(idx.T)] = np.arange(n)
    rows, cols, w = [], [], []
    for dz in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if (dz, dy, dx) <= (0, 0, 0):
                    continue
                q = idx + np.array([dz, dy, dx])
                ok = np.all((q >= 0) & (q < np.array(mask.shape)), axis=1)
                j = np.full(n, -1)
                j[ok] = lut[tuple(q[ok].T)]
                good = j >= 0
                rows.append(np.flatnonzero(good))
                cols.append(j[good])
                w.append(np.full(int(good.sum()), float(np.linalg.norm(np.array([dz, dy, dx]) * h))))
    rows, cols, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(w)
    plain = coo_matrix((np.r_[w, w], (np.r_[rows, cols], np.r_[cols, rows])), shape=(n, n)).tocsr()
    pen_node = (D.max() / np.maximum(D, 1e-12)) ** 4
    pw = w * 0.5 * (pen_node[rows] + pen_node[cols])
    pen = coo_matrix((np.r_[pw, pw], (np.r_[rows, cols], np.r_[cols, rows])), shape=(n, n)).tocsr()
    return plain, pen


def _teasar_paths(P, D, plain, pen, h, scale, const):
    """TEASAR's paths over the voxels at ``P`` (distance transform ``D``) of the graphs of :func:`_voxel_graphs`.

    Takes the voxel positions, ``D``, the plain and penalised graphs, the spacing ``h`` and the cover
    ``scale × D + const``; returns the paths (voxel index arrays of ≥ 2 voxels) from the farthest
    uncovered voxel back to the tree, until the root's component is covered.
    """
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree
    n = len(P)
    d0 = dijkstra(plain, indices=int(np.argmax(D)))
    d0[~np.isfinite(d0)] = -1
    root = int(np.argmax(d0))
    geo = dijkstra(plain, indices=root)
    _, pred = dijkstra(pen, indices=root, return_predecessors=True)
    reach = np.isfinite(geo)
    covered = ~reach  # only the root's component is skeletonised
    in_tree = np.zeros(n, bool)
    in_tree[root] = True
    tree = cKDTree(P)
    paths = []
    snap = 1.5 * float(h.max())
    while not covered.all():
        cand = np.where(covered, -1.0, geo)
        far = int(np.argmax(cand))
        path = [far]
        tv = np.flatnonzero(in_tree)
        ttree = cKDTree(P[tv])
        while not in_tree[path[-1]] and pred[path[-1]] >= 0:
            nxt = int(pred[path[-1]])
            dd, jj = ttree.query(P[nxt])
            if dd <= max(snap, D[nxt]) and not in_tree[nxt]:  # the tree is in nxt's inscribed ball
                path.append(int(tv[jj]))  # join the tree where the path comes alongside it
                break
            path.append(nxt)
        path = np.asarray(path)
        in_tree[path] = True
        for v in path:
            covered[tree.query_ball_point(P[v], scale * D[v] + const)] = True
        covered[path] = True
        if len(path) >= 2:
            paths.append(path)
    return paths


def trim_tips(g: CentrelineGraph, boundary=None, factor: float = 1.5) -> CentrelineGraph:
    """Redo the ends: drop each terminal chain's last ``factor`` × radius (the skeleton bends
    towards the farthest cap voxel there), then, with boundary points, extend the end along its
    axis so that the end ball ``B(p, r)`` reaches the cap: ``p = e + (L − r) u`` with ``L`` the
    farthest boundary point along the axis ``u`` within ``r / 2`` of it."""
    deg = g.degrees()
    drop = np.zeros(g.n_nodes, bool)
    ends = []
    for chain in g.branches():
        for c in (chain, chain[::-1]):
            if deg[c[0]] != 1:
                continue
            s = np.r_[0, np.cumsum(np.linalg.norm(np.diff(g.points[c], axis=0), axis=1))]
            k = 1
            while k < len(c) - 3 and s[k] < factor * g.radii[c[k]] and deg[c[k]] == 2:
                k += 1
            drop[c[:k]] = True
            ends.append(c[k:k + 4])
    if not drop.any() or (~drop).sum() < 2:
        return g
    new_pts, new_r, new_e = [], [], []
    if boundary is not None:
        for tail in ends:
            if len(tail) < 3:
                continue
            e = g.points[tail[0]]
            r = float(g.radii[tail[0]])
            u = g.points[tail[0]] - g.points[tail[-1]]
            u /= np.linalg.norm(u)
            w = boundary - e
            along = w @ u
            perp = np.linalg.norm(w - np.outer(along, u), axis=1)
            sel = (along > 0) & (perp < 0.5 * r)
            if sel.any():
                L = float(along[sel].max())
                if L - r > 1e-9:
                    new_pts.append(e + (L - r) * u)
                    new_r.append(r)
                    new_e.append(tail[0])
    keep = ~drop
    old = np.flatnonzero(keep)
    g2 = _subgraph(g.points, g.radii, g.edges, keep)
    if new_pts:
        remap = -np.ones(g.n_nodes, dtype=np.int64)
        remap[old] = np.arange(len(old))
        n0 = g2.n_nodes
        g2 = CentrelineGraph(np.r_[g2.points, np.asarray(new_pts)], np.r_[g2.radii, new_r],
                             np.r_[g2.edges, np.stack([remap[new_e], n0 + np.arange(len(new_pts))], axis=1)])
    return g2


def _subgraph(P, R, E, keep):
    new = -np.ones(len(P), dtype=np.int64)
    new[keep] = np.arange(int(keep.sum()))
    E = E[keep[E[:, 0]] & keep[E[:, 1]]]
    return CentrelineGraph(P[keep], R[keep], new[E])


def prune_spurs(g: CentrelineGraph, factor: float = 2.5, rounds: int = 10) -> CentrelineGraph:
    """Remove terminal branches shorter than ``factor`` × the radius at their junction."""
    for _ in range(rounds):
        deg = g.degrees()
        drop = np.zeros(g.n_nodes, bool)
        for chain in g.branches():
            a, b = chain[0], chain[-1]
            if (deg[a] == 1) == (deg[b] == 1):
                continue  # not a spur (end-to-end or junction-to-junction)
            junction = b if deg[a] == 1 else a
            L = float(np.sum(np.linalg.norm(np.diff(g.points[chain], axis=0), axis=1)))
            if L < factor * g.radii[junction]:
                drop[chain[chain != junction]] = True
        if not drop.any():
            break
        g = _subgraph(g.points, g.radii, g.edges, ~drop)
    return g


def smooth_chains(g: CentrelineGraph, iterations: int = 2) -> CentrelineGraph:
    """3-point moving average of positions and radii along chains (ends and junctions fixed)."""
    deg = g.degrees()
    for _ in range(iterations):
        P, R = g.points.copy(), g.radii.copy()
        for chain in g.branches():
            if len(chain) < 3:
                continue
            for k in range(1, len(chain) - 1):
                v = chain[k]
                if deg[v] != 2:
                    continue
                P[v] = (g.points[chain[k - 1]] + 2 * g.points[v] + g.points[chain[k + 1]]) / 4
                R[v] = (g.radii[chain[k - 1]] + 2 * g.radii[v] + g.radii[chain[k + 1]]) / 4
        g.points, g.radii = P, R
    return g


def array_centreline(arr, geometry, threshold=None, smooth: float = 1.0):
    """:func:`image_centreline` on an in-memory array ``[i, j, k]`` with its geometry."""
    from skimage.measure import marching_cubes
    h = np.asarray(geometry["spacing"], float)
    mask, s, thr = mask_from_array(arr, h, threshold, smooth)
    g, edt = skeleton_graph(mask, h)  # index-scaled coordinates first (origin 0, axes aligned)
    r_skeleton = float(np.median(g.radii))
    smooth_chains(g, iterations=6)
    # boundary points of the smoothed image at the threshold, restricted to the kept component
    sm = np.where(ndimage.binary_dilation(mask, iterations=2), s, min(float(s.min()), thr - 1))
    verts, _f, _n, _v = marching_cubes(sm, level=thr, spacing=tuple(h))
    refine_on_boundary(g, verts)
    if smooth and smooth > 0:  # Gaussian blur moves a cylinder's iso-surface in by σ²/(2r)
        sig = float(smooth) * float(h.mean())
        g.radii = g.radii + sig * sig / (2.0 * g.radii)
    straighten_junctions(g)
    g = trim_tips(g, verts)
    smooth_chains(g)
    D = np.asarray(geometry.get("direction", np.eye(3)), float)
    if smooth and smooth > 0:  # the same blur bias on the boundary points (for RBF fits): out by σ²/(2r)
        from scipy.spatial import cKDTree
        _, near = cKDTree(g.points).query(verts)
        out = verts - g.points[near]
        out /= np.maximum(np.linalg.norm(out, axis=1), 1e-12)[:, None]
        verts = verts + (sig * sig / (2.0 * g.radii[near]))[:, None] * out
    g.points = g.points @ D.T + np.asarray(geometry["origin"], float)
    g.boundary_points = verts @ D.T + np.asarray(geometry["origin"], float)
    info = {"threshold": thr, "foreground_voxels": int(mask.sum()), "skeleton_nodes": int(g.n_nodes),
            "boundary_points": int(len(verts)), "spacing": h.tolist()}
    g.findings = []
    if len(np.unique(np.asarray(arr)[::3, ::3, ::3])) > 16:  # a grey image, not a segmentation
        from ..findings import Finding
        from .tubularity import TUBE_FRACTION, tube_fraction
        frac = tube_fraction(mask, h, r_skeleton)
        info["tube_fraction"] = round(frac, 3)
        if frac < TUBE_FRACTION:
            g.findings.append(Finding(
                "not-tube-like", f"only {100 * frac:.0f} % of the object taken from the grey image is tube-like "
                "(Frangi vesselness): bright structures joined to the vessel, such as bone, are probably part of "
                "the model; give seed points in the vessel (input.seeds) or a centreline with the image",
                {"tube_fraction": round(frac, 3), "limit": TUBE_FRACTION}))
    return g, info


def image_centreline(path, threshold=None, smooth: float = 1.0):
    """Centreline graph with radii of a segmented (or grey) vessel image; ``(graph, info)``."""
    from ..bodies.image import read_image
    arr, geometry = read_image(path)
    if arr.size == 0:
        raise InputError(f"{path}: the image is empty")
    try:
        g, info = array_centreline(arr, geometry, threshold=threshold, smooth=smooth)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    g.source = str(path)
    return g, info


def read_point_cloud(path) -> np.ndarray:
    """Boundary points ``(N, 3)``: ``.npy`` (N, ≥3), a mesh's vertices (``.ply .stl .obj .off``) or
    text rows ``x y z [...]`` (spaces, tabs or commas; ``#`` comments; extra columns ignored)."""
    import os
    from pathlib import Path
    from ..io.confine import regular_file
    p = Path(os.fspath(path))
    regular_file(p, "a point file")
    suf = p.suffix.lower()
    try:
        if suf == ".npy":
            a = np.asarray(np.load(p, allow_pickle=False), dtype=float)
        elif suf in (".ply", ".stl", ".obj", ".off"):
            import trimesh
            a = np.asarray(trimesh.load(p, process=False, force="mesh").vertices, dtype=float)
        else:
            rows = []
            for line in p.read_text().splitlines():
                s = line.split("#", 1)[0].replace(",", " ").split()
                if s:
                    rows.append([float(v) for v in s[:3]])
            a = np.asarray(rows, dtype=float)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: not a point cloud of x y z rows ({type(exc).__name__})") from None
    if a.ndim != 2 or a.shape[1] < 3 or len(a) == 0:
        raise InputError(f"{p}: the point cloud is empty or not (N, 3)")
    a = np.ascontiguousarray(a[:, :3])
    if not np.all(np.isfinite(a)):
        raise InputError(f"{p}: the point cloud has non-finite coordinates")
    return a


def fit_to_boundary(g: CentrelineGraph, points: np.ndarray) -> CentrelineGraph:
    """Fit a centreline graph's positions and radii to boundary points of the vessel wall
    (:func:`~porecad.vessels.wall_fit.refine_on_boundary`,
    :func:`~porecad.vessels.wall_fit.straighten_junctions`, chain smoothing); the ends keep
    their places. Returns the graph (modified)."""
    if len(points) < 12:
        raise InputError("the boundary point cloud has too few points (need at least 12)")
    refine_on_boundary(g, np.asarray(points, float))
    straighten_junctions(g)
    smooth_chains(g)
    fitted = g.info.get("fitted")
    g.info = {k: v for k, v in g.info.items() if k != "fitted"}
    g.info["fitted_nodes"] = int(np.sum(fitted)) if fitted is not None else 0
    g.info["boundary_points"] = int(len(points))
    if g.info["fitted_nodes"] == 0:
        raise InputError("no centreline node is surrounded by the boundary points (wrong cloud or units?)")
    return g
