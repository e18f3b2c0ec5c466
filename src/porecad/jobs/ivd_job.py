"""Patient-specific porous intervertebral discs from images (000 ch.6, §6.3).

Stages: read the subject (a challenge-layout folder of Dixon channels, or one
image; :mod:`porecad.imaging.challenge`) → segment the discs (classical
threshold/morphology/components, or the two-stage 3D U-Net of §6.2.4 from a
checkpoint) → per disc a closed body surface (marching cubes on the label,
Taubin smoothing; :func:`porecad.bodies.image.image_body`) → one closed
porous scaffold per disc with each requested design method that is present
(TPMS infill, TBSS, TIS, ARBF — the methods of 000 ch.2–5, all with the P
surface / P-like settings used in §6.3) → a report (JSON and a small HTML
table); with a label map in the folder, the segmentation is scored (Dice,
Hausdorff, HD95, mean surface distance; §6.2.6).

000 gives no IVD-specific design parameters ("automatically deployed at their
optimal values"); the defaults in :data:`METHOD_DEFAULTS` are chosen to give
a connected, closed scaffold on a disc of ~40 × 30 × 10 mm in seconds.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import time
from pathlib import Path

import numpy as np

from ..errors import InputError, OutputError, PorecadError, RecipeError
from ..version import __version__
from .contract import Job, Result
from ..recipes.keys import METHOD_DEFAULTS, METHODS  # declared with the recipe keys (the [params] tables)


def available_methods() -> list[str]:
    """The design methods whose job is registered (every one of :data:`METHODS` in this version)."""
    from .registry import module_name, names
    return [m for m in METHODS if m in names() and importlib.util.find_spec(module_name(m)) is not None]


def segment(stack, segmenter: str = "classical", checkpoint=None, log=None):
    """Instance labels (0, 1..n from the superior end) and info for a stack."""
    if segmenter == "classical":
        from ..imaging.classical import segment_discs
        return segment_discs(stack.channels, stack.geometry["spacing"])
    if segmenter == "unet":
        if checkpoint is None:
            raise RecipeError("input.checkpoint", "a U-Net segmenter needs a checkpoint file "
                                                  "(train one with `porecad seg train`)")
        from ..seg import require_torch
        require_torch()
        from ..seg.predict import predict_stack
        return predict_stack(stack, checkpoint, log=log)
    raise InputError(f"unknown segmenter {segmenter!r}; use classical or unet")


def method_recipes(method: str, body_path, mesh_path, params: dict | None = None) -> list[dict]:
    """The recipe(s) of one design method on a closed body mesh file (TBSS: fits tried in turn)."""
    p = {**METHOD_DEFAULTS[method], **(params or {})}
    out = {"mesh": str(mesh_path)}
    if method == "tpms":
        return [{"job": "infill",
                 "tpms": {"type": p["type"], "structure": p["structure"], "porosity": p["porosity"],
                          "cell_size": p["cell_size"]},
                 "domain": {"kind": "mesh", "path": str(body_path), "boundary": "cut"},
                 "sampling": {"voxel": p["voxel"]}, "output": out}]
    if method == "tbss":
        return [{"job": "tbss", "body": {"kind": "mesh", "path": str(body_path), "fit": fit, "control": ctrl},
                 "tpms": {"type": p["type"], "structure": p["structure"], "periods": list(p["periods"])},
                 "tdf": {"method": "layer", "by": "w", "grid": 40, "control": 10},
                 "mesh": {"resolution": p["resolution"]}, "output": out} for fit, ctrl in p["fits"]]
    if method == "tis":
        return [{"job": "tis", "domain": {"kind": "body", "path": str(body_path), "tets": p["tets"]},
                 "tis": {"type": p["type"], "lambda": p["lambda"], "relative": p["relative"], "structure": "pore"},
                 "mesh": {"resolution": p["resolution"], "method": "lattice", "smooth": 0}, "output": out}]
    if method == "arbf":
        return [{"job": "arbf", "domain": {"kind": "body", "path": str(body_path), "tets": p["tets"]},
                 "arbf": {"basis": p["basis"], "shape": p["shape"], "iso": p["iso"], "local": True,
                          "ring": p["ring"]},
                 "mesh": {"resolution": p["resolution"]}, "output": out}]
    raise InputError(f"unknown method {method!r}; use {', '.join(METHODS)}")


def _scaffold(method, body_path, mesh_path, force, params=None, report_dir=None, memory_limit=None) -> dict:
    """Run one method on one disc; the first recipe variant that succeeds wins (TBSS fits).

    ``report_dir``: also write that scaffold's report directory (the full
    analysis, measured inside the disc's design domain: the disc body for
    TPMS, ARBF and TIS, the fitted TBSS solid for TBSS).
    """
    from . import run_recipe
    recipes = method_recipes(method, body_path, mesh_path, params)
    if report_dir is not None:
        for r in recipes:
            r["output"]["report"] = str(report_dir)
    errors = []
    t = time.perf_counter()
    for recipe in recipes:
        try:
            rep = run_recipe(recipe, force=force, threads=1, memory_limit=memory_limit)
        except PorecadError as exc:
            errors.append(str(exc).splitlines()[0])
            continue
        keep = ("porosity", "volume", "surface_area", "triangles", "closed", "manifold", "oriented",
                "threshold", "tets", "warnings", "mesh_file", "report_dir")
        res = {k: rep[k] for k in keep if k in rep}
        res["time_s"] = time.perf_counter() - t
        if method == "tbss":
            res["fit"] = recipe["body"]["fit"]
            res["control"] = recipe["body"]["control"]
        if errors:
            res["retries"] = errors
        return res
    raise PorecadError(f"{method}: {errors[-1]}")


def report_dir_name(disc: int, method: str) -> str:
    """The report directory of one disc's scaffold (``reports = true``)."""
    return f"disc_{disc:02d}_{method}_report"


