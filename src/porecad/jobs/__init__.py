"""Jobs: one contract for every method.

A job is what a user asks for (``tpms``, ``infill``, ``tbss``, ``hex``,
``tis``, ``arbf``, ``vessel``, ``ivd``). Each is one module here with a typed
spec built from its recipe tables and one ``run(spec, progress, options) ->
Result``; :mod:`~porecad.jobs.registry` maps names to jobs and
:func:`run_recipe` runs any recipe through it — the command line, ``porecad
build``, the Python API and the studio all go this one way.

Examples
--------
>>> from porecad.jobs import run_recipe
>>> report = run_recipe({"job": "tpms",
...                      "tpms": {"type": "P", "structure": "pore", "threshold": 0.0},
...                      "domain": {"kind": "box", "cells": [1, 1, 1]},
...                      "sampling": {"resolution": 60}})
>>> round(report["porosity"], 2)
0.5
"""

from __future__ import annotations

from pathlib import Path

from .contract import Job, Result, RunOptions
from .registry import get as get_job
from .registry import names as job_names
from .runner import execute, parse

__all__ = ["Job", "Result", "RunOptions", "get_job", "job_names", "run_recipe", "run_recipe_file", "parse",
           "execute", "run_in_memory"]


def run_recipe(recipe: dict, force: bool = False, progress=None, threads: int | None = None,
               check_intersections: bool | None = None, memory_limit: int | None = None, base=None,
               source=None, confine=None) -> dict:
    """Run a recipe (a dict) through its job; write its outputs atomically; return the report.

    Parameters
    ----------
    recipe : dict
        ``job = "..."`` and the job's tables (see each job module, e.g.
        :mod:`porecad.jobs.tis_job`), plus ``[output]`` (``mesh``, ``report``,
        ``recipe`` and job-specific files).
    force : bool
        Overwrite existing outputs.
    progress : callable, optional
        ``progress(stage, done, total)``.
    threads : int, optional
        Worker threads (default: all cores).
    check_intersections : bool, optional
        Search the solid for self-intersections before writing (default: the job's choice).
    memory_limit : int, optional
        Bytes the job may use (default: the available memory).
    base : path, optional
        Directory that relative paths in the recipe are resolved against.
    source : path, optional
        The recipe file this recipe was read from.
    confine : path or (path, set), optional
        A folder the recipe's outputs must lie in (a shared recipe cannot
        write elsewhere), optionally with the output paths exempt from it.

    Returns
    -------
    dict
        The report: the common keys (``job``, ``porecad_version``,
        ``recipe_format``, ``closed``, ``manifold``, ``volume``,
        ``surface_area``, ``porosity``, ``domain_volume``, ``warnings``,
        ``timings``, ...) and the job's own.
    """
    options = RunOptions(threads=threads, check_intersections=check_intersections, memory_limit=memory_limit,
                         force=force)
    if confine is not None and not isinstance(confine, tuple):
        confine = (confine, frozenset())
    return execute(recipe, base=base, progress=progress, options=options, source=source, confine=confine)


def run_recipe_file(path, force: bool = False, progress=None, out_dir=None, **overrides) -> dict:
    """Run a recipe file: input paths in it are relative to the file; the file itself is never overwritten.

    Its outputs are relative paths inside its folder, or inside ``out_dir``
    when given (refused otherwise: a shared recipe cannot write elsewhere).
    """
    from ..io.recipe import read_recipe
    recipe = read_recipe(path)
    p = Path(path)
    folder = p.resolve().parent if out_dir is None else Path(out_dir)
    return run_recipe(recipe, force=force, progress=progress, base=p.resolve().parent, source=p,
                      confine=folder, **overrides)


def run_in_memory(recipe: dict, base=None, threads: int | None = None, progress=None):
    """Run a recipe's job without writing anything: ``(vertices, faces, report)`` (the common report keys).

    The ``[output]`` table is ignored. A job that writes several files of its
    own (``ivd``) is refused.
    """
    from ..errors import InputError
    from ..io.recipe import FORMAT_VERSION
    from .runner import common_report, run_job
    recipe = {k: v for k, v in recipe.items() if k != "output"}
    job, spec, _, _ = parse(recipe, base)
    result = run_job(job, spec, progress, RunOptions(threads=threads))
    if result.vertices is None:
        raise InputError(f"job {job.name!r} writes its own files; export it to see them, or run it with outputs")
    return result.vertices, result.faces, common_report(result.report, job.name, FORMAT_VERSION)
