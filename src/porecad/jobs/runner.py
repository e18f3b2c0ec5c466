"""Run any job from its recipe, the same way for every job.

:func:`execute` is the one path from a recipe to files: read the recipe's
``job``, ``format`` and the job's tables into its typed spec (every error
names the recipe key; unknown keys are refused), check every output before
any work (no overwrite without ``force``, no two outputs on one file, no
output on an input, a writable directory), run the job, give its report the
common keys, and write the mesh, the extra outputs, the recipe and the
report atomically.
"""

from __future__ import annotations

import copy
import dataclasses
import os
from pathlib import Path

from ..errors import InputError, RecipeError
from ..io.recipe import FORMAT_VERSION, save_recipe
from ..version import __version__
from .contract import Result, RunOptions, Timer
from .outputs import validated_report, write_report_output
from ..recipes.table import Table

#: keys every job's report has (None where a job has no value, e.g. the porosity of a solid vessel)
COMMON_KEYS = ("job", "porecad_version", "recipe_format", "triangles", "vertices", "closed", "manifold",
               "oriented", "volume", "surface_area", "domain_volume", "porosity", "porosity_error", "pieces",
               "islands_dropped", "islands_volume_fraction", "coverage", "warnings", "warning_details", "timings")


def parse(recipe: dict, base=None, confine=None):
    """The job and its spec of a recipe (all checks; nothing run). Returns ``(job, spec, outputs, root)``.

    ``confine``: ``(folder, trusted)`` for a recipe read from a file: its
    outputs must lie inside ``folder`` and its workers are at most the
    cores (values in ``trusted``, output paths or a scheduler, were typed on
    the command line: the user's, not the recipe's).
    """
    from . import registry
    if not isinstance(recipe, dict):
        raise InputError(f"a recipe is a table (dict), got {type(recipe).__name__}")
    from ..recipes.keys import ROOT
    from ..recipes.schema import job_keys
    root = Table(recipe, "", Path(base) if base is not None else Path.cwd(), confine=confine, schema=ROOT)
    fmt = root.get("format")
    if fmt > FORMAT_VERSION:
        raise RecipeError("format", f"this recipe has format {fmt}, newer than this porecad ({__version__}) "
                                    f"reads (≤ {FORMAT_VERSION}); update porecad")
    root.get("porecad_version")
    name = root.get("job")
    if name is None:
        raise RecipeError("job", f"is required; one of {', '.join(registry.names())}")
    job = registry.get(name)
    root.schema = job_keys(name)
    try:
        spec = job.spec.from_recipe(root)
    except InputError:
        raise
    except (TypeError, ValueError, IndexError, KeyError, OverflowError) as exc:
        # a value of the wrong shape that a check upstream let through: still the recipe's fault, one line
        raise RecipeError(name, f"a value of the recipe has the wrong type or shape ({type(exc).__name__}: "
                                f"{' '.join(str(exc).split())[:120]})") from None
    from .promise import Promise
    root.promise = Promise.from_recipe(root)
    out = root.table("output")
    outputs = {k: out.get(k) for k in job.outputs}
    out.done()
    root.done()
    return job, spec, {k: v for k, v in outputs.items() if v}, root


def check_outputs(outputs: dict, inputs, force: bool, source=None, dirs=()) -> None:
    """Refuse bad outputs before any work: clobbering, two outputs on one file, an output on an input."""
    from ..analysis.report import check_report_dir, is_report_dir
    from ..io import check_output_path
    seen = {}
    ins = {os.path.realpath(p) for p in inputs if p}
    if source is not None:
        ins.add(os.path.realpath(source))
    for key, path in outputs.items():
        real = os.path.realpath(path)
        if real in seen:
            raise RecipeError(f"output.{key}", f"{path} is also output.{seen[real]}: give two different files")
        if real in ins:
            raise RecipeError(f"output.{key}", f"{path} is an input of this job: refusing to overwrite it")
        seen[real] = key
        if key in dirs:
            if os.path.exists(path) and not os.path.isdir(path):
                raise RecipeError(f"output.{key}", f"{path}: is a file, not a directory")
            continue
        if key == "report_dir" and not is_report_dir(path):
            raise RecipeError("output.report_dir", f"{path} is a folder for the HTML report; "
                              "give a name not ending in .json (output.report takes a JSON file)")
        if key in ("report", "report_dir") and is_report_dir(path):
            check_report_dir(path, force=force, design=True)
            continue
        check_output_path(path, force=force)


def common_report(report: dict, job_name: str, fmt: int) -> dict:
    """``report`` with the :data:`COMMON_KEYS` first (missing ones None).

    The job's ``warnings`` (:class:`~porecad.findings.Finding` or text)
    become ``warnings`` (sentences) and ``warning_details`` (code, message, values).
    """
    from ..findings import report_fields
    out = {"job": job_name, "porecad_version": __version__, "recipe_format": fmt}
    for k in COMMON_KEYS[3:]:
        out[k] = report.get(k)
    out.update(report_fields(report.get("warning_details") or report.get("warnings")))
    for k, v in report.items():
        if k not in out:
            out[k] = v
    return out


