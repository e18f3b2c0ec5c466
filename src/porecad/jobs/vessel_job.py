"""The ``vessel`` job: implicit vessel models from centrelines or images (document 003 ch. 3–4).

Steps: a centreline graph with radii (``.vtp`` / ``.swc`` / ``.json`` file,
or a segmented image skeletonised with distance-transform radii refined on
the image boundary), validated (connected, positive radii, no
self-intersection); skeleton marching into overlapping segments (003 §3.2);
per segment a swept-radius tube truncated to its box, joined by Li's
shape-preserving union (003 Eq. 2.12) or another 003 blend; optionally a
multi-layer wall from the approximate distance with porous layers (003 ch. 4);
open ends trimmed by planes; polygonisation; validation (closed, manifold);
the outputs.

Recipe::

    job = "vessel"
    [input]  kind = "centreline" | "image", path = "tree.json" (.vtp .swc .json, or an image),
             points = "wall.xyz" (centreline: boundary points to fit), threshold (image), radius_array (.vtp),
             image = "ct.mha", frame = "auto" | "lps" | "ras" (centreline: segment the image along it),
             seeds = [[x, y, z], ...] (image: the vessel between the seeds, mm)
    voxel = 0.1                       # grid spacing, mm
    blend = "2,0.2" | {kind = "li" | "sharp" | "softmax" | "rfunc", n, delta, k, alpha}
    wall = [0.1, 0.3, 0.2]            # layer thicknesses from the lumen out (none: a solid lumen)
    porous = {layer = 2, type = "G", cell_size = 0.6}
    trim_ends = true, fit = "rbf" | "ellipsoid" | "tube", segment_length, segment_angle = 45,
    evaluation = "local" | "global", workers = 1, executor = "thread" | "process"
    [output] mesh, report, recipe
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import InputError, ResourceError
from ..findings import Finding
from .contract import DeferredDomain, Job, Result, Timer, stage_progress
from .outputs import validated_report

MAX_SAMPLES = 120_000_000


def load_graph(spec: dict):
    """The centreline graph of a recipe's ``input`` (validated), and input info."""
    kind = spec.get("kind", "centreline")
    if kind == "centreline":
        from ..vessels.readers import read_centreline
        g = read_centreline(spec["path"], radius_array=spec.get("radius_array"))
        info = {"kind": kind, "path": str(spec["path"]), **g.info}
        if spec.get("points"):
            from ..vessels.skeleton import fit_to_boundary, read_point_cloud
            g.validate()  # the graph must make sense before it is fitted
            cloud = read_point_cloud(spec["points"])
            fit_to_boundary(g, cloud)
            g.boundary_points = cloud
            info.update(points=str(spec["points"]), fitted_nodes=g.info["fitted_nodes"],
                        boundary_points=g.info["boundary_points"])
        if spec.get("image"):
            from ..vessels.ct_segment import guide_by_image, load_volume
            g.validate()
            vol = load_volume(spec["image"])
            info.update(image=str(spec["image"]), **guide_by_image(g, vol, spec.get("frame", "auto")))
    elif kind == "image" and spec.get("seeds"):
        from ..vessels.ct_segment import guide_by_image, load_volume
        from ..vessels.seed_path import seed_centreline
        vol = load_volume(spec["path"])
        g, sinfo = seed_centreline(spec["seeds"], vol)
        g.validate()
        info = {"kind": kind, "path": str(spec["path"]), **sinfo, **guide_by_image(g, vol, "lps")}
    elif kind == "image":
        from ..vessels.skeleton import image_centreline
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
    from ..fields.blends import check_blend
    if isinstance(value, dict):
        b = dict(value)
    elif value is None:
        b = {"kind": "li", "n": 2, "delta": 0.2}
    else:
        parts = str(value).split(",")
        if len(parts) != 2:
            raise InputError(f"takes n,delta (e.g. 2,0.2), got {value!r}")
        try:
            b = {"kind": "li", "n": int(parts[0]), "delta": float(parts[1])}
        except ValueError:
            raise InputError(f"takes n,delta (e.g. 2,0.2), got {value!r}") from None
    kind = b.pop("kind", "li")
    check_blend(kind, **b)
    return {"kind": kind, **b}


