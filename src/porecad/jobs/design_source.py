"""A design as the simulation needs it: the ``properties`` job and the source of ``porecad volmesh``.

A source is a recipe (a dict, ``.toml`` or ``.json``) or a closed mesh file.
A TPMS recipe of a box of whole cells is an exactly periodic unit cell: its
field is voxelised directly (:func:`periodic_cell`,
:func:`porecad.simulate.cell_voxels.field_cell_voxels`). Any other source is
turned into a mesh (a recipe runs through its job, :func:`run_in_memory`)
and voxelised over its bounding box. The mechanics and flow themselves
(arrays in) are in :mod:`porecad.simulate.properties`; this module is the
jobs layer's part: it plans and runs recipes, so ``simulate`` does not.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ..errors import InputError, ResourceError
from ..resources import memory_budget
from ..simulate.cell_voxels import field_cell_voxels, mesh_voxels
from ..simulate.elastic_tensors import GIBSON_ASHBY_PUBLISHED, engineering_constants, gibson_ashby_fit
from ..simulate.homogenise import check_moduli, estimate_stiffness_memory, homogenise_stiffness
from ..simulate.properties import permeability_properties, stiffness_properties
from ..simulate.stokes import estimate_stokes_memory

__all__ = ["load_source", "solid_mesh_of", "periodic_cell", "recipe_cell_voxels", "cell_of", "porosity_sweep",
           "design_properties"]

_MAX_RECIPE_BYTES = 1 << 20


def load_source(source) -> dict:
    """A recipe (dict, ``.toml`` or ``.json`` file) or a mesh file, as ``{"kind", "recipe" | "path"}``."""
    if isinstance(source, dict):
        return {"kind": "recipe", "recipe": source, "name": "recipe"}
    p = Path(os.fspath(source))
    if not p.exists():
        raise InputError(f"{p}: no such file (give a closed mesh or a recipe .toml/.json)")
    if p.suffix.lower() == ".toml":
        from porecad.io.recipe import load_recipe
        return {"kind": "recipe", "recipe": load_recipe(p), "name": str(p), "base": str(p.resolve().parent)}
    if p.suffix.lower() == ".json":
        from ..io.confine import regular_file
        if regular_file(p, "a recipe") > _MAX_RECIPE_BYTES:
            raise InputError(f"{p}: a recipe file larger than 1 MiB is not a recipe")
        try:
            recipe = json.loads(p.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{p}: not a JSON recipe ({' '.join(str(exc).split())})") from None
        if not isinstance(recipe, dict):
            raise InputError(f"{p}: a JSON recipe must be an object")
        return {"kind": "recipe", "recipe": recipe, "name": str(p), "base": str(p.resolve().parent)}
    return {"kind": "mesh", "path": str(p), "name": str(p)}


def _is_periodic_recipe(recipe: dict) -> bool:
    dom = dict(recipe.get("domain", {"kind": "box"}))
    return recipe.get("job", "tpms") == "tpms" and dom.get("kind", "box") == "box" and not recipe.get("grading")


def solid_mesh_of(src: dict, progress=None):
    """The closed surface of a source: a mesh file read, or a recipe run through its job.

    Returns
    -------
    vertices, faces, info : arrays and a dict (the build report of a recipe)
    """
    from ..io import read_mesh

    if src["kind"] == "mesh":
        v, f = read_mesh(src["path"])
        return np.asarray(v, float), np.asarray(f, np.int64), {"source": src["path"]}
    from . import run_in_memory

    v, f, report = run_in_memory(src["recipe"], base=src.get("base"))  # any job, through the registry
    return np.asarray(v, float), np.asarray(f, np.int64), {"source": src["name"], "build": report}


def periodic_cell(recipe: dict) -> dict:
    """The periodic field of a TPMS recipe's box of whole cells: ``field``, ``lo``, ``hi`` and ``info``.

    ``info``: ``box`` (mm extent), ``type``, ``structure``, ``threshold``.
    Raises :class:`InputError` for a recipe that is not a tpms job on a box domain.
    """
    from .tpms_job import plan_tpms

    if recipe.get("job", "tpms") != "tpms":
        raise InputError(f"a periodic cell comes from a tpms recipe; this one is job {recipe.get('job')!r} "
                         "(give its mesh instead)")
    domain = dict(recipe.get("domain", {"kind": "box", "cells": [1, 1, 1]}))
    if domain.get("kind", "box") != "box":
        raise InputError("a periodic cell needs a box domain of whole cells (domain.kind = \"box\")")
    plan = plan_tpms(recipe)
    lo, hi = plan.grid.box_min, plan.grid.box_max
    info = {"box": (hi - lo).tolist(), "type": plan.type.name, "structure": plan.structure,
            "threshold": plan.threshold_info.get("threshold")}
    return {"field": plan.field, "lo": lo, "hi": hi, "info": info}


def recipe_cell_voxels(recipe: dict, voxels: int):
    """Solid mask of a TPMS recipe's box of whole cells, exactly periodic: ``(solid, voxel, info)``."""
    cell = periodic_cell(recipe)
    solid, h = field_cell_voxels(cell["field"], cell["lo"], cell["hi"], voxels)
    return solid, h, cell["info"]


