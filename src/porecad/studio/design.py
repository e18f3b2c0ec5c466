"""The studio's form: its fields, and the recipe a filled form stands for.

The page sends a *design*: a flat dict of form values (``{"job": "infill",
"type": "G", "structure": "sheet", "control": "porosity", "value": 0.7, ...}``).
:func:`recipe_of` turns it into the recipe that ``porecad build`` runs — the
same tables the command line writes (``cli/cmd_lattice.tpms_recipe``,
``cli/cmd_tis.tis_recipe``, ...) — and :func:`design_of` reads a recipe back
into form values. Every value is checked here for its type and bounded before
the job's own checks (:func:`porecad.jobs.parse`) see it; an error names the
form field (:class:`FieldError`). File inputs are names of the session's
uploads, never paths: :class:`~porecad.studio.session.Session` resolves them
inside its work folder.
"""

from __future__ import annotations

import math

from ..errors import InputError, RecipeError
from ..recipes.schema import default_of
from .form_schema import FIELD_KEYS, apply_more, main_field, more_fields, more_of

#: jobs the studio designs, in the order of the job menu
JOBS = ("tpms", "infill", "tbss", "hex", "tis", "vessel")
JOB_TITLES = {"tpms": "Box lattice", "infill": "Infill of a body", "tbss": "B-spline solid (TBSS)",
              "hex": "Hex map", "tis": "Tetrahedral (TIS)", "vessel": "Vessel from a centreline"}
LATTICE = ("tpms", "infill", "hex")
GRADINGS = ("none", "axial", "radial", "depth", "expression")
BUILT_IN = {"infill": ("disc",), "tbss": ("disc", "box", "cylinder", "tube"), "hex": ("frustum", "cylinder"),
            "tis": ("regular-tet", "two-tets", "icosahedron")}
#: upload kinds each job's file field accepts
UPLOAD_KINDS = {"infill": ("mesh", "image"), "tbss": ("mesh",), "hex": ("mesh",), "tis": ("mesh", "volume"),
                "vessel": ("centreline",)}


class FieldError(InputError):
    """A form value is invalid; ``field`` names the form field."""

    def __init__(self, field: str, detail: str):
        self.field = str(field)
        self.detail = str(detail)
        super().__init__(f"{field}: {detail}")


def _f(name, label, kind, default=None, jobs=JOBS, when=None, options=None, help="", **bounds):  # noqa: A002
    return {"name": name, "label": label, "kind": kind, "default": default, "jobs": list(jobs),
            "when": when or {}, "options": options, "help": help, **bounds}


def fields(tpms_types) -> list[dict]:
    """The form fields (for the page): name, label, kind, default, the jobs and conditions that show it.

    The main fields that are one recipe key take that key's options, help
    and bounds from the recipe schema; every other scalar key of a job's
    recipe is a "more settings" field made from the job's JSON Schema
    (:mod:`porecad.studio.form_schema`).
    """
    return [main_field(f) for f in _main_fields(tpms_types)] + more_fields(JOBS)