def build_field(graph, voxel: float, blend: dict, wall=None, porous=None, trim=False, segment_length=None,
                segment_angle=45.0, workers=1, executor="thread", local=True, timings=None, boundary=None,
                progress=None, fit="rbf"):
    """Sample the vessel solid on a grid; return ``(values, grid, extras)`` (see :func:`run_vessel`).

    ``boundary``: boundary points (pooled), or a callable ``segments -> [cloud per segment]``.
    ``progress(stage, done, total)``: per segment of the field, the stage named with its up-front estimate
    (``field ~N s``, also ``extras["estimate_s"]``).
    """
    from ..mesh.polygonise import Grid
    from ..vessels.model import estimate_seconds, evaluate_grid
    from ..vessels.segments import march
    from ..vessels import walls as W
    timings = {} if timings is None else timings
    h = float(voxel)
    T = float(sum(wall)) if wall else 0.0
    delta = float(blend.get("delta", 0.0)) if blend["kind"] == "li" else 0.0
    pad = T + delta + 3.0 * h
    c = pad
    lo, hi = graph.bounds()
    lo, hi = lo - (T + 3 * h), hi + (T + 3 * h)
    grid = Grid.from_box(lo, hi, spacing=h)
    if grid.n_samples > MAX_SAMPLES:
        raise ResourceError(f"the grid would have {grid.n_samples:,} samples (limit {MAX_SAMPLES:,}); "
                            "use a larger voxel")
    t = time.perf_counter()
    segs = march(graph, length=segment_length, angle_deg=segment_angle, pad=pad)
    timings["march_s"] = time.perf_counter() - t
    if callable(boundary):  # one cloud per segment (the image's local segmentations)
        t = time.perf_counter()
        boundary = boundary(segs)
        timings["segmentation_s"] = time.perf_counter() - t
    t = time.perf_counter()
    stats = {}
    xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
    bl = {k: v for k, v in blend.items() if k != "kind"}
    est = estimate_seconds(segs, xs, ys, zs, boundary=boundary, local=local) / max(int(workers), 1)
    F = evaluate_grid(segs, graph, xs, ys, zs, c, {"kind": blend["kind"], **bl}, local=local,
                      workers=workers, executor=executor, stats=stats, boundary=boundary, fit=fit,
                      progress=stage_progress(progress, f"field ~{est:.0f} s"))
    timings["field_s"] = time.perf_counter() - t
    extras = {"segments": segs, "c": c, "lumen": F, "eval": stats, "estimate_s": est}
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


def porous_layer_connectivity(d, wall, layer, phi, spacing, trim_mask=None, min_voxels: int = 27) -> dict:
    """Connected components of the material of porous layer ``layer`` on the grid (26-connectivity).

    The layer's material is ``{d_{k-1} ≤ d̃ ≤ d_k} ∩ {φ ≤ 0}`` (within the trimmed solid).
    ``components`` counts pieces of at least ``min_voxels`` samples (3³: smaller
    ones are below the grid's resolution); ``components_all`` counts every piece;
    ``largest_fraction`` is the share of the layer's material in the largest.
    """
    from scipy import ndimage
    from ..vessels.walls import band
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




def _seeds(value):
    """``[[x, y, z], ...]`` (mm) → a list of 2 to 16 finite triples."""
    from ..vessels.seed_path import MAX_SEEDS
    if not isinstance(value, (list, tuple)) or not value or not isinstance(value[0], (list, tuple)):
        value = [value]
    try:
        S = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError("takes points [x, y, z] in mm") from None
    if S.ndim != 2 or S.shape[1] != 3 or not np.all(np.isfinite(S)):
        raise InputError("takes points [x, y, z] in mm (finite numbers)")
    if not 2 <= len(S) <= MAX_SEEDS:
        raise InputError(f"takes 2 to {MAX_SEEDS} points, got {len(S)}")
    return S.tolist()


