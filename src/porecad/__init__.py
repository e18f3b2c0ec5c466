"""porecad: porous tissue-engineering scaffolds and implicit vascular models as watertight, printable meshes.

Compose fields and mesh them::

    import porecad as pc
    gyroid = pc.sheet(pc.tpms("G", cell_size=2.0), porosity=0.6)
    mesh = pc.polygonise(gyroid, bounds=([0, 0, 0], [4, 4, 4]), voxel=0.05)
    pc.save(mesh, "gyroid.stl")

or run any job (what every ``porecad`` command runs) from its recipe with
:func:`run_recipe`, or as a function (:func:`infill`, :func:`tbss`,
:func:`hex_scaffold`, :func:`tis`, :func:`arbf`, :func:`vessel`); simulate a design with
:func:`properties` (stiffness, permeability) and :func:`volume_mesh` (tets for FEA).

The names are loaded on first use (PEP 562), so that ``porecad`` the command
starts, and handles Ctrl-C, before numpy and the rest are imported.
"""

from .version import __version__

_API = ("Mesh", "Scaffold", "analyze", "arbf", "box", "disc", "export", "expression", "hex_scaffold", "infill",
        "load", "mesh_body", "polygonise", "pore", "properties", "rod", "run", "save", "sheet", "slice", "sphere",
        "tbss", "tis", "tpms", "vessel", "volume_mesh")
_ERRORS = ("InputError", "MeshError", "OutputError", "PorecadError", "RangeError", "RecipeError", "ResourceError")
_JOBS = ("run_recipe", "run_recipe_file")

__all__ = ["__version__", "Mesh", "Scaffold", "tpms", "pore", "rod", "sheet", "box", "sphere", "disc", "mesh_body",
           "expression", "polygonise", "analyze", "save", "load", "run", "run_recipe", "run_recipe_file", "infill",
           "tbss", "hex_scaffold", "tis", "arbf", "vessel", "properties", "volume_mesh", "slice", "export",
           "PorecadError", "InputError", "RecipeError", "RangeError", "ResourceError", "OutputError", "MeshError"]


def __getattr__(name):
    import importlib
    module = "api" if name in _API else "errors" if name in _ERRORS else "jobs" if name in _JOBS else None
    if module is None:
        raise AttributeError(f"module 'porecad' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