def cell_of(src: dict, voxels: int, progress=None) -> dict:
    """The voxel cell of a source: ``solid`` mask [z, y, x], ``voxel`` (mm), ``periodic``, and the surface stats."""
    from ..mesh.validate import signed_volume, surface_area

    voxels = int(voxels)
    if voxels < 4 or voxels > 512:
        raise InputError(f"voxels per cell edge must lie in 4..512, got {voxels}")
    if src["kind"] == "recipe" and _is_periodic_recipe(src["recipe"]):
        solid, h, info = recipe_cell_voxels(src["recipe"], voxels)
        # surface statistics for the Kozeny-Carman estimate come from the built mesh
        v, f, binfo = solid_mesh_of(src, progress)
        return {"solid": solid, "voxel": h, "periodic": True, "info": info,
                "mesh_volume": float(signed_volume(v, f)), "mesh_area": float(surface_area(v, f)),
                "box_volume": float(np.prod(info["box"]))}
    v, f, binfo = solid_mesh_of(src, progress)
    solid, h, origin = mesh_voxels(v, f, voxels)
    ext = np.ptp(v, axis=0)
    return {"solid": solid, "voxel": h, "periodic": False, "info": {"box": ext.tolist()},
            "mesh_volume": float(signed_volume(v, f)), "mesh_area": float(surface_area(v, f)),
            "box_volume": float(np.prod(ext))}


def porosity_sweep(recipe: dict, porosities, voxels: int, E: float, nu: float, progress=None) -> dict:
    """Relative modulus against relative density over a porosity sweep, with the Gibson–Ashby fit.

    Parameters
    ----------
    recipe : dict
        A periodic TPMS recipe (box of whole cells); its ``tpms.porosity`` is
        replaced by each value of the sweep (threshold through the type's
        calibration curve).
    porosities : sequence of float
        At most 12 values in (0, 1).
    voxels : int
    E, nu : float

    Returns
    -------
    dict
        ``rows`` (porosity, relative density, E1..E3 / E, mean relative
        modulus, G12 / E, Zener ratio, or an ``error`` for a point outside
        the valid range or without a load path), ``fit``
        (:func:`~porecad.simulate.elastic_tensors.gibson_ashby_fit`) and
        ``published`` (exponents from the literature, with sources).
    """
    E, nu = check_moduli(E, nu)
    ps = [float(p) for p in porosities]
    if not ps or len(ps) > 12 or any(not 0 < p < 1 for p in ps):
        raise InputError("a porosity sweep takes 1 to 12 porosities in (0, 1)")
    if not _is_periodic_recipe(recipe):
        raise InputError("a porosity sweep needs a tpms recipe on a box of whole cells (a periodic cell)")
    rows = []
    for p in ps:
        rec = json.loads(json.dumps(recipe))
        tp = rec.setdefault("tpms", {})
        tp.pop("threshold", None)
        tp["porosity"] = p
        try:
            solid, h, info = recipe_cell_voxels(rec, voxels)
            res = homogenise_stiffness(np.where(solid, 0, -1).astype(np.int32), h, [(E, nu)], progress=progress)
            eng = engineering_constants(res["C"])
            rows.append({"porosity": p, "relative_density": float(solid.mean()),
                         "E1_rel": eng["E1"] / E, "E2_rel": eng["E2"] / E, "E3_rel": eng["E3"] / E,
                         "relative_modulus": float(np.mean([eng["E1"], eng["E2"], eng["E3"]]) / E),
                         "G12_rel": eng["G12"] / E, "zener_ratio": eng["zener_ratio"],
                         "threshold": info.get("threshold")})
        except InputError as exc:
            rows.append({"porosity": p, "error": str(exc)})
    good = [r for r in rows if "error" not in r]
    fit = None
    if len(good) >= 2:
        fit = gibson_ashby_fit([r["relative_density"] for r in good], [r["relative_modulus"] for r in good])
    return {"rows": rows, "fit": fit, "published": GIBSON_ASHBY_PUBLISHED}