def _main_fields(tpms_types) -> list[dict]:
    """The form's own fields (a design layer: one field may stand for several recipe keys)."""
    lattice_c = {"control": ["porosity", "threshold"]}
    return [
        _f("body", "Body", "body", "disc", jobs=("infill", "tbss", "hex", "tis"),
           help="a built-in shape or an uploaded file"),
        _f("centreline", "Centreline", "body", "", jobs=("vessel",), help="an uploaded .json, .swc or .vtp"),
        _f("body_label", "Image label", "number", None, jobs=("infill",), when={"body_kind": ["image"]},
           help="voxel value of the body in a label image"),
        _f("body_threshold", "Image threshold", "number", None, jobs=("infill",), when={"body_kind": ["image"]},
           help="body = voxels ≥ this (e.g. 300 HU for bone)"),
        _f("type", "TPMS type", "select", "G", jobs=("tpms", "infill", "tbss", "hex"), options=list(tpms_types)),
        _f("tis_type", "TIS type", "select", "P", jobs=("tis",), options=["P", "D", "G"]),
        _f("structure", "Structure", "select", None, jobs=("tpms", "infill", "tbss", "hex"),
           options=["pore", "rod", "sheet"]),
        _f("tis_structure", "Structure", "select", "pore", jobs=("tis",), options=["pore", "rod"]),
        _f("control", "Set by", "select", "porosity", jobs=LATTICE + ("tbss",), options=["porosity", "threshold"]),
        _f("value", "Porosity / threshold", "number", 0.7, jobs=LATTICE + ("tbss",), step=0.01, when=lattice_c,
           help="porosity (void fraction) or threshold C; with a grading: the value at the start"),
        _f("grading", "Grading", "select", "none", jobs=("tpms", "infill", "tbss"), options=list(GRADINGS),
           help="axial: along an axis; radial: from the axis outwards; depth: surface to deepest point; "
                "expression: a formula in x, y, z (mm) and dn (depth, 0 at the surface, 1 deepest)"),
        _f("expression", "Formula", "text", "0.5 + 0.3 * dn", jobs=("tpms", "infill"),
           when={"grading": ["expression"]}, help="e.g. 0.5 + 0.3 * dn, or 0.6 + 0.01 * z"),
        _f("value_to", "… graded to", "number", 0.8, jobs=("tpms", "infill", "tbss"), step=0.01,
           when={"grading": ["axial", "radial", "depth"]}),
        _f("axis", "Axis", "select", "z", jobs=("tpms", "infill", "tbss"), options=["x", "y", "z"],
           when={"grading": ["axial", "radial"]}),
        _f("cell_size", "Cell size (mm)", "number", None, jobs=("tpms", "infill"), lo=1e-3, hi=1e4, step=0.1),
        _f("cells", "Cells x y z", "int3", [2, 2, 2], jobs=("tpms",), lo=1, hi=1000),
        _f("periods", "Periods u v w", "int3", None, jobs=("tbss",), lo=1, hi=200),
        _f("grid", "Hex cells i j k", "int3", [2, 2, 3], jobs=("hex",), lo=1, hi=200),
        _f("element", "Element", "select", None, jobs=("hex",), options=["hex8", "hex20"]),
        _f("boundary", "Boundary", "select", None, jobs=("infill",), options=["cut", "skin", "whole"]),
        _f("skin", "Skin (mm)", "number", None, jobs=("infill",), when={"boundary": ["skin"]}, lo=1e-3, hi=1e4),
        _f("lambda", "Periods per tet (λ)", "number", None, jobs=("tis",), lo=0.1, hi=100),
        _f("relative", "Relative threshold", "number", 0.176, jobs=("tis",), lo=0.0, hi=1.0, step=0.01),
        _f("tets", "Tetrahedra", "int", None, jobs=("tis",), when={"body_kind": ["mesh"]}, lo=1, hi=200_000),
        _f("size", "Size (mm)", "number", None, jobs=("tis",), when={"body_kind": ["builtin"]}, lo=1e-3, hi=1e5),
        _f("wall", "Wall layers (mm)", "text", "0.1 0.3 0.2", jobs=("vessel",),
           help="thicknesses from the lumen out; empty: a solid lumen"),
        _f("porous_layer", "Porous layer", "int", 0, jobs=("vessel",), lo=0, hi=16, help="0: none"),
        _f("porous_cell", "Porous cell (mm)", "number", 0.6, jobs=("vessel",), lo=1e-3, hi=1e4,
           when={"porous_layer": ["nonzero"]}),
        _f("resolution", "Samples per cell", "int", None, jobs=("tpms", "tbss", "hex", "tis"), lo=3, hi=512,
           help="of the exported mesh; the preview starts coarser"),
        _f("voxel", "Voxel (mm)", "number", None, jobs=("infill", "vessel"), lo=1e-3, hi=1e4,
           help="sample spacing of the exported mesh (infill: empty = the default that follows the cell)"),
        _f("allow_closed_pores", "Allow closed pores", "check", False, jobs=LATTICE + ("tbss",),
           help="build outside the valid range; the report says so"),
        _f("min_feature", "Printer minimum feature (mm)", "number", 0.15, lo=0.0, hi=100.0, step=0.05,
           help="walls and struts thinner than this are flagged"),
    ]


# ---------------------------------------------------------------------------------------------------- values

def _default(job: str, name: str):
    """The recipe schema's default of main form field ``name`` in ``job`` (the key it is)."""
    return default_of(job, FIELD_KEYS[name][job])


