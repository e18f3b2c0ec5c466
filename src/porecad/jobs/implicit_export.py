"""A tpms or infill recipe's design as an implicit 3MF (:mod:`porecad.io.implicit_3mf`).

The design is planned as the slicer plans it (:func:`porecad.printing.part.from_recipe`): the
lattice plan of the recipe, a porosity resolved to a threshold with porecad's calibration (the
type's curve for a box of cells; the body's own samples for an infill, without the corrections
for a mesh's discretisation), then turned into the function graph's description.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError, RecipeError
from ..io.implicit_3mf import ImplicitDesign, Ramp
from ..lattice.spec import CellRamp

#: the jobs whose design is a closed-form field
FIELD_JOBS = ("tpms", "infill")


def _refuse_unsupported(job, spec) -> None:
    """One-line errors for what the function graph does not hold."""
    if job.name not in FIELD_JOBS:
        raise InputError(f"an implicit 3MF holds a tpms or infill design; job {job.name!r} is a mesh: "
                         "write its mesh with porecad build")
    tp, domain = spec.tpms, spec.domain
    if tp.structure == "surface":
        raise RecipeError("tpms.structure", "a bare surface is not a solid; an implicit 3MF needs pore, rod "
                                            "or sheet")
    if isinstance(tp.cell_size, CellRamp):
        raise RecipeError("tpms.cell_size", "a cell-size ramp is not supported in an implicit 3MF; give one "
                                            "cell size")
    if domain.kind == "disc":
        raise RecipeError("domain.kind", "the disc body is not supported in an implicit 3MF; use a mesh body "
                                         "(kind = mesh)")
    if domain.kind == "mesh" and domain.boundary != "cut":
        raise RecipeError("domain.boundary", f"boundary {domain.boundary!r} is not supported in an "
                                             "implicit 3MF; use boundary = cut")


def threshold_of(threshold):
    """The plan's threshold field as a number or a :class:`Ramp`; a RecipeError for any other grading."""
    from ..fields.base import Constant
    from ..grading import Ramp as RampField
    if isinstance(threshold, (int, float)):
        return float(threshold)
    if isinstance(threshold, Constant):
        return float(threshold.value)
    if isinstance(threshold, RampField):
        centre = None if threshold.centre is None else tuple(float(c) for c in threshold.centre)
        return Ramp(threshold.v0, threshold.v1, threshold.s0, threshold.s1, tuple(int(a) for a in threshold.axes),
                    centre)
    raise RecipeError("grading", "an implicit 3MF holds a constant threshold or a linear or radial threshold "
                                 "ramp (of = threshold); this grading is not supported")


def plan_design(recipe: dict, base=None):
    """The checked spec's lattice plan, its porosity calibrated as the slicer's (``(job, spec, plan)``)."""
    from ..lattice.plan import hold_porosity, plan_lattice, replay_hold
    from .runner import parse
    from .tpms_job import regions_wanted
    job, spec, _, _ = parse(recipe, base)
    _refuse_unsupported(job, spec)
    plan = plan_lattice(spec)
    if plan.body is not None:
        n, axis = regions_wanted(spec, plan, calibrating=True)
        hold_porosity(plan, n, axis, allow=spec.tpms.allow_closed_pores)
        replay_hold(plan, 0.0, bias=0.0)  # the exact field: no correction for a mesh's discretisation
    return job, spec, plan


def implicit_design(recipe: dict, base=None) -> ImplicitDesign:
    """The :class:`ImplicitDesign` of a tpms or infill recipe (a dict; ``base``: its folder)."""
    from ..fields.tpms import TPMSField
    from ..io.implicit_3mf import box_mesh
    job, spec, plan = plan_design(recipe, base)
    material = plan.material
    phi = material.phi
    if not isinstance(phi, TPMSField):
        raise RecipeError("tpms.cell_size", "an implicit 3MF needs a regular TPMS lattice")
    threshold = threshold_of(material.threshold)
    terms = tuple((float(t.coef), tuple((fn, int(k)) for fn, k in t.funcs)) for t in phi.type.terms)
    common = {"name": f"{phi.type.name} {material.structure}", "terms": terms, "constant": float(phi.type.constant),
              "cell_size": tuple(float(x) for x in phi.cell_size), "origin": tuple(float(x) for x in phi.origin),
              "structure": material.structure, "sheet_level": float(material.sheet_level), "threshold": threshold}
    if plan.body is None:
        lo, hi = (tuple(float(x) for x in plan.grid.box_min), tuple(float(x) for x in plan.grid.box_max))
        return ImplicitDesign(**common, mesh=box_mesh(lo, hi), box=(lo, hi), bbox_only=True)
    body = plan.body
    return ImplicitDesign(**common, mesh=(np.asarray(body.vertices), np.asarray(body.faces)), box=None,
                          bbox_only=False)


def export_implicit(recipe, out, base=None, force: bool = False) -> dict:
    """Write the design of ``recipe`` (a dict or a ``.toml`` file) as an implicit 3MF ``out``; return the report.

    The report: ``file``, ``bytes``, ``nodes`` (of the function graph), ``type``, ``structure``,
    ``threshold`` (a number, or the ramp as a dict), ``cell_size``, ``domain`` (box or mesh) and
    ``mesh_triangles`` (of the evaluation mesh).
    """
    import dataclasses
    from pathlib import Path

    from ..io import check_output_path
    from ..io.implicit_3mf import load_lib3mf, write_implicit_3mf
    load_lib3mf()  # before the design is planned: a missing extra is the first thing said
    if Path(out).suffix.lower() != ".3mf":
        raise InputError(f"an implicit 3MF is written to a .3mf file, got {str(out)[:200]!r}")
    check_output_path(out, force=force)
    if not isinstance(recipe, dict):
        from ..io.recipe import read_recipe
        p = Path(recipe)
        recipe, base = read_recipe(p), (base if base is not None else p.resolve().parent)
    design = implicit_design(recipe, base)
    report = write_implicit_3mf(design, out, force=force)
    c = design.threshold
    report.update(type=design.name.split()[0], structure=design.structure,
                  threshold=dataclasses.asdict(c) if isinstance(c, Ramp) else c,
                  cell_size=list(design.cell_size), domain="box" if design.box is not None else "mesh")
    return report