def run_ivd(image_path, out_dir, segmenter: str = "classical", methods=("tpms",), checkpoint=None,
            channels=None, discs=None, force: bool = False, smooth_iterations: int = 10, params=None,
            log=None, reports: bool = False, memory_limit: int | None = None) -> dict:
    """Segment a subject and build one porous scaffold per disc and method.

    Parameters
    ----------
    image_path : path
        Subject folder (challenge layout), image file or DICOM series folder.
    out_dir : path
        Output folder (created); holds ``segmentation.nii.gz``,
        ``disc_NN_body.stl``, ``disc_NN_<method>.stl``, ``ivd_report.json``
        and ``ivd_report.html``.
    segmenter : {"classical", "unet"}
    methods : sequence of str
        Design methods; ones not installed are skipped (listed in the report).
    checkpoint : path, optional
        U-Net checkpoint (``segmenter="unet"``).
    discs : list of int, optional
        Only these disc numbers (1 = most superior).
    params : dict, optional
        Method → parameter overrides (see :data:`METHOD_DEFAULTS`).
    log : callable, optional
        Called with progress lines.
    reports : bool
        Also write a report directory per scaffold (``disc_NN_<method>_report``:
        HTML, plots and the analysis measured inside that disc's domain).
    memory_limit : int, optional
        Bytes each scaffold may use (its estimate is refused past it; default: 80 % of the available memory).

    Returns
    -------
    dict
        The report. Raises :class:`PorecadError` after writing the report when
        a scaffold failed.
    """
    from ..imaging.challenge import find_subjects, load_subject
    from ..imaging.io import write_volume
    from ..imaging.metrics import evaluate_labels

    log = log or (lambda msg: None)
    t0 = time.perf_counter()
    methods, skipped = _installed(methods)
    subjects = find_subjects(image_path)
    if len(subjects) > 1:
        raise InputError(f"{image_path}: holds {len(subjects)} subjects; give one subject folder")
    out = Path(out_dir)
    _check_outputs(out, force, reports)
    stack, subject = load_subject(subjects[0], channels)
    log(f"read {subject}: channels {', '.join(stack.names)}, {'x'.join(map(str, stack.shape))} voxels")
    labels, seg_info, t_seg, chosen = _segmented(stack, segmenter, checkpoint, image_path, discs, log)
    n = int(labels.max())
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {out}: {exc.strerror}") from None
    seg_path = write_volume(out / "segmentation.nii.gz", labels.astype(np.uint8), stack.geometry, force=True)
    report = {"job": "ivd", "porecad_version": __version__, "subject": subject, "input": str(image_path),
              "channels": stack.names, "shape": list(stack.shape), "geometry": stack.geometry,
              "segmenter": segmenter, "segmentation": {**{k: v for k, v in seg_info.items() if k != "score_image"},
                                                        "file": str(seg_path), "time_s": t_seg},
              "methods": methods, "skipped_methods": skipped,
              "parameters": {m: {**METHOD_DEFAULTS[m], **((params or {}).get(m, {}))} for m in methods},
              "discs": []}
    if stack.labels is not None:
        report["metrics"] = evaluate_labels(stack.labels, labels, np.asarray(stack.geometry["spacing"], float))
        log(f"segmentation vs labels: Dice {report['metrics']['all']['dice']:.3f}")
    failures = []
    for d in chosen:
        report["discs"].append(_disc(d, n, labels, stack.geometry, seg_path, out, methods, params, smooth_iterations,
                                     reports, failures, log, memory_limit))
    report["failures"] = failures
    report["time_s"] = time.perf_counter() - t0
    report["report_file"] = str(out / "ivd_report.json")
    _write_report(out, report)
    if failures:
        raise PorecadError(f"{len(failures)} scaffold(s) failed ({failures[0]}); see {out / 'ivd_report.json'}")
    return report