def limits(name: str) -> tuple:
    """``(lo, hi)`` of main form field ``name``: the form's own limits, within the schema's of its key."""
    f = main_field(next(f for f in _main_fields(()) if f["name"] == name))
    return f["lo"], f["hi"]


def _num(design, name, default=None, lo=-1e7, hi=1e7, required=True):
    v = design.get(name, default)
    if v is None or v == "":
        if required and default is None:
            raise FieldError(name, "is required")
        return default
    if isinstance(v, bool):
        raise FieldError(name, f"must be a number, got {v!r}")
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise FieldError(name, f"must be a number, got {str(v)[:40]!r}") from None
    if not math.isfinite(x) or not lo <= x <= hi:
        raise FieldError(name, f"must lie in [{lo:g}, {hi:g}], got {x:g}")
    return x


def _int(design, name, default=None, lo=0, hi=10**6):
    x = _num(design, name, default, lo, hi)
    if x is None:
        return None
    if x != int(x):
        raise FieldError(name, f"must be a whole number, got {x:g}")
    return int(x)


def _choice(design, name, options, default):
    v = design.get(name, default)
    if v is None or v == "":
        v = default
    if not isinstance(v, str) or v not in options:
        raise FieldError(name, f"must be one of {', '.join(map(str, options))}, got {str(v)[:40]!r}")
    return v


def _int3(design, name, default, lo=1, hi=1000):
    v = design.get(name, default)
    if isinstance(v, str):
        v = v.replace(",", " ").split()
    if not isinstance(v, (list, tuple)) or len(v) != 3:
        raise FieldError(name, "takes three whole numbers")
    try:
        return [_int({name: x}, name, None, lo, hi) for x in v]
    except FieldError as exc:
        raise FieldError(name, f"takes three whole numbers in [{lo}, {hi}] ({exc.detail})") from None


def _flag(design, name, default=False):
    v = design.get(name, default)
    if isinstance(v, str):
        v = v.lower() in ("1", "true", "on", "yes")
    return bool(v)


def _numbers(design, name, lo=0.0, hi=1e4, max_len=16):
    v = design.get(name, "")
    if v is None:
        return []
    if isinstance(v, str):
        if len(v) > 400:
            raise FieldError(name, "is too long")
        v = v.replace(",", " ").split()
    if not isinstance(v, (list, tuple)) or len(v) > max_len:
        raise FieldError(name, f"takes at most {max_len} numbers")
    try:
        return [_num({name: x}, name, None, lo, hi) for x in v]
    except FieldError as exc:
        raise FieldError(name, f"takes numbers in [{lo:g}, {hi:g}] ({exc.detail})") from None


# ---------------------------------------------------------------------------------------------------- recipes

def _amount(design, job, bounds):
    """The [tpms] threshold/porosity keys and the [grading] table (or None) of a lattice design."""
    control = _choice(design, "control", ("porosity", "threshold"), "porosity")
    lo, hi = (0.0, 1.0) if control == "porosity" else (-100.0, 100.0)
    grading = _choice(design, "grading", GRADINGS, "none") if job in ("tpms", "infill") else "none"
    if grading == "expression":
        expr = " ".join(str(design.get("expression") or "").split())
        if not expr or len(expr) > 500:
            raise FieldError("expression", "give a formula of at most 500 characters")
        return {}, {"kind": "expression", "of": control, "expr": expr}
    v0 = _num(design, "value", None, lo, hi)
    if grading == "none":
        return {control: v0}, None
    v1 = _num(design, "value_to", None, lo, hi)
    axis = _choice(design, "axis", ("x", "y", "z"), "z")
    a = "xyz".index(axis)
    blo, bhi = bounds
    if grading == "axial":
        return {}, {"kind": "linear", "of": control, "axis": axis, "start": float(blo[a]), "end": float(bhi[a]),
                    "from": v0, "to": v1}
    if grading == "radial":
        axes = "".join(c for c in "xyz" if c != axis)
        centre = [0.5 * (float(blo[i]) + float(bhi[i])) for i in range(3)]
        r1 = max(0.5 * (float(bhi[i]) - float(blo[i])) for i in range(3) if i != a)
        return {}, {"kind": "radial", "of": control, "axes": axes, "centre": centre, "r0": 0.0, "r1": r1,
                    "from": v0, "to": v1}
    if job != "infill":
        raise FieldError("grading", "depth grading needs a body (job infill)")
    return {}, {"kind": "expression", "of": control, "expr": f"{v0!r} + ({v1!r} - {v0!r}) * dn"}


