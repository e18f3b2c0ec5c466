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
             seeds = [[x, y, z], ...] (image: the vessel between the seeds, mm, LPS),
             seeds_file = "seeds.mrk.json" (image: the seeds from a 3D Slicer markups file, its own frame)
    frame_out = "lps" | "ras"         # the outputs' frame (default: the input's; the report states it)
    voxel = 0.1                       # grid spacing, mm
    blend = "2,0.2" | {kind = "li" | "sharp" | "softmax" | "rfunc", n, delta, k, alpha}
    wall = [0.1, 0.3, 0.2]            # layer thicknesses from the lumen out (none: a solid lumen)
    porous = {layer = 2, type = "G", cell_size = 0.6}
    trim_ends = true, fit = "rbf" | "ellipsoid" | "tube", segment_length, segment_angle = 45,
    evaluation = "local" | "global", workers = 1, executor = "thread" | "process"
    [output] mesh, report, recipe, centreline (.vtp with MaximumInscribedSphereRadius and SPACE),
             labelmap (.nrrd / .seg.nrrd on the image's grid)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from ..findings import Finding
from ..fields.blends import Blend
from ..vessels.field_grid import build_field, labelmap, porous_layer_connectivity, wall_domain
from ..vessels.walls import PERIODIC_003, PorousLayer
from .contract import DeferredDomain, Job, Result, RunOptions, Validation, stage_progress



@dataclasses.dataclass(frozen=True)
class VesselInput:
    """A checked ``[input]`` table: a centreline file or an image (see the module docstring for the keys)."""

    kind: str                        # centreline or image
    path: str
    points: str | None = None        # centreline: boundary points to fit it to
    radius_array: str | None = None  # centreline (.vtp): the radius array
    image: str | None = None         # centreline: segment this image along it
    frame: str | None = None         # centreline: lps, ras or auto
    threshold: float | None = None   # image: foreground threshold (None: halfway)
    smooth: float | None = None      # image: its smoothing
    seeds: list | str | None = None  # image: the seeds [[x, y, z], ...] (mm, LPS) or a markups file


def load_graph(inp: VesselInput, graph=None):
    """The centreline graph of a recipe's ``input`` (validated), and input info; ``graph``: that graph instead
    (in-process use: tests, benchmarks).

    ``info["frame"]``: the frame of the input's coordinates (``lps``, ``ras``, or None when a centreline file
    does not say); the graph itself is in the image's LPS frame whenever an image is read.
    """
    if graph is not None:
        g, info = graph, {"kind": "graph", "frame": None}
    elif inp.kind == "centreline":
        from ..vessels.readers import read_centreline
        g = read_centreline(inp.path, radius_array=inp.radius_array)
        info = {"kind": inp.kind, "path": str(inp.path), **g.info}
        given = inp.frame if inp.frame not in (None, "auto") else g.info.get("frame")
        info["frame"] = given
        if g.info.get("radii_given") is False and not inp.image:
            raise InputError(f"{inp.path}: a markups curve has no radii; give the `image` they come from")
        if inp.points:
            from ..vessels.skeleton import fit_to_boundary, read_point_cloud
            g.validate()  # the graph must make sense before it is fitted
            cloud = read_point_cloud(inp.points)
            fit_to_boundary(g, cloud)
            g.boundary_points = cloud
            info.update(points=str(inp.points), fitted_nodes=g.info["fitted_nodes"],
                        boundary_points=g.info["boundary_points"])
        if inp.image:
            from ..vessels.ct_segment import guide_by_image, load_volume
            g.validate()
            vol = load_volume(inp.image)
            info.update(image=str(inp.image), **guide_by_image(g, vol, given or "auto"))
            g.volume = vol
    elif inp.kind == "image" and inp.seeds:
        g, info = _seed_graph(inp)
    elif inp.kind == "image":
        from ..vessels.skeleton import image_centreline
        g, info = image_centreline(inp.path, threshold=inp.threshold, smooth=inp.smooth)
        info = {"kind": inp.kind, "path": str(inp.path), **info, "frame": "lps"}
    else:
        raise InputError(f"unknown vessel input {inp.kind!r}")
    g.validate()
    info.update(nodes=int(g.n_nodes), edges=int(len(g.edges)),
                radius_min=float(g.radii.min()), radius_max=float(g.radii.max()))
    return g, info


def _seed_graph(inp: VesselInput):
    """The centreline between the seeds (numbers in the image's LPS frame, or a 3D Slicer markups file), segmented
    in the image, with ``path-not-tube`` findings where the path leaves the tube."""
    from ..vessels.ct_segment import guide_by_image, load_volume
    from ..vessels.seed_path import seed_centreline
    from ..vessels.tube_path import not_tube_findings
    seeds, frame = inp.seeds, "lps"
    if isinstance(seeds, str):
        from ..io.slicer import read_markups
        marks, frame = read_markups(seeds)
        seeds = np.concatenate([P for _kind, P in marks])
    seeds = np.asarray(seeds, float).reshape(-1, 3)
    if frame == "ras":
        seeds = seeds * [-1.0, -1.0, 1.0]
    vol = load_volume(inp.path)
    g, sinfo = seed_centreline(seeds, vol)
    g.validate()
    tm = g.tube_map
    info = {"kind": "image", "path": str(inp.path), **sinfo, **guide_by_image(g, vol, "lps"), "frame": frame}
    flip = (lambda P: P * [-1.0, -1.0, 1.0]) if frame == "ras" else None  # noqa: E731
    g.findings = list(getattr(g, "findings", None) or []) + not_tube_findings(
        g, tm.tubeness(g.points), to_frame=flip, frame=frame.upper())
    g.volume = vol
    return g, info


def parse_blend(value):
    """``"n,delta"`` (Li's union) or a table → the checked :class:`~porecad.fields.blends.Blend`."""
    if isinstance(value, dict):
        return Blend(**{"kind": "li", **value})
    parts = str(value).split(",")
    if len(parts) != 2:
        raise InputError(f"takes n,delta (e.g. 2,0.2), got {value!r}")
    try:
        n, delta = int(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"takes n,delta (e.g. 2,0.2), got {value!r}") from None
    return Blend("li", n, delta)


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

    input: VesselInput
    voxel: float
    blend: Blend
    wall: tuple | None
    porous: PorousLayer | None
    trim: bool
    fit: str | None
    segment_length: float | None
    segment_angle: float
    workers: int
    executor: str
    evaluation: str
    frame_out: str | None = None

    @classmethod
    def from_recipe(cls, r):
        from ..recipes.key import REQUIRED
        i = r.table("input")
        kind = i.get("kind")
        path = i.get("path")
        if kind == "centreline":
            inp = VesselInput(kind, path, points=i.get("points"), radius_array=i.get("radius_array"),
                              image=i.get("image"), frame=i.get("frame"))
        else:
            if i.has("points"):
                raise i.error("points", "fits a centreline to a boundary cloud; it does not go with an image")
            if i.has("seeds") and i.has("seeds_file"):
                raise i.error("seeds_file", "gives the seeds from a markups file; give `seeds` or it, not both")
            seeds = i.get("seeds", check=_seeds) if i.has("seeds") else None
            if i.has("seeds_file"):
                seeds = str(i.get("seeds_file", REQUIRED))
            inp = VesselInput(kind, path, threshold=i.get("threshold"), smooth=i.get("smooth"), seeds=seeds)
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
            if ptype not in PERIODIC_003:  # a TPMS type (the declared default G when not given)
                from ..fields.tpms import get_type
                ptype = p.get("type", check=lambda v: get_type(v).name)
            cell = p.get("cell_size")
            porous = PorousLayer(layer, ptype, cell)
        p.done()
        trim = r.get("trim_ends", bool(wall))
        fit = r.get("fit")
        segment_length = r.get("segment_length")
        segment_angle = r.get("segment_angle")
        workers = r.get("workers")
        executor = r.get("executor")
        evaluation = r.get("evaluation")
        return cls(inp, voxel, blend, tuple(wall) if wall else None, porous, trim, fit, segment_length,
                   segment_angle, workers, executor, evaluation, r.get("frame_out"))

    def inputs(self) -> list:
        i = self.input
        return [p for p in (i.path, i.points, i.image, i.seeds if isinstance(i.seeds, str) else None) if p]


def run(spec: VesselSpec, progress=None, options=None, graph=None) -> Result:
    """Build the vessel model of ``spec`` (nothing written); ``graph`` replaces the input (in-process use)."""
    from ..mesh.polygonise import polygonise
    from ..mesh.shells import drop_specks
    from ..mesh.polygonise import GridArraySampler

    timer = (options or RunOptions()).stages  # the runner's stage clock: it reports the timings
    wall = list(spec.wall) if spec.wall else None
    if (getattr(options, "outputs", None) or {}).get("labelmap") and not (
            spec.input.kind == "image" or spec.input.image):
        _no_labelmap(None, False)
    with timer("input"):
        stage = None if progress is None or graph is not None else (
            "centreline" if spec.input.kind == "image" else "input")
        if stage:
            progress(stage, 0, 1)
        graph, info = load_graph(spec.input, graph)
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
                                   fit=fit, memory_limit=getattr(options, "memory_limit", None))
    with timer("polygonise"):
        res = polygonise(GridArraySampler(values, grid), grid, caps=True, progress=stage_progress(progress, "mesh"))
    if len(res.faces) == 0:
        raise InputError("the vessel model is empty at this voxel size (radii smaller than the grid spacing?)")
    vertices, faces, shells = drop_specks(res.vertices, res.faces, 2.0 * float(np.prod(grid.spacing)))
    segs = ex["segments"]
    report = {"input": info, "blend": spec.blend.keywords(), "voxel": spec.voxel,
              "grid": {"shape": list(grid.shape), "spacing": list(grid.spacing)},
              "branches": int(max(s.branch for s in segs) + 1), "segments": len(segs),
              "evaluation": spec.evaluation, "workers": spec.workers, "trim_ends": spec.trim,
              "evaluated_samples": ex["eval"].get("evaluated_samples"), "grid_samples": grid.n_samples,
              "rbf_segments": int(ex["eval"].get("rbf_segments", 0)), "field_estimate_s": ex["estimate_s"]}
    if getattr(graph, "segmentation_stats", None) is not None:
        report["segmentation"] = dict(graph.segmentation_stats)
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
            report["porous"] = dataclasses.asdict(spec.porous)
            report["porous"]["connectivity"] = porous_layer_connectivity(
                ex["distance"], wall, spec.porous.layer, ex["porous_values"][spec.porous.layer],
                grid.spacing, trim_mask=values <= 0)
    report["warnings"] = warnings
    flip = _output_frame(report, info, spec.frame_out, getattr(graph, "volume", None) is not None)
    vertices = vertices * flip
    # the analysis domain: the wall without its pores, or the solid lumen itself
    domain = (DeferredDomain(wall_domain, ex["distance"], wall, graph.ends() if spec.trim else None, grid, flip)
              if spec.porous else (vertices, faces))
    extra = extra_outputs(graph, values, grid, flip, report["frame"])
    return Result(report, vertices, faces, design=False, domain=domain, extra_outputs=extra,
                  validation=Validation("the vessel model"))


