"""The ``vessel`` job: implicit vessel models from centrelines or images (document 003 ch. 3–4).

Steps: a centreline graph with radii (``.vtp`` / ``.swc`` / ``.json`` file,
or a segmented image skeletonised with distance-transform radii refined on
the image boundary), validated (connected, positive radii, no
self-intersection); skeleton marching into overlapping segments (003 §3.2);
per segment a swept-radius tube truncated to its box, joined by Li's
shape-preserving union (003 Eq. 2.12) or another 003 blend; optionally a
multi-layer wall from the approximate distance with porous layers (003 ch. 4);
open ends trimmed by planes; polygonisation; validation (closed, manifold);
the outputs. Recipe keys: see :func:`run_vessel`.
"""

from __future__ import annotations

import time

import numpy as np

from . import __version__
from .errors import InputError, ResourceError

MAX_SAMPLES = 120_000_000


def load_graph(spec: dict):
    """The centreline graph of a recipe's ``input`` (validated), and input info."""
    kind = spec.get("kind", "centreline")
    if kind == "centreline":
        from .vessels.readers import read_centreline
        g = read_centreline(spec["path"], radius_array=spec.get("radius_array"))
        info = {"kind": kind, "path": str(spec["path"]), **g.info}
        if spec.get("points"):
            from .vessels.skeleton import fit_to_boundary, read_point_cloud
            g.validate()  # the graph must make sense before it is fitted
            cloud = read_point_cloud(spec["points"])
            fit_to_boundary(g, cloud)
            g.boundary_points = cloud
            info.update(points=str(spec["points"]), fitted_nodes=g.info["fitted_nodes"],
                        boundary_points=g.info["boundary_points"])
    elif kind == "image":
        from .vessels.skeleton import image_centreline
        g, info = image_centreline(spec["path"], threshold=spec.get("threshold"),
                                   smooth=spec.get("smooth", 1.0))
        info = {"kind": kind, "path": str(spec["path"]), **info}
    elif kind == "graph":  # in-process use (tests, benchmarks)
        g = spec["graph"]
        info = {"kind": kind}
    else:
        raise InputError(f"unknown vessel input {kind!r}")
    g.validate()
    info.update(nodes=int(g.n_nodes), edges=int(len(g.edges)),
                radius_min=float(g.radii.min()), radius_max=float(g.radii.max()))
    return g, info


def parse_blend(value):
    """``"n,delta"`` or a dict → blend parameters for :mod:`porecad.fields.blends`."""
    from .fields.blends import check_blend
    if isinstance(value, dict):
        b = dict(value)
    elif value is None:
        b = {"kind": "li", "n": 2, "delta": 0.2}
    else:
        parts = str(value).split(",")
        if len(parts) != 2:
            raise InputError(f"--blend takes n,delta (e.g. 2,0.2), got {value!r}")
        try:
            b = {"kind": "li", "n": int(parts[0]), "delta": float(parts[1])}
        except ValueError:
            raise InputError(f"--blend takes n,delta (e.g. 2,0.2), got {value!r}") from None
    kind = b.pop("kind", "li")
    check_blend(kind, **b)
    return {"kind": kind, **b}


def build_field(graph, voxel: float, blend: dict, wall=None, porous=None, trim=False, segment_length=None,
                segment_angle=45.0, workers=1, executor="thread", local=True, timings=None, boundary=None):
    """Sample the vessel solid on a grid; return ``(values, grid, extras)`` (see :func:`run_vessel`)."""
    from .mesh.polygonise import Grid
    from .vessels.model import evaluate_grid
    from .vessels.segments import march
    from .vessels import walls as W
    timings = {} if timings is None else timings
    h = float(voxel)
    if not np.isfinite(h) or h <= 0:
        raise InputError(f"--voxel must be a positive length in mm, got {voxel}")
    T = float(sum(wall)) if wall else 0.0
    delta = float(blend.get("delta", 0.0)) if blend["kind"] == "li" else 0.0
    pad = T + delta + 3.0 * h
    c = pad
    lo, hi = graph.bounds()
    lo, hi = lo - (T + 3 * h), hi + (T + 3 * h)
    grid = Grid.from_box(lo, hi, spacing=h)
    if grid.n_samples > MAX_SAMPLES:
        raise ResourceError(f"the grid would have {grid.n_samples:,} samples (limit {MAX_SAMPLES:,}); "
                            "use a larger --voxel")
    t = time.perf_counter()
    segs = march(graph, length=segment_length, angle_deg=segment_angle, pad=pad)
    timings["march_s"] = time.perf_counter() - t
    t = time.perf_counter()
    stats = {}
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    bl = {k: v for k, v in blend.items() if k != "kind"}
    F = evaluate_grid(segs, graph, xs, ys, zs, c, {"kind": blend["kind"], **bl}, local=local,
                      workers=workers, executor=executor, stats=stats, boundary=boundary)
    timings["field_s"] = time.perf_counter() - t
    extras = {"segments": segs, "c": c, "lumen": F, "eval": stats}
    out = F
    if wall:
        t = time.perf_counter()
        d = W.approximate_distance(F, grid.spacing)
        phis = {}
        if porous:
            phis[int(porous["layer"])] = W.porous_values(porous["type"], porous["cell_size"], xs, ys, zs)
        out = W.wall_field(d, wall, phis)
        extras.update(distance=d, porous_values=phis)
        timings["wall_s"] = time.perf_counter() - t
    if trim:
        out = W.trim_ends(out, xs, ys, zs, graph.ends(), T)
    return out, grid, extras