@dataclasses.dataclass(frozen=True)
class VesselSpec:
    """A checked ``vessel`` recipe (see the module docstring for the keys)."""

    input: dict
    voxel: float
    blend: dict
    wall: tuple | None
    porous: dict | None
    trim: bool
    fit: str | None
    segment_length: float | None
    segment_angle: float
    workers: int
    executor: str
    evaluation: str

    @classmethod
    def from_recipe(cls, r):
        from ..vessels.walls import PERIODIC_003
        from .schema_key import REQUIRED
        i = r.table("input")
        kind = i.get("kind")
        inp = {"kind": kind, "path": i.get("path")}
        if kind == "centreline":
            if i.has("points"):
                inp["points"] = i.get("points", REQUIRED)
            if i.has("radius_array"):
                inp["radius_array"] = i.get("radius_array", REQUIRED)
            if i.has("image"):
                inp["image"] = i.get("image", REQUIRED)
                inp["frame"] = i.get("frame")
        else:
            if i.has("points"):
                raise i.error("points", "fits a centreline to a boundary cloud; it does not go with an image")
            inp["threshold"] = i.get("threshold")
            inp["smooth"] = i.get("smooth")
            if i.has("seeds"):
                inp["seeds"] = i.get("seeds", REQUIRED, check=_seeds)
        i.done()
        if not r.has("voxel"):
            raise r.error("voxel", "is required: the grid spacing in mm")
        voxel = r.get("voxel")
        blend = r.get("blend", check=parse_blend)
        wall = r.get("wall")
        p = r.table("porous")
        porous = None
        if p.data:
            if not wall:
                raise p.error("layer", "a porous layer needs a wall (layer thicknesses)")
            layer = p.get("layer", hi=len(wall))
            ptype = p.get("type")
            if ptype not in PERIODIC_003:
                from ..fields.tpms import get_type
                p.get("type", REQUIRED, check=lambda v: get_type(v).name)
            cell = p.get("cell_size")
            porous = {"layer": layer, "type": ptype, "cell_size": cell}
        p.done()
        trim = r.get("trim_ends", bool(wall))
        fit = r.get("fit")
        segment_length = r.get("segment_length")
        segment_angle = r.get("segment_angle")
        workers = r.get("workers")
        executor = r.get("executor")
        evaluation = r.get("evaluation")
        return cls(inp, voxel, blend, tuple(wall) if wall else None, porous, trim, fit, segment_length,
                   segment_angle, workers, executor, evaluation)

    def inputs(self) -> list:
        return [p for p in (self.input.get("path"), self.input.get("points")) if p]