def box_bounds(design) -> tuple[list, list]:
    """The box of a ``tpms`` design (origin 0): cells × cell size."""
    cells = _int3(design, "cells", [2, 2, 2], *limits("cells"))
    cs = _num(design, "cell_size", _default("tpms", "cell_size"), *limits("cell_size"))
    return [0.0, 0.0, 0.0], [c * cs for c in cells]


def recipe_of(design: dict, resolve_input=None, body_bounds=None) -> dict:
    """The recipe (no ``[output]``) of a design.

    Parameters
    ----------
    design : dict
        Form values (see :func:`fields`).
    resolve_input : callable, optional
        ``resolve_input(name, kinds) -> path``: an upload's path in the session's
        work folder (a :class:`FieldError` otherwise). Without it, file
        designs are refused.
    body_bounds : callable, optional
        ``body_bounds(design) -> (lo, hi)`` of the design's body (axial and
        radial gradings span it).
    """
    if not isinstance(design, dict):
        raise InputError("a design is a table of form values")
    job = _choice(design, "job", JOBS, "tpms")
    _num(design, "min_feature", 0.15, *limits("min_feature"))  # the preview's analysis only: checked here all the same

    def resolve(name, kinds):
        if resolve_input is None:
            raise FieldError("body", "no uploads in this context")
        return resolve_input(name, kinds)

    if job == "tpms":
        cells = _int3(design, "cells", [2, 2, 2], *limits("cells"))
        tp, grading = _amount(design, job, box_bounds(design))
        recipe = {"job": "tpms",
                  "tpms": {"type": str(design.get("type", "G")), "structure": _structure(design, "tpms"),
                           "cell_size": _num(design, "cell_size", _default("tpms", "cell_size"), *limits("cell_size")),
                           **tp},
                  "domain": {"kind": "box", "cells": cells},
                  "sampling": {"resolution": _int(design, "resolution", _default("tpms", "resolution"),
                                                  *limits("resolution"))}}
    elif job == "infill":
        body = str(design.get("body") or "disc")
        if body == "disc":
            domain = {"kind": "disc"}
        else:
            domain = {"kind": "mesh", "path": str(resolve(body, UPLOAD_KINDS["infill"]))}
            for src, key in (("body_label", "label"), ("body_threshold", "threshold")):
                if design.get(src) not in (None, ""):
                    domain[key] = _num(design, src, None, -1e9, 1e9)
        domain["boundary"] = _choice(design, "boundary", ("cut", "skin", "whole"), _default("infill", "boundary"))
        if domain["boundary"] == "skin":
            domain["skin"] = _num(design, "skin", _default("infill", "skin"), *limits("skin"))
        if domain["kind"] == "disc":
            domain.pop("boundary")
            if design.get("boundary", "cut") != "cut":
                raise FieldError("boundary", "the built-in disc takes boundary cut; upload a body for skin or whole")
        bounds = body_bounds(design) if body_bounds is not None and design.get("grading", "none") in (
            "axial", "radial") else ([0, 0, 0], [1, 1, 1])
        tp, grading = _amount(design, job, bounds)
        recipe = {"job": "infill",
                  "tpms": {"type": str(design.get("type", "G")), "structure": _structure(design, "infill"),
                           "cell_size": _num(design, "cell_size", _default("infill", "cell_size"),
                                             *limits("cell_size")), **tp},
                  "domain": domain, "sampling": {}}
        voxel = _num(design, "voxel", None, *limits("voxel"), required=False)
        if voxel is not None:
            recipe["sampling"]["voxel"] = voxel
    else:
        make = {"tbss": _tbss_recipe, "hex": _hex_recipe, "tis": _tis_recipe, "vessel": _vessel_recipe}[job]
        recipe, grading = make(design, resolve), None
    if job in ("tpms", "infill"):
        if grading:
            recipe["grading"] = grading
        if _flag(design, "allow_closed_pores"):
            recipe["tpms"]["allow_closed_pores"] = True
    apply_more(design, job, recipe, FieldError)
    return recipe


def _structure(design, job):
    return _choice(design, "structure", ("pore", "rod", "sheet"), _default(job, "structure"))