def drop_specks(vertices, faces, voxel_volume: float):
    """Remove closed shells enclosing less than 2 voxel volumes (sub-grid specks and pockets
    marching cubes leaves where a feature is about one voxel); count what remains.

    Returns ``(vertices, faces, info)`` with ``shells``, ``solid_islands`` (positive-volume
    shells besides the largest), ``cavities`` (negative-volume shells: closed voids) and
    ``specks_removed``.
    """
    import trimesh
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse import coo_matrix
    adj = trimesh.Trimesh(vertices, faces, process=False).face_adjacency
    n = len(faces)
    _, lab = connected_components(coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(n, n)),
                                  directed=False)
    p0, p1, p2 = (vertices[faces[:, k]] for k in range(3))
    vol = np.bincount(lab, weights=np.einsum("ij,ij->i", p0, np.cross(p1, p2)) / 6.0)
    speck = np.abs(vol) < 2.0 * voxel_volume
    keep_faces = ~speck[lab]
    if speck.any() and keep_faces.any():
        from .mesh.weld import compact
        vertices, faces = compact(vertices, faces[keep_faces])
    vol = vol[~speck]
    info = {"shells": int(len(vol)), "solid_islands": int(max((vol > 0).sum() - 1, 0)),
            "cavities": int((vol < 0).sum()), "specks_removed": int(speck.sum())}
    return vertices, faces, info


def porous_layer_connectivity(d, wall, layer, phi, spacing, trim_mask=None, min_voxels: int = 27) -> dict:
    """Connected components of the material of porous layer ``layer`` on the grid (26-connectivity).

    The layer's material is ``{d_{k-1} ≤ d̃ ≤ d_k} ∩ {φ ≤ 0}`` (within the trimmed solid).
    ``components`` counts pieces of at least ``min_voxels`` samples (3³: smaller
    ones are below the grid's resolution); ``components_all`` counts every piece;
    ``largest_fraction`` is the share of the layer's material in the largest.
    """
    from scipy import ndimage
    from .vessels.walls import band
    off = np.concatenate([[0.0], np.cumsum(wall)])
    mat = (band(d, off[layer - 1], off[layer]) <= 0) & (phi <= 0)
    if trim_mask is not None:
        mat &= trim_mask
    lab, n = ndimage.label(mat, structure=np.ones((3, 3, 3)))
    sizes = np.bincount(lab.ravel())[1:] if n else np.zeros(0)
    layer_vox = int((band(d, off[layer - 1], off[layer]) <= 0).sum())
    return {"components": int((sizes >= min_voxels).sum()), "components_all": int(n),
            "largest_fraction": float(sizes.max() / sizes.sum()) if n else 0.0,
            "material_fraction": float(mat.sum() / max(layer_vox, 1))}