def execute(recipe: dict, base=None, progress=None, options: RunOptions | None = None, source=None,
            confine=None) -> dict:
    """Run a recipe and write its outputs; return the report.

    Parameters
    ----------
    recipe : dict
        The recipe (a TOML document as a dict).
    base : path, optional
        Directory relative input and output paths are resolved against (the
        recipe file's directory; default: the current directory).
    progress : callable, optional
        ``progress(stage, done, total)``.
    options : RunOptions, optional
        Threads, self-intersection check, memory limit, force.
    source : path, optional
        The recipe file being run (never overwritten; reported as ``recipe_file``).
    confine : (path, set), optional
        Outputs only inside this folder (see :func:`parse`).

    The outputs are one set (:func:`porecad.io.atomic.output_set`): they
    appear together when the job and every write succeed, else none does.
    A job that writes a folder of its own (``ivd``, which reads back what it
    wrote) writes each file atomically as it goes.
    """
    import contextlib

    from ..io.atomic import output_set
    from .promise import keep_promise
    options = options or RunOptions()
    job, spec, outputs, root = parse(recipe, base, confine)
    check_outputs(outputs, spec.inputs(), options.force, source, job.dir_outputs)
    islands = root.promise.islands or getattr(spec, "islands", None) or "drop"
    options = dataclasses.replace(options, outputs=outputs, islands=islands)
    with contextlib.nullcontext() if job.dir_outputs else output_set():
        result = run_job(job, spec, progress, options)
        keep_promise(result, spec, root.promise)
        report = common_report(result.report, job.name, FORMAT_VERSION)
        write_outputs(result, report, outputs, recipe, root, options.force, source)
    return report


def run_job(job, spec, progress=None, options: RunOptions | None = None) -> Result:
    """Run ``job`` on ``spec`` with a fresh stage clock and check its solid (nothing is written).

    The solid is checked as its :class:`~porecad.jobs.contract.Validation` asks
    (closed, manifold, outward, and free of self-intersections where asked; else
    nothing is written); its figures join the report, then the job's own
    ``derive``; the report gets the stage ``timings`` and ``total_s``.
    """
    options = dataclasses.replace(options or RunOptions(), stages=Timer())
    result: Result = job.run(spec, progress=progress, options=options)
    check = result.validation
    if check is not None:
        with options.stages("validate"):
            mesh, result.check, result.vertices = validated_report(
                result.vertices, result.faces, check.domain_volume, check.intersections, solid=check.solid,
                what=check.what, self_intersections=check.known_pairs, hint=check.hint)
        result.report.update(mesh)
    if result.derive is not None:
        result.derive(result.report)
    result.report["timings"] = options.stages.total()
    return result


def write_outputs(result: Result, report: dict, outputs: dict, recipe: dict, root: Table, force: bool,
                  source=None) -> None:
    """Write the mesh, extra outputs, recipe and report of a finished job (in that order)."""
    import time

    from ..io import write_mesh
    timings = report.get("timings") or {}
    if outputs.get("mesh"):
        if not result.mesh_written:
            t = time.perf_counter()
            frame = report.get("frame")  # the vessel job's frame, marked as 3D Slicer reads it
            write_mesh(outputs["mesh"], result.vertices, result.faces, force=force,
                       header=f"SPACE={frame}" if frame in ("LPS", "RAS") else None)
            timings["write_s"] = timings.get("write_s", 0.0) + time.perf_counter() - t
        report["mesh_file"] = str(outputs["mesh"])
    for key, writer in result.extra_outputs.items():
        if outputs.get(key):
            writer(outputs[key], force)
            report[f"{key}_file"] = str(outputs[key])
    if outputs.get("recipe"):
        save_recipe(portable_recipe(recipe, root, outputs["recipe"]), outputs["recipe"], force=force)
        report["recipe_file"] = str(outputs["recipe"])
    elif source is not None:
        report["recipe_file"] = str(Path(source).resolve())
    report["timings"] = timings
    # the report folder (HTML) first, so that a JSON report beside it names it
    for key in ("report_dir", "report"):
        if outputs.get(key):
            write_report_output(outputs[key], report, result.vertices, result.faces,
                                domain_volume=result.domain_volume, design=result.design, force=force,
                                field=result.field, domain=result.domain, skin=result.skin, check=result.check)


def portable_recipe(recipe: dict, root: Table, target) -> dict:
    """The recipe to save at ``target``: input and output paths relative to its directory, versions stamped.

    An output outside that directory is saved as its bare file name: a
    recipe writes only inside its own folder (:meth:`Table.output`), so a
    shared copy reruns beside itself.
    """
    out = copy.deepcopy(recipe)
    where = Path(os.path.abspath(target)).parent
    for loc, value in root.paths():
        node = out
        for k in loc[:-1]:
            node = node[k]
        rel = _relative(value, where)
        if loc[0] == "output" and (os.path.isabs(rel) or rel.split(os.sep)[0] == ".."):
            rel = os.path.basename(value)
        node[loc[-1]] = rel
    out["format"] = FORMAT_VERSION
    out["porecad_version"] = __version__
    output = out.get("output")
    if isinstance(output, dict):
        output.pop("recipe", None)  # rerunning a recipe never rewrites it
    return out


def _relative(path: str, where: Path) -> str:
    try:
        return os.path.relpath(os.path.abspath(path), where)
    except ValueError:  # another drive (Windows)
        return os.path.abspath(path)