def _tbss_recipe(design, resolve):
    body = str(design.get("body") or "disc")
    if body in BUILT_IN["tbss"]:
        b = {"kind": body}
    else:
        b = {"kind": "mesh", "path": str(resolve(body, UPLOAD_KINDS["tbss"]))}
    control = _choice(design, "control", ("porosity", "threshold"), "porosity")
    lo, hi = (0.0, 1.0) if control == "porosity" else (-100.0, 100.0)
    v0 = _num(design, "value", None, lo, hi)
    grading = _choice(design, "grading", GRADINGS, "none")
    v1 = v0 if grading == "none" else _num(design, "value_to", None, lo, hi)
    # gradings in the parameter cube of the B-spline solid: axial along u, v or w (the axis x, y or z),
    # radial from the sides inwards, depth from the boundary inwards (001's layer and function TDFs)
    if grading in ("none", "axial"):
        tdf = {"method": "function", "expr": _axis_param(design)}
    elif grading == "radial":
        tdf = {"method": "layer", "by": "sides"}
    else:
        tdf = {"method": "layer", "by": "boundary"}
    tdf[f"{control}_range"] = [v0, v1]  # one value: a constant TDF maps onto [v0, v0]
    recipe = {"job": "tbss", "body": b,
              "tpms": {"type": str(design.get("type", "G")), "structure": _structure(design, "tbss"),
                       "periods": _int3(design, "periods", list(_default("tbss", "periods")), *limits("periods"))},
              "tdf": tdf, "mesh": {"resolution": _int(design, "resolution", _default("tbss", "resolution"),
                                                    *limits("resolution"))}}
    if _flag(design, "allow_closed_pores"):
        recipe["tpms"]["allow_closed_pores"] = True
    return recipe


def _axis_param(design):
    """The TBSS parameter (u, v, w) along which an axial grading runs: the TDF expression in it."""
    axis = _choice(design, "axis", ("x", "y", "z"), "z")
    return {"x": "u", "y": "v", "z": "w"}[axis]


def _hex_recipe(design, resolve):
    body = str(design.get("body") or "frustum")
    if body in BUILT_IN["hex"]:
        b = {"kind": body}
    elif body in BUILT_IN["tbss"] + BUILT_IN["tis"] + BUILT_IN["infill"]:
        raise FieldError("body", f"the hex job's built-in bodies are {', '.join(BUILT_IN['hex'])}")
    else:
        b = {"kind": "mesh", "path": str(resolve(body, UPLOAD_KINDS["hex"]))}
    control = _choice(design, "control", ("porosity", "threshold"), "porosity")
    lo, hi = (0.0, 1.0) if control == "porosity" else (-100.0, 100.0)
    recipe = {"job": "hex", "body": b,
              "tpms": {"type": str(design.get("type", "P")), "structure": _structure(design, "hex"),
                       control: _num(design, "value", None, lo, hi)},
              "grid": _int3(design, "grid", [2, 2, 3], *limits("grid")),
              "element": _choice(design, "element", ("hex8", "hex20"), _default("hex", "element")),
              "mesh": {"resolution": _int(design, "resolution", _default("hex", "resolution"), *limits("resolution"))}}
    if _flag(design, "allow_closed_pores"):
        recipe["tpms"]["allow_closed_pores"] = True
    return recipe


def _tis_recipe(design, resolve):
    body = str(design.get("body") or "regular-tet")
    if body in BUILT_IN["tis"]:
        domain = {"kind": body, "size": _num(design, "size", _default("tis", "size"), *limits("size"))}
    elif body in BUILT_IN["tbss"] + BUILT_IN["hex"] + BUILT_IN["infill"]:
        raise FieldError("body", f"the TIS job's built-in domains are {', '.join(BUILT_IN['tis'])}")
    else:
        from ..volmesh import is_volume_mesh_path
        path = str(resolve(body, UPLOAD_KINDS["tis"]))
        domain = {"kind": "tet-mesh", "path": path} if is_volume_mesh_path(path) else \
            {"kind": "body", "path": path, "tets": _int(design, "tets", _default("tis", "tets"), *limits("tets"))}
    return {"job": "tis", "domain": domain,
            "tis": {"type": _choice(design, "tis_type", ("P", "D", "G"), "P"),
                    "lambda": _num(design, "lambda", _default("tis", "lambda"), *limits("lambda")),
                    "structure": _choice(design, "tis_structure", ("pore", "rod"), "pore"),
                    "relative": _num(design, "relative", 0.176, *limits("relative"))},
            "mesh": {"resolution": _int(design, "resolution", _default("tis", "resolution"), *limits("resolution")),
                     "method": "lattice",
                     "smooth": 0}}