def _segmented(stack, segmenter, checkpoint, image_path, discs, log):
    """Segment the discs: ``(labels, info, seconds, the disc numbers to build)``; no disc, or an unknown one, refused."""
    t = time.perf_counter()
    labels, seg_info = segment(stack, segmenter, checkpoint, log=log)
    t_seg = time.perf_counter() - t
    n = int(labels.max())
    if n == 0:
        raise InputError(f"{segmenter} segmentation found no disc in {image_path}")
    log(f"segmented {n} discs ({segmenter}, {t_seg:.1f} s)")
    chosen = list(range(1, n + 1)) if not discs else sorted({int(d) for d in discs})
    bad = [d for d in chosen if not 1 <= d <= n]
    if bad:
        raise RecipeError("discs", f"disc {bad[0]}: the segmentation has discs 1..{n}")
    return labels, seg_info, t_seg, chosen


def _installed(methods) -> tuple[list, list]:
    """``(methods to run, methods skipped as not installed)``; an unknown method or none installed is refused."""
    methods = list(dict.fromkeys(methods))
    for m in methods:
        if m not in METHODS:
            raise InputError(f"unknown method {m!r}; use {', '.join(METHODS)}")
    have = available_methods()
    skipped = [m for m in methods if m not in have]
    methods = [m for m in methods if m in have]
    if not methods:
        raise InputError(f"none of the requested methods is installed (skipped: {', '.join(skipped)})")
    return methods, skipped


def _check_outputs(out: Path, force: bool, reports: bool) -> None:
    """Refuse an output folder that would be overwritten without ``force`` (before any work)."""
    from ..io.atomic import check_output_dir
    check_output_dir(out)
    if out.exists() and not force:
        clash = [p for p in [out / "ivd_report.json", out / "segmentation.nii.gz"] + sorted(out.glob("disc_*.stl"))
                 + (sorted(out.glob("disc_*_report")) if reports else []) if p.exists()]
        if clash:
            raise OutputError(f"{clash[0]}: already exists (`force` overwrites it)")