def design_properties(source, stiffness: bool = True, permeability: bool = True, E: float = 1.0,
                      nu: float = 0.3, voxels: int = 64, sweep=None, block: bool = False, progress=None,
                      memory_limit: int | None = None) -> dict:
    """Stiffness, permeability and a porosity sweep of a design (the ``properties`` job).

    Parameters
    ----------
    source : dict, str or os.PathLike
        A recipe (dict, ``.toml``, ``.json``) or a closed mesh file.
    stiffness, permeability : bool
        What to compute.
    E, nu : float
        The solid's Young's modulus (MPa) and Poisson ratio.
    voxels : int
        Voxels along the cell's shortest edge.
    sweep : sequence of float, optional
        Porosities of a Gibson–Ashby sweep (periodic recipes only).
    block : bool
        Treat the cell as a non-periodic sample block for the permeability.
    progress : callable(stage, done, total), optional
    memory_limit : int, optional

    Returns
    -------
    dict
        ``source``, ``cell`` (grid, voxel, periodic, porosity), and
        ``stiffness`` / ``permeability`` / ``sweep`` sections.

    Raises
    ------
    InputError, MeshError, ResourceError
        Bad input (one line), an open mesh, or a job too large (refused with
        the estimate before any voxelisation).

    Examples
    --------
    A gyroid sheet cell at 60 % porosity (about 10 s)::

        rec = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.6},
               "domain": {"kind": "box", "cells": [1, 1, 1]}}
        out = design_properties(rec, voxels=16, E=1000.0, nu=0.3)
        out["stiffness"]["engineering"]["E1"]   # 173 (MPa): well below the solid's 1000
    """
    t0 = time.perf_counter()
    if not (stiffness or permeability or sweep):
        raise InputError("ask for stiffness, permeability or a sweep")
    E, nu = check_moduli(E, nu)
    src = load_source(source)
    voxels = int(voxels)
    # refuse up front: the estimate for a cube of `voxels` (a longer box only adds to it)
    limit = memory_budget(memory_limit)
    shape = (voxels,) * 3
    need = max(estimate_stiffness_memory(shape) if stiffness or sweep else 0,
               estimate_stokes_memory((2 * voxels if block else voxels,) + shape[1:]) if permeability else 0)
    if need > 0.8 * limit:
        raise ResourceError(f"properties job too large for this machine: {voxels}^3 voxels need about "
                            f"{need / 2**30:.1f} GiB, {limit / 2**30:.1f} GiB available; use fewer voxels")
    out = {"source": src["name"], "solid_E_MPa": E, "solid_nu": nu}
    if stiffness or permeability:
        cell = cell_of(src, voxels, progress)
        solid = cell["solid"]
        out["cell"] = {"grid": list(solid.shape[::-1]), "voxel_mm": cell["voxel"], "periodic": cell["periodic"],
                       "porosity_voxel": float(1 - solid.mean()), "box_mm": cell["info"]["box"]}
        if not cell["periodic"]:
            out["cell"]["note"] = ("the mesh's bounding box is treated as the cell: periodic boundary "
                                   "conditions for the stiffness" + (", a mirrored sample block for the flow"
                                                                     if block else ""))
        if stiffness:
            out["stiffness"] = stiffness_properties(solid, cell["voxel"], E, nu, progress)
        if permeability:
            out["permeability"] = permeability_properties(solid, cell["voxel"], block=block, progress=progress,
                                                          mesh_area=cell["mesh_area"],
                                                          mesh_volume=cell["mesh_volume"])
    if sweep:
        if src["kind"] != "recipe":
            raise InputError("a porosity sweep needs a recipe (the porosity is a design parameter)")
        out["sweep"] = porosity_sweep(src["recipe"], sweep, voxels, E, nu, progress)
    out["time_s"] = time.perf_counter() - t0
    return out