def _vessel_recipe(design, resolve):
    name = design.get("centreline") or ""
    if not name:
        raise FieldError("centreline", "upload a centreline file (.json, .swc or .vtp) first")
    recipe = {"job": "vessel", "input": {"kind": "centreline", "path": str(resolve(str(name),
                                                                                   UPLOAD_KINDS["vessel"]))},
              "voxel": _num(design, "voxel", 0.1, *limits("voxel"))}
    wall = _numbers(design, "wall", 1e-4, 1e4)
    if wall:
        recipe["wall"] = wall
    layer = _int(design, "porous_layer", 0, *limits("porous_layer"))
    if layer:
        if layer > len(wall):
            raise FieldError("porous_layer", f"there are {len(wall)} wall layers")
        recipe["porous"] = {"layer": layer, "type": str(design.get("type", "G")),
                            "cell_size": _num(design, "porous_cell", 0.6, *limits("porous_cell"))}
    return recipe


def check_range(recipe: dict) -> None:
    """Refuse a constant porosity or threshold outside its valid range now (the job would, later).

    The job's own check (:func:`porecad.calibration.check_porosity`, ``check_threshold``)
    is run on the design's value so that the page can mark the field; graded
    designs are checked by the job.
    """
    from ..calibration import check_porosity, check_threshold
    from ..errors import RangeError
    tp = recipe.get("tpms")
    if not isinstance(tp, dict) or tp.get("allow_closed_pores") or tp.get("structure") not in ("pore", "rod", "sheet"):
        return
    try:
        if tp.get("porosity") is not None:
            check_porosity(tp["type"], tp["structure"], tp["porosity"])
        elif tp.get("threshold") is not None:
            check_threshold(tp["type"], tp["structure"], tp["threshold"])
    except RangeError as exc:
        raise FieldError("value", " ".join(str(exc).split())) from None


# ---------------------------------------------------------------------------------------------------- back

def design_of(recipe: dict, upload_name=None) -> dict:
    """Form values of a recipe (the reverse of :func:`recipe_of` for the keys the form has).

    ``upload_name(path) -> name`` gives the upload that stands for an input
    path (None: the input is not available in this session).
    """
    if not isinstance(recipe, dict):
        raise InputError("a recipe is a table")
    job = recipe.get("job")
    if job not in JOBS:
        raise RecipeError("job", f"the studio designs {', '.join(JOBS)} jobs, not {str(job)[:40]!r}")
    name_of = upload_name or (lambda p: None)
    d: dict = {"job": job}
    tp = recipe.get("tpms") if isinstance(recipe.get("tpms"), dict) else {}
    _tpms_form(d, tp)
    if isinstance(recipe.get("grading"), dict):
        _grading_form(d, recipe["grading"])
    dom = recipe.get("domain") if isinstance(recipe.get("domain"), dict) else {}
    if job == "tpms":
        d["cells"] = dom.get("cells", [1, 1, 1])
        d["resolution"] = (recipe.get("sampling") or {}).get("resolution", _default("tpms", "resolution"))
    elif job == "infill":
        _infill_form(d, recipe, dom, name_of)
    elif job in ("tbss", "hex"):
        _body_form(d, job, recipe, tp, name_of)
    elif job == "tis":
        _tis_form(d, recipe, dom, name_of)
    else:
        _vessel_form(d, recipe, name_of)
    d.update(more_of(recipe, job))
    return {k: v for k, v in d.items() if v is not None}


def _tpms_form(d, tp):
    """Add the form values of a recipe's ``tpms`` table ``tp`` (type, structure, control, cell size,
    closed pores) to the form dict ``d``; returns nothing."""
    for k in ("type", "structure"):
        if k in tp:
            d[k] = tp[k]
    for k in ("porosity", "threshold"):
        if tp.get(k) is not None:
            d["control"], d["value"], d["grading"] = k, tp[k], "none"
    if isinstance(tp.get("cell_size"), (int, float)):
        d["cell_size"] = tp["cell_size"]
    elif isinstance(tp.get("cell_size"), list) and tp["cell_size"]:
        d["cell_size"] = tp["cell_size"][0]
    if tp.get("allow_closed_pores"):
        d["allow_closed_pores"] = True