def _disc(d, n, labels, geometry, seg_path, out: Path, methods, params, smooth_iterations, reports, failures,
          log, memory_limit=None) -> dict:
    """Disc ``d``: its body mesh from the segmentation, then a scaffold per method; the disc's report entry.

    A failed method is recorded in the entry and appended to ``failures``; the others still run.
    """
    from ..bodies.image import image_body, index_to_physical
    from ..io import write_mesh
    from ..mesh.validate import signed_volume
    mask = labels == d
    centre = index_to_physical(np.argwhere(mask).mean(axis=0)[None], geometry)[0]
    entry = {"disc": d, "voxels": int(mask.sum()),
             "voxel_volume_mm3": float(mask.sum() * np.prod(np.asarray(geometry["spacing"], float))),
             "centre_mm": centre.tolist(), "scaffolds": {}}
    v, f, binfo = image_body(seg_path, label=d, smooth_iterations=smooth_iterations)
    body_path = write_mesh(out / f"disc_{d:02d}_body.stl", v, f, force=True)
    entry["body"] = {"file": str(body_path), "triangles": int(len(f)), "volume_mm3": float(signed_volume(v, f)),
                     "extent_mm": (v.max(axis=0) - v.min(axis=0)).tolist()}
    for m in methods:
        log(f"disc {d}/{n}: {m} …")
        try:
            res = _scaffold(m, body_path, out / f"disc_{d:02d}_{m}.stl", True, (params or {}).get(m),
                            report_dir=out / report_dir_name(d, m) if reports else None, memory_limit=memory_limit)
        except PorecadError as exc:
            failures.append(f"disc {d} {m}: {str(exc).splitlines()[0]}")
            entry["scaffolds"][m] = {"error": str(exc).splitlines()[0]}
            log(f"disc {d}/{n}: {m} failed: {exc}")
            continue
        entry["scaffolds"][m] = res
        log(f"disc {d}/{n}: {m} porosity {res.get('porosity', float('nan')):.3f}, "
            f"{res.get('triangles')} triangles, {res['time_s']:.1f} s")
    return entry


def _write_report(out: Path, report: dict) -> None:
    """``ivd_report.json`` and ``ivd_report.html``, each written atomically."""
    from ..io.atomic import atomic_write
    from ..io.jsonable import json_default
    with atomic_write(out / "ivd_report.json", force=True) as fh:
        fh.write((json.dumps(report, indent=1, default=json_default) + "\n").encode())
    with atomic_write(out / "ivd_report.html", force=True) as fh:
        fh.write(html_report(report).encode())


def html_report(report: dict) -> str:
    """A one-page HTML summary of an ivd report (template ``porecad/pages/templates/ivd.html``)."""
    from ..pages import render
    rows = []
    for d in report["discs"]:
        for m, s in d["scaffolds"].items():
            mesh = Path(s.get("mesh_file", "")).name
            rows.append({"disc": d["disc"], "method": m, "error": s.get("error"), "mesh": mesh,
                         "volume": d["body"]["volume_mm3"], "porosity": s.get("porosity", float("nan")),
                         "triangles": s.get("triangles"), "closed": s.get("closed"), "manifold": s.get("manifold"),
                         "report": f"{Path(s['report_dir']).name}/report.html" if s.get("report_dir") else None})
    metrics = report["metrics"]["all"] if "metrics" in report else None
    return render("ivd.html", title="porecad ivd report", report=report, rows=rows, metrics=metrics)