def run(spec: VesselSpec, progress=None, options=None, graph=None) -> Result:
    """Build the vessel model of ``spec`` (nothing written); ``graph`` replaces the input (in-process use)."""
    from ..mesh.polygonise import polygonise
    from ..mesh.shells import drop_specks
    from ..mesh.validate import signed_volume
    from ..mesh.polygonise import GridArraySampler

    timer = Timer()
    wall = list(spec.wall) if spec.wall else None
    with timer("input"):
        stage = None if progress is None or graph is not None else (
            "centreline" if spec.input.get("kind") == "image" else "input")
        if stage:
            progress(stage, 0, 1)
        graph, info = load_graph({"kind": "graph", "graph": graph} if graph is not None else dict(spec.input))
        if stage:
            progress(stage, 1, 1)
    boundary = getattr(graph, "segment_clouds", None) or getattr(graph, "boundary_points", None)
    fit = spec.fit
    if fit in ("rbf", "ellipsoid") and boundary is None:
        raise InputError(f"an RBF fit (fit = {fit}) needs boundary points: give an image or a point cloud")
    if fit is None:
        fit = "rbf" if boundary is not None else "tube"
    info["fit"] = fit
    values, grid, ex = build_field(graph, spec.voxel, spec.blend, wall=wall, porous=spec.porous, trim=spec.trim,
                                   segment_length=spec.segment_length, segment_angle=spec.segment_angle,
                                   workers=spec.workers, executor=spec.executor,
                                   local=spec.evaluation == "local", timings=timer.timings,
                                   boundary=boundary if fit != "tube" else None, progress=progress,
                                   fit=fit)
    with timer("polygonise"):
        res = polygonise(GridArraySampler(values, grid), grid, caps=True, progress=stage_progress(progress, "mesh"))
    if len(res.faces) == 0:
        raise InputError("the vessel model is empty at this voxel size (radii smaller than the grid spacing?)")
    vertices, faces, shells = drop_specks(res.vertices, res.faces, 2.0 * float(np.prod(grid.spacing)))
    with timer("validate"):
        mesh_rep, chk, vertices = validated_report(vertices, faces, what="the vessel model")
    segs = ex["segments"]
    report = {"input": info, "blend": spec.blend, "voxel": spec.voxel,
              "grid": {"shape": list(grid.shape), "spacing": list(grid.spacing)},
              "branches": int(max(s.branch for s in segs) + 1), "segments": len(segs),
              "evaluation": spec.evaluation, "workers": spec.workers, "trim_ends": spec.trim,
              "evaluated_samples": ex["eval"].get("evaluated_samples"), "grid_samples": grid.n_samples,
              "rbf_segments": int(ex["eval"].get("rbf_segments", 0)), "field_estimate_s": ex["estimate_s"]}
    if getattr(graph, "segmentation_stats", None) is not None:
        report["segmentation"] = dict(graph.segmentation_stats)
    report.update(mesh_rep)
    report.update(shells)
    warnings = list(getattr(graph, "findings", None) or [])
    if wall and min(wall) < 3 * spec.voxel:
        warnings.append(Finding(
            "layer-thin", f"a wall layer of {min(wall):g} mm spans fewer than 3 voxels of {spec.voxel:g} mm: thin "
            "skins and pore walls may break up; use a voxel ≤ the thinnest layer / 3",
            {"layer": min(wall), "voxel": spec.voxel}))
    if wall:
        report["wall"] = {"thicknesses": wall, "total": float(sum(wall))}
        if spec.porous:
            report["porous"] = dict(spec.porous)
            report["porous"]["connectivity"] = porous_layer_connectivity(
                ex["distance"], wall, int(spec.porous["layer"]), ex["porous_values"][int(spec.porous["layer"])],
                grid.spacing, trim_mask=values <= 0)
    report["volume"] = float(signed_volume(vertices, faces))
    report["warnings"] = warnings
    report["timings"] = timer.total()
    # the analysis domain: the wall without its pores, or the solid lumen itself
    domain = (DeferredDomain(wall_domain, ex["distance"], wall, graph.ends() if spec.trim else None, grid)
              if spec.porous else (vertices, faces))
    return Result(report, vertices, faces, design=False, domain=domain, check=chk)


def wall_domain(distance, wall, ends, grid):
    """The closed surface of a vessel wall without its pores (the design domain of its porous layer).

    The band ``0 ≤ d̃ ≤ T`` of the approximate distance (003 Eqs. 4.13–4.16,
    :func:`porecad.vessels.walls.wall_field` without porous layers), trimmed
    at the open ends like the model, polygonised on the model's grid.
    """
    from ..mesh.polygonise import polygonise
    from ..vessels import walls as W
    from ..mesh.polygonise import GridArraySampler
    values = W.wall_field(distance, wall)
    if ends is not None:
        xs, ys, zs = grid.axis(0), grid.axis(1), grid.axis(2)
        values = W.trim_ends(values, xs, ys, zs, ends, float(sum(wall)))
    res = polygonise(GridArraySampler(values, grid), grid, caps=True)
    return res.vertices, res.faces.astype(np.int64)


JOB = Job("vessel", VesselSpec, run, summary=("branches", "segments", "volume", "solid_islands", "cavities"),
          title="implicit vessel models and porous grafts from centrelines or images (003)")