def run_vessel(recipe: dict, force: bool = False, progress=None) -> dict:
    """Run a ``vessel`` recipe; write its outputs atomically; return the report.

    Recipe: ``input`` (``kind`` centreline|image, ``path``), ``voxel`` (mm),
    ``blend`` (``{"kind": "li", "n": 2, "delta": 0.2}`` or ``"n,delta"``),
    ``wall`` (layer thicknesses, mm, from the lumen out, or None for a solid
    lumen), ``porous`` (``{"layer": K, "type": "G", "cell_size": L}``),
    ``trim_ends`` (bool; default: True with a wall), ``segment_length``,
    ``segment_angle`` (deg), ``workers``, ``executor`` (thread|process),
    ``evaluation`` (local|global), ``output`` (``mesh``, ``report``).
    """
    from .mesh.polygonise import polygonise
    from .mesh.validate import signed_volume
    from .outputs import check_outputs, finish_job, validated_report
    from .vessels.model import GridArraySampler
    from .vessels.walls import PERIODIC_003, check_wall

    t_start = time.perf_counter()
    out = dict(recipe.get("output", {}))
    check_outputs(out, ("mesh", "report"), force)
    voxel = recipe.get("voxel")
    if voxel is None:
        raise InputError("give --voxel H (the grid spacing in mm)")
    blend = parse_blend(recipe.get("blend"))
    wall = recipe.get("wall")
    porous = recipe.get("porous")
    if porous and not wall:
        raise InputError("--porous-layer needs --wall T1,T2,...")
    if wall:
        wall = check_wall(wall, porous and porous.get("layer"), porous and porous.get("cell_size"))
    if porous:
        from .fields.tpms import get_type
        if porous["type"] not in PERIODIC_003:
            get_type(porous["type"])  # one-line error for an unknown type
    trim = recipe.get("trim_ends")
    trim = bool(wall) if trim is None else bool(trim)
    workers = int(recipe.get("workers", 1))
    if workers < 1:
        raise InputError(f"--workers must be ≥ 1, got {workers}")
    evaluation = recipe.get("evaluation", "local")
    if evaluation not in ("local", "global"):
        raise InputError(f"evaluation is local or global, got {evaluation!r}")
    fit = recipe.get("fit")
    if fit not in (None, "rbf", "tube"):
        raise InputError(f"fit is rbf or tube, got {fit!r}")
    timings = {}
    t = time.perf_counter()
    graph, info = load_graph(dict(recipe.get("input", {})))
    timings["input_s"] = time.perf_counter() - t
    boundary = getattr(graph, "boundary_points", None)
    if fit == "rbf" and boundary is None:
        raise InputError("--fit rbf needs boundary points: give --image or --points")
    if fit is None:
        fit = "rbf" if boundary is not None else "tube"
    info["fit"] = fit
    values, grid, ex = build_field(graph, voxel, blend, wall=wall, porous=porous, trim=trim,
                                   segment_length=recipe.get("segment_length"),
                                   segment_angle=float(recipe.get("segment_angle", 45.0)), workers=workers,
                                   executor=recipe.get("executor", "thread"), local=evaluation == "local",
                                   timings=timings, boundary=boundary if fit == "rbf" else None)
    t = time.perf_counter()
    stage = (lambda done, total: progress("mesh", done, total)) if progress is not None else None
    res = polygonise(GridArraySampler(values, grid), grid, caps=True, progress=stage)
    timings["polygonise_s"] = time.perf_counter() - t
    if len(res.faces) == 0:
        raise InputError("the vessel model is empty at this --voxel (radii smaller than the grid spacing?)")
    vertices, faces, shells = drop_specks(res.vertices, res.faces, float(np.prod(grid.spacing)))
    t = time.perf_counter()
    mesh_rep, _ = validated_report(vertices, faces, what="the vessel model")
    timings["validate_s"] = time.perf_counter() - t
    segs = ex["segments"]
    report = {"job": "vessel", "porecad_version": __version__, "input": info,
              "blend": blend, "voxel": float(voxel), "grid": {"shape": list(grid.shape),
                                                              "spacing": list(grid.spacing)},
              "branches": int(max(s.branch for s in segs) + 1), "segments": len(segs),
              "evaluation": evaluation, "workers": workers, "trim_ends": trim,
              "evaluated_samples": ex["eval"].get("evaluated_samples"), "grid_samples": grid.n_samples,
              "rbf_segments": int(ex["eval"].get("rbf_segments", 0))}
    report.update(mesh_rep)
    report.update(shells)
    if wall and min(wall) < 3 * float(voxel):
        report.setdefault("warnings", []).append(
            f"a wall layer of {min(wall):g} mm spans fewer than 3 voxels of {float(voxel):g} mm: thin skins and "
            "pore walls may break up; use --voxel ≤ the thinnest layer / 3")
    if wall:
        report["wall"] = {"thicknesses": wall, "total": float(sum(wall))}
        if porous:
            report["porous"] = dict(porous)
            report["porous"]["connectivity"] = porous_layer_connectivity(
                ex["distance"], wall, int(porous["layer"]), ex["porous_values"][int(porous["layer"])],
                grid.spacing, trim_mask=values <= 0)
    report["volume"] = float(signed_volume(vertices, faces))
    return finish_job(report, vertices, faces, out, force, timings, t_start, design=False)