@dataclasses.dataclass(frozen=True)
class IvdSpec:
    """A checked ``ivd`` recipe.

    Recipe::

        job = "ivd"
        [input]   path = "spine/" (subject folder, image or DICOM series), channels = ["opp", "wat", "fat"],
                  segmenter = "classical" | "unet", checkpoint = "ivd.pt"
        methods = ["tpms", "tis"]        # or ["all"]
        discs = [1, 2]                   # default: every disc found
        smooth_iterations = 10           # Taubin smoothing of each disc surface
        reports = false                  # a report directory per scaffold (analysis in the disc's domain)
        [params.tpms] porosity = 0.6 ... # overrides of METHOD_DEFAULTS
        [output]  dir = "discs/", recipe = "ivd.toml"
    """

    path: str
    segmenter: str
    checkpoint: str | None
    channels: tuple | None
    methods: tuple
    discs: tuple | None
    smooth_iterations: int
    params: dict
    reports: bool = False

    @classmethod
    def from_recipe(cls, r):
        i = r.table("input")
        path = i.get("path")
        segmenter = i.get("segmenter")
        checkpoint = i.get("checkpoint")
        if segmenter == "unet" and checkpoint is None:
            raise i.error("checkpoint", "a U-Net segmenter needs a checkpoint file (train one with `porecad seg "
                                        "train`)")
        channels = i.get("channels")
        if channels is not None:
            if not isinstance(channels, list) or not 1 <= len(channels) <= 16 or \
                    not all(isinstance(c, str) and 0 < len(c) <= 32 for c in channels):
                raise i.error("channels", "takes a list of 1 to 16 channel names")
            channels = tuple(channels)
        i.done()
        methods = r.get("methods")
        if not isinstance(methods, list) or not methods or any(m not in METHODS + ("all",) for m in methods):
            raise r.error("methods", f"takes a list of {', '.join(METHODS)} or all")
        methods = tuple(METHODS) if "all" in methods else tuple(dict.fromkeys(methods))
        discs = r.get("discs")
        smooth = r.get("smooth_iterations")
        reports = r.get("reports")
        p = r.table("params")
        params = {}
        for m in METHODS:
            if p.has(m):
                params[m] = _method_params(p.table(m), m)
                _check_method_recipes(m, path, params[m])
        p.done()
        return cls(path, segmenter, checkpoint, channels, methods, tuple(discs) if discs else None, smooth, params,
                   reports)

    def inputs(self) -> list:
        return [p for p in (self.path, self.checkpoint) if p]


def _method_params(t, method) -> dict:
    """Overrides of one method's design parameters (same keys and types as :data:`METHOD_DEFAULTS`)."""
    out = {}
    for k in METHOD_DEFAULTS[method]:
        if not t.has(k):
            continue
        out[k] = t.get(k)  # typed and bounded like the default (porecad.recipes.keys)
        if isinstance(METHOD_DEFAULTS[method][k], list):
            if not isinstance(out[k], list) or len(out[k]) > 16:
                raise t.error(k, "takes a list like the default")
    t.done()
    return out


def _check_method_recipes(method: str, image_path, params: dict) -> None:
    """Check the recipes one method's overrides make with that job's own spec (every value and list shape).

    The disc bodies do not exist yet: the image stands in for them (only
    its existence is checked here). An error names ``params.<method>``.
    """
    from .runner import parse
    try:
        for recipe in method_recipes(method, image_path, "disc.stl", params):
            parse({k: v for k, v in recipe.items() if k != "output"})
    except RecipeError as exc:
        raise RecipeError(f"params.{method}", f"{exc.key}: {exc.detail}") from None
    except InputError as exc:
        raise RecipeError(f"params.{method}", str(exc)) from None
    except (TypeError, ValueError, IndexError, KeyError) as exc:
        raise RecipeError(f"params.{method}", f"a value has the wrong shape ({type(exc).__name__})") from None


def run(spec: IvdSpec, progress=None, options=None) -> Result:
    """Segment, and build every disc's scaffolds into ``options.outputs["dir"]`` (written here: many files)."""
    out = (options.outputs if options else {}).get("dir")
    if not out:
        raise RecipeError("output.dir", "is required: the folder the discs, scaffolds and report are written to")
    log = getattr(progress, "log", None)  # a progress object may also take log lines
    report = run_ivd(spec.path, out, segmenter=spec.segmenter, methods=spec.methods, checkpoint=spec.checkpoint,
                     channels=list(spec.channels) if spec.channels else None,
                     discs=list(spec.discs) if spec.discs else None, force=bool(options and options.force),
                     smooth_iterations=spec.smooth_iterations, params=spec.params, log=log, reports=spec.reports,
                     memory_limit=getattr(options, "memory_limit", None))
    return Result(report, mesh_written=True)


JOB = Job("ivd", IvdSpec, run, outputs=("dir", "recipe"), dir_outputs=("dir",), summary=("subject", "segmenter", "report_file"),
          title="patient-specific porous discs from spine images (000 ch.6)")