def _grading_form(d, g):
    """Add the form values of a recipe's ``grading`` table ``g`` to the form dict ``d``; returns nothing,
    raises :class:`RecipeError` for a grading kind the form has not."""
    d["control"] = g.get("of", "threshold")
    if g.get("kind") == "linear":
        d.update(grading="axial", axis=g.get("axis", "z"), value=g.get("from"), value_to=g.get("to"))
    elif g.get("kind") == "radial":
        axes = str(g.get("axes", "xy"))
        d.update(grading="radial", axis=next((c for c in "xyz" if c not in axes), "z"), value=g.get("from"),
                 value_to=g.get("to"))
    elif g.get("kind") == "constant":
        d.update(grading="none", value=g.get("value"))
    elif g.get("kind") == "expression":
        d.update(grading="expression", expression=str(g.get("expr", "")))
    else:
        raise RecipeError("grading.kind", f"the studio's form has no {g.get('kind')!r} grading; build this "
                                          "recipe with `porecad build`")


def _infill_form(d, recipe, dom, name_of):
    """Add an infill job's form values (body, its label/threshold, boundary, skin, voxel) from the recipe
    and its ``domain`` table ``dom`` to the form dict ``d``; returns nothing."""
    if dom.get("kind") == "mesh":
        d["body"] = name_of(dom.get("path"))
        for src, key in (("body_label", "label"), ("body_threshold", "threshold")):
            if key in dom:
                d[src] = dom[key]
    else:
        d["body"] = "disc"
    d["boundary"] = dom.get("boundary", "cut")
    if "skin" in dom:
        d["skin"] = dom["skin"]
    if "voxel" in (recipe.get("sampling") or {}):
        d["voxel"] = recipe["sampling"]["voxel"]


def _body_form(d, job, recipe, tp, name_of):
    """Add a tbss or hex job's form values (body, resolution; tbss periods and ranges, hex grid and
    element) to the form dict ``d``; returns nothing."""
    b = recipe.get("body") if isinstance(recipe.get("body"), dict) else {}
    d["body"] = name_of(b.get("path")) if b.get("kind") == "mesh" else b.get("kind")
    d["resolution"] = (recipe.get("mesh") or {}).get("resolution", _default(job, "resolution"))
    if job == "tbss":
        d["periods"] = tp.get("periods", list(_default(job, "periods")))
        tdf = recipe.get("tdf") or {}
        for k in ("porosity", "threshold"):
            r = tdf.get(f"{k}_range")
            if r:
                d.update(control=k, value=r[0], value_to=r[1], grading="none" if r[0] == r[1] else "axial")
    else:
        d["grid"] = recipe.get("grid", [2, 2, 2])
        d["element"] = recipe.get("element", _default(job, "element"))


def _tis_form(d, recipe, dom, name_of):
    """Add a tis job's form values (type, structure, relative density, resolution, lambda, body) to the
    form dict ``d``; returns nothing."""
    t = recipe.get("tis") or {}
    d.update(tis_type=t.get("type", "P"), tis_structure=t.get("structure", "pore"),
             relative=t.get("relative", 0.176),
             resolution=(recipe.get("mesh") or {}).get("resolution", _default("tis", "resolution")))
    d["lambda"] = t.get("lambda", _default("tis", "lambda"))
    if dom.get("kind") in BUILT_IN["tis"]:
        d["body"] = dom["kind"]
        d["size"] = dom.get("size", _default("tis", "size"))
    else:
        d["body"] = name_of(dom.get("path"))
        if "tets" in dom:
            d["tets"] = dom["tets"]


def _vessel_form(d, recipe, name_of):
    """Add a vessel job's form values (centreline, voxel, wall, porous layer) to the form dict ``d``;
    returns nothing."""
    inp = recipe.get("input") or {}
    d["centreline"] = name_of(inp.get("path"))
    d["voxel"] = recipe.get("voxel")
    d["wall"] = " ".join(str(x) for x in recipe.get("wall") or [])
    p = recipe.get("porous") or {}
    if p:
        d.update(porous_layer=p.get("layer", 0), type=p.get("type", "G"), porous_cell=p.get("cell_size", 0.6))