def _output_frame(report, info, frame_out, in_lps: bool) -> np.ndarray:
    """State the output's frame in the report; the factors that take the model's points there (x, y negated
    from LPS to RAS). The model is built in the image's LPS frame when an image was read, else in the input's."""
    given = info.get("frame")
    out = frame_out or given
    built = "lps" if in_lps else given
    if out and not built:
        raise InputError(f"frame_out = {out}: the centreline file does not say its frame; give `frame` (lps or ras)")
    report["frame"] = out.upper() if out else "as-input"
    return np.array([-1.0, -1.0, 1.0]) if out and out != built else np.ones(3)


def extra_outputs(graph, values, grid, flip, frame: str) -> dict:
    """Writers of the model's centreline (VTP) and, with an image, its labelmap on the image's grid (NRRD)."""
    from ..io.slicer import write_centreline_vtp, write_labelmap_nrrd
    out = {"centreline": lambda path, force: write_centreline_vtp(
        path, graph.branches(), graph.points * flip, graph.radii, frame if frame != "as-input" else None, force)}
    vol = getattr(graph, "volume", None)
    if vol is not None:
        out["labelmap"] = lambda path, force: write_labelmap_nrrd(
            path, labelmap(values, grid, vol), vol.h, vol.origin, vol.D, force)
    return out


def _no_labelmap(path, force):
    raise InputError("a labelmap lies on an image's grid: give the `image` (output.labelmap needs one)")


JOB = Job("vessel", VesselSpec, run, summary=("branches", "segments", "volume", "solid_islands", "cavities"),
          outputs=("mesh", "report", "recipe", "centreline", "labelmap"),
          title="implicit vessel models and porous grafts from centrelines or images (003)")
