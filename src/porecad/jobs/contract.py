"""The job contract: a typed spec from a recipe, ``run(spec, progress, options) -> Result``.

Every method porecad offers (``tpms``, ``infill``, ``tbss``, ``hex``, ``tis``,
``arbf``, ``vessel``, ``ivd``) is a :class:`Job`: a spec class whose
``from_recipe`` reads the recipe's tables through
:class:`~porecad.recipes.table.Table` (every check there, errors naming
the recipe key), and a ``run`` function that computes without writing
anything and returns a :class:`Result` — the mesh, the report and the design
domain. :func:`porecad.jobs.runner.execute` does the rest the same way for
every job: output checks before any work, validation, atomic writes of the
mesh, extra outputs, recipe and report.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np


@dataclasses.dataclass
class RunOptions:
    """How (not what) to run: machine settings that are not part of the design.

    Attributes
    ----------
    threads : int or None
        Worker threads (None: all cores).
    check_intersections : bool or None
        Search the solid for self-intersecting faces before writing (None: the
        job's default).
    memory_limit : int or None
        Bytes the job may use (None: the available memory).
    force : bool
        Overwrite existing outputs.
    outputs : dict
        The checked output paths (set by the runner; a job that streams its
        mesh writes to ``outputs["mesh"]``).
    islands : str
        What the promise check does with loose pieces, ``"drop"`` or ``"keep"``
        (set by the runner from the recipe; a job that streams its mesh drops
        them as it writes).
    stages : Timer
        The run's stage clock (the runner's: a job times a stage with ``with
        options.stages("mesh"): ...``; the runner reports them as ``timings``).
    """

    threads: int | None = None
    check_intersections: bool | None = None
    memory_limit: int | None = None
    force: bool = False
    outputs: dict = dataclasses.field(default_factory=dict)
    islands: str = "drop"
    stages: "Timer" = dataclasses.field(default_factory=lambda: Timer())


@dataclasses.dataclass
class Result:
    """What a job computed (nothing is written yet).

    Attributes
    ----------
    report : dict
        The job's report (JSON-ready); the runner adds the common keys.
    vertices, faces : ndarray or None
        The validated solid, its vertices rounded as mesh files store them
        (float32, :func:`porecad.mesh.validate.stored_coordinates`; None when the job streamed its mesh to the file
        or writes several meshes itself, as ``ivd`` does).
    domain_volume : float or None
        Volume of the design domain (porosity is measured against it).
    domain : object, optional
        The design domain for the analysis (issue 22): a
        :class:`~porecad.fields.base.Field` (negative inside), ``(vertices,
        faces)`` of a closed surface, a :class:`~porecad.bodies.mesh.MeshBody`,
        a :class:`~porecad.analysis.domain.BoxDomain`, or a
        :class:`DeferredDomain` that computes one only when a report
        directory asks for the analysis. None: the mesh's bounding box.
    skin : float or None
        Thickness (mm) of the closing shell of a ``skin`` infill: the analysis
        splits closed pores into those the shell closes and the lattice's own.
    design : dict or False or None
        The TPMS design for the report's porosity–threshold plot (None: from
        the report; False: not a TPMS threshold design).
    field : Field or None
        The field whose zero level set the mesh is (analytic curvature).
    extra_outputs : dict
        Output key → ``writer(path, force)`` for outputs besides the mesh
        (a tet mesh, a TDF file).
    mesh_written : bool
        The mesh is already in the output file (streamed).
    body : object, optional
        The body the user gave (``(vertices, faces)``, a
        :class:`~porecad.bodies.mesh.MeshBody` or a field negative inside
        with ``bounds``): the promise check measures the solid's coverage of
        it (:mod:`porecad.jobs.promise`). None: no body.
    check : dict or None
        :func:`porecad.mesh.validate.check_solid` of exactly ``vertices,
        faces`` (the runner's validation before writing): a report directory's
        analysis reuses it instead of validating the mesh a second time.
    validation : Validation or None
        How the runner checks the solid before anything is written (None:
        nothing to check here: a streamed mesh, checked as it was written, or
        a job that writes its own files).
    derive : callable or None
        ``derive(report)``: figures and findings the job takes from the
        checked solid's report (its volume, porosity), added by the runner
        after the check.
    """

    report: dict
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    domain_volume: float | None = None
    domain: Any = None
    skin: float | None = None
    design: Any = None
    field: Any = None
    extra_outputs: dict = dataclasses.field(default_factory=dict)
    mesh_written: bool = False
    check: dict | None = None
    body: Any = None
    validation: "Validation | None" = None
    derive: Callable | None = None

    def __post_init__(self):
        # the coordinates the mesh files store (float32); a solid still to check is rounded by the check
        if self.vertices is not None and self.validation is None:
            from ..mesh.validate import stored_coordinates
            self.vertices = stored_coordinates(self.vertices)


@dataclasses.dataclass(frozen=True)
class Validation:
    """How the runner checks a job's solid before anything is written (:func:`porecad.jobs.outputs.validated_report`).

    Attributes
    ----------
    what : str
        The solid's name in errors ("the hex scaffold").
    domain_volume : float or None
        The volume its porosity is measured against (None: no porosity).
    intersections : bool
        Search the solid for self-intersecting face pairs (refused if any).
    known_pairs : int or None
        That count, when the job has just made it on exactly these vertices and faces (not searched again).
    hint : str
        What may avoid self-intersections (joins the refusal).
    solid : bool
        A closed solid (False: a bare surface, no volume or porosity).
    """

    what: str = "the solid"
    domain_volume: float | None = None
    intersections: bool = False
    known_pairs: int | None = None
    hint: str = ""
    solid: bool = True


class DeferredDomain:
    """A design domain computed on demand: ``DeferredDomain(fn, *args)`` calls ``fn(*args)`` once, when asked.

    A job hands one over when building its domain surface costs work that
    only the full analysis (a report directory) needs, e.g. the boundary of
    a TBSS solid or the non-porous wall of a vessel.
    """

    def __init__(self, fn: Callable, *args):
        self.fn, self.args = fn, args

    def resolve(self):
        """The domain (computed on the first call)."""
        if self.fn is not None:
            self.value = self.fn(*self.args)
            self.fn = self.args = None
        return self.value


@dataclasses.dataclass(frozen=True)
class Job:
    """A registered job.

    Attributes
    ----------
    name : str
        The recipe's ``job`` value.
    spec : type
        Spec class with ``from_recipe(table) -> spec`` and ``inputs() -> list``.
    run : callable
        ``run(spec, progress=None, options=None) -> Result``.
    outputs : tuple of str
        The keys its ``[output]`` table takes (``mesh``, ``report``, ``recipe``, ...).
    summary : tuple of str
        Report keys the command line prints.
    title : str
        One line for listings.
    dir_outputs : tuple of str
        Output keys that are folders the job fills itself (it checks their files).
    """

    name: str
    spec: type
    run: Callable
    outputs: tuple = ("mesh", "report", "recipe")
    summary: tuple = ()
    title: str = ""
    dir_outputs: tuple = ()


def stage_progress(progress, stage: str):
    """A ``(done, total)`` callback forwarding to ``progress(stage, done, total)`` (None without one)."""
    if progress is None:
        return None
    return lambda done, total: progress(stage, done, total)


class Timer:
    """Named stage timings: ``with timer("mesh"): ...`` adds ``mesh_s``."""

    def __init__(self):
        self.t0 = time.perf_counter()
        self.timings: dict[str, float] = {}

    def __call__(self, name: str):
        timer = self

        class _Stage:
            def __enter__(self):
                self.t = time.perf_counter()

            def __exit__(self, *exc):
                key = f"{name}_s"
                timer.timings[key] = timer.timings.get(key, 0.0) + time.perf_counter() - self.t
                return False

        return _Stage()

    def total(self) -> dict:
        """The timings with ``total_s`` since the timer started."""
        out = dict(self.timings)
        out["total_s"] = time.perf_counter() - self.t0
        return out
