"""The Python API: fields you compose, one polygoniser, the jobs as functions.

In the style of scikit-image's functional API and fogleman/sdf's field
algebra: a TPMS is a field, a structure (pore, rod, sheet) turns it into a
solid, ``&``, ``|`` and ``-`` combine solids with bodies, and
:func:`polygonise` turns any bounded solid into a closed triangle mesh. The
jobs (:func:`infill`, :func:`tbss`, :func:`hex_scaffold`, :func:`tis`,
:func:`arbf`, :func:`vessel`) run exactly what the command line runs and
return the mesh with its report.

Examples
--------
>>> import porecad as pc
>>> gyroid = pc.sheet(pc.tpms("G", cell_size=2.0), porosity=0.6)
>>> mesh = pc.polygonise(gyroid, bounds=([0, 0, 0], [4, 4, 4]), voxel=0.1)
>>> mesh.closed, round(1 - mesh.volume / 64.0, 2)
(True, 0.6)

The fields and solids (:func:`tpms`, :func:`pore`, :func:`rod`,
:func:`sheet`, :func:`box`, :func:`sphere`, :func:`disc`,
:func:`mesh_body`, :func:`expression`) are defined in
:mod:`porecad.api_fields` and exported here.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from .api_fields import box, disc, expression, mesh_body, pore, rod, sheet, sphere, tpms
from .errors import InputError
from .recipes.schema import default_of as _d  # every default below is the recipe schema's

__all__ = ["Mesh", "Scaffold", "tpms", "pore", "rod", "sheet", "box", "sphere", "disc", "mesh_body", "expression",
           "polygonise", "analyze", "save", "load", "run", "infill", "tbss", "hex_scaffold", "tis", "arbf", "vessel",
           "slice", "export"]


# ---------------------------------------------------------------------------------------------- meshes
@dataclasses.dataclass
class Mesh:
    """A triangle mesh: ``vertices`` (V, 3) float64 in mm and ``faces`` (F, 3) int, outward oriented.

    Unpacks as ``vertices, faces = mesh``.

    Examples
    --------
    >>> import porecad as pc
    >>> m = pc.polygonise(pc.sphere(5.0), voxel=0.5)
    >>> m.closed, abs(m.volume - 4 / 3 * 3.14159 * 125) < 0.02 * 523.6
    (True, True)
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __iter__(self):
        return iter((self.vertices, self.faces))

    @property
    def volume(self) -> float:
        """Enclosed volume (mm³; divergence theorem)."""
        from .mesh.validate import signed_volume
        return float(signed_volume(self.vertices, self.faces))

    @property
    def area(self) -> float:
        """Surface area (mm²)."""
        from .mesh.validate import surface_area
        return float(surface_area(self.vertices, self.faces))

    @property
    def bounds(self):
        """``(lo, hi)``: the axis-aligned bounding box."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    @property
    def closed(self) -> bool:
        """Closed, edge-manifold and consistently oriented (a printable solid's topology)."""
        from .mesh.topology import edge_topology
        t = edge_topology(self.faces)
        return bool(t["closed"] and t["manifold"] and t["oriented"])

    def to_trimesh(self):
        """The mesh as a :class:`trimesh.Trimesh` (no processing)."""
        import trimesh
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


@dataclasses.dataclass
class Scaffold(Mesh):
    """A mesh built by a job, with the job's ``report`` (dict, as ``--json`` prints it)."""

    report: dict = dataclasses.field(default_factory=dict)


# ---------------------------------------------------------------------------------------------- meshing
def polygonise(solid, voxel=None, bounds=None, resolution=None, threads=None) -> Mesh:
    """A closed, manifold, outward triangle mesh of ``{solid < 0}`` (chunked marching cubes).

    Parameters
    ----------
    solid : Field
        Negative inside. Bounded (a body, a box, or ``lattice & body``), or
        give ``bounds``.
    voxel : float, optional
        Sample spacing (mm).
    bounds : ((3,), (3,)), optional
        The box to mesh; the solid is cut flat and capped on its faces.
    resolution : int, optional
        Samples along the longest side instead of ``voxel`` (default 100).
    threads : int, optional
        Worker threads (default: all cores).

    Returns
    -------
    Mesh
    """
    from .errors import MeshError
    from .mesh.polygonise import Grid
    from .mesh.polygonise import polygonise as _mc
    from .resources import estimate, require_fits, work_estimate
    capped = bounds is not None
    if bounds is None:
        bounds = solid.bounds
        if bounds is None:
            raise InputError("the solid is unbounded (a lattice): intersect it with a body or a box, or give bounds")
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(hi > lo):
        raise InputError(f"bounds must be two points lo < hi, got {bounds!r}")
    if voxel is None:
        voxel = float((hi - lo).max()) / float(resolution or 100)
    elif resolution is not None:
        raise InputError("give voxel or resolution, not both")
    voxel = float(voxel)
    if not np.isfinite(voxel) or voxel <= 0:
        raise InputError(f"voxel must be positive, got {voxel!r}")
    if not capped:
        lo, hi = lo - 2 * voxel, hi + 2 * voxel
    with np.errstate(over="ignore"):
        counts = np.maximum(np.round((hi - lo) / voxel), 1) + 1
    require_fits(work_estimate(np.prod(counts), 0.0, sample_bytes=0.0), change="use a larger voxel")  # before a cast
    n = counts.astype(np.int64)
    grid = Grid.from_box(lo, hi, samples_per_axis=n)
    ext = hi - lo
    # a guard: the triangles of a lattice with cells of ~10 samples filling the box
    require_fits(estimate(grid, 10 * voxel, "sheet", float(np.prod(ext)),
                          float(2 * (ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2])), 16 << 20, threads or 2))
    res = _mc(solid.sample_grid, grid, caps=True, threads=threads)
    if len(res.faces) == 0:
        raise MeshError("the solid is empty at this voxel size")
    return Mesh(res.vertices, res.faces.astype(np.int64))


def analyze(mesh, domain=None, pores=False, voxel=None) -> dict:
    """Metrics of a mesh: validity, volume, area, porosity against a ``domain``; with ``pores`` sizes.

    Parameters
    ----------
    mesh : Mesh or (vertices, faces)
    domain : Field or Mesh, optional
        The design domain (a body or a box) the porosity refers to; default
        the mesh's bounding box.
    pores : bool
        Also pore and strut sizes, interconnectivity, permeability estimate.
    voxel : float, optional
        Voxel size for ``pores``.

    Returns
    -------
    dict
        As ``porecad analyze --json``.
    """
    from .analysis.report import analyze_arrays
    v, f = (np.asarray(a) for a in mesh)
    domain_volume = None
    if isinstance(domain, Mesh):
        domain_volume = domain.volume
    elif domain is not None:
        if hasattr(domain, "volume") and not callable(domain.volume):
            domain_volume = float(domain.volume)
        elif domain.bounds is not None and type(domain).__name__ == "Box":
            lo, hi = domain.bounds
            domain_volume = float(np.prod(hi - lo))
        else:
            raise InputError("domain must be a Mesh, a mesh body or a box")
    report, _ = analyze_arrays(v, f, domain_volume=domain_volume, pores=pores, voxel=voxel)
    return report


def properties(design, stiffness=True, permeability=True, E=1.0, nu=0.3, voxels=64, sweep=None,
               report=None, force=False) -> dict:
    """Homogenised stiffness, Darcy permeability and a porosity sweep of a design (``porecad properties``).

    Parameters
    ----------
    design : dict, str or os.PathLike
        A recipe of whole cells (dict, ``.toml``, ``.json``) or a closed mesh file.
    stiffness, permeability : bool
        What to compute: the 6 × 6 tensor by periodic voxel FE, the Darcy tensor by a Stokes solve.
    E, nu : float
        The solid's Young's modulus (MPa) and Poisson ratio.
    voxels : int
        Voxels along the cell's shortest edge.
    sweep : sequence of float, optional
        Porosities of a Gibson–Ashby sweep (recipes only).
    report : str or os.PathLike, optional
        Also write the report: ``.html`` the "Mechanics and flow" page
        (:func:`porecad.simulate.properties_page.properties_page`), else JSON.
    force : bool
        Replace an existing report file.

    Returns
    -------
    dict
        ``cell``, ``stiffness`` (``C_MPa``, ``engineering``, ``directional_modulus``,
        ``hashin_shtrikman``), ``permeability`` (``permeability_mm2``, ``tortuosity``,
        ``kozeny_carman_mm2``), ``sweep`` (``rows``, ``fit``, ``published``).

    References
    ----------
    L. J. Gibson, M. F. Ashby, *Cellular Solids*, 2nd ed., Cambridge University Press (1997).

    Examples
    --------
    >>> import porecad as pc
    >>> cell = {"job": "tpms", "domain": {"kind": "box", "cells": [1, 1, 1]},
    ...         "tpms": {"type": "G", "structure": "sheet", "porosity": 0.6}}
    >>> out = pc.properties(cell, stiffness=False, voxels=12)
    >>> k = out["permeability"]["permeability_mm2"]
    >>> bool(k[0][0] > 0 and abs(k[0][0] / k[2][2] - 1) < 1e-6)
    True
    """
    from .jobs.design_source import design_properties
    if report is not None:
        from .io.atomic import check_output_path
        check_output_path(report, force=force)
    out = design_properties(design, stiffness=stiffness, permeability=permeability, E=E, nu=nu,
                            voxels=voxels, sweep=sweep)
    if report is not None:
        from .simulate.properties_page import write_properties_report
        write_properties_report(report, out, force=force)
    return out


def volume_mesh(mesh, size=None, order=1) -> dict:
    """Tetrahedral volume mesh of a closed solid for FEA (``porecad volmesh``).

    Parameters
    ----------
    mesh : Mesh or (vertices, faces)
        Closed, manifold, free of self-intersections.
    size : float, optional
        Target element edge length (mm); default the mean surface edge length.
    order : {1, 2}
        Linear (C3D4) or quadratic (C3D10) tets.

    Returns
    -------
    dict
        ``points``, ``cells``, ``cell_type``, ``quality`` (dihedral angles,
        radius and aspect ratios), ``volume_error``; write it with
        :func:`porecad.simulate.tetmesh_solid.write_volume_mesh`.
    """
    from .simulate.tetmesh_solid import volume_mesh as _volume_mesh
    v, f = (np.asarray(a) for a in mesh)
    return _volume_mesh(v, f, size=size, order=order)


def save(mesh, path, force: bool = False, check_intersections: bool | None = None):
    """Write a mesh (STL, PLY, OBJ, 3MF by suffix) atomically, after checking it is a valid solid.

    Refuses an existing file unless ``force``; refuses a mesh that is not
    closed, manifold and outward (and, for up to 2 million triangles or
    when asked, one that intersects itself).
    """
    from .io import write_mesh
    from .jobs.outputs import validated_report
    v, f = (np.asarray(a) for a in mesh)
    check = len(f) <= 2_000_000 if check_intersections is None else bool(check_intersections)
    _, _, v = validated_report(v, f, check_intersections=check, what="the mesh")
    return write_mesh(path, v, f, force=force)


def load(path) -> Mesh:
    """Read a mesh file (STL, OBJ, PLY, OFF, 3MF) as a :class:`Mesh` (checked, not repaired)."""
    from .io import read_mesh
    v, f = read_mesh(path)
    return Mesh(v, f)


def slice(source, out, printer=None, pixel=None, layer=None, fmt=None, orient=None, strict=False,  # noqa: A001
          check=True, force=False, base=None, progress=None, scheduler=None, mesh_out=None, mesh_voxel=None,
          memory_limit=None) -> dict:
    """Slice a design for a printer (docs/printing.md); returns the report (findings in ``warnings``).

    ``source``: a recipe (dict or ``.toml``; tpms and infill are sliced from their field, other jobs from
    their mesh), a mesh file or a :class:`Mesh`. ``out``: ``.zip`` (PNG layers), ``.svg``, ``.cli``/``.clib``.
    ``printer``: a profile file (TOML), a preset's name (``"prusa-sl1"``), a dict of its keys, or None (a
    generic 50 µm DLP printer).
    ``orient``: None (as designed), ``"auto"`` (the least unsupported area of 26 directions) or a direction.
    ``scheduler``: a dask scheduler (``"local:4"``, ``"tcp://host:8786"``, a Client) for a field's layer bands.
    ``mesh_out``: also write the part's mesh as it is printed (turned by ``orient``): a mesh part's own
    triangles, a field part meshed at ``mesh_voxel`` (default 4 pixels).
    ``memory_limit``: bytes the slicing may use (default: 80 % of the available memory); slices estimated
    larger are refused before any work.
    """
    from .findings import report_fields
    from .io import check_output_path
    from .printing import Printer, from_source, load_printer, printer_from_dict, slice_to
    from .printing.part import Part
    if printer is None:
        prof = Printer()
    elif isinstance(printer, dict):
        prof = printer_from_dict(printer)
    else:
        prof = load_printer(printer)
    check_output_path(out, force=force)
    from .printing.formats import format_of
    from .printing.raster import check_size
    format_of(out, fmt, prof.format)  # every check before the design is planned (a body's calibration: a while)
    if mesh_out is not None:
        check_output_path(mesh_out, force=force)
    if pixel is not None:  # None: the profile's pixel_x and pixel_y; a number: both; a pair: x and y
        from .printing.slicing import pixel_sizes
        pixel = pixel_sizes(prof, pixel)
    layer = check_size("the layer height", prof.layer if layer is None else layer)
    if isinstance(source, Mesh):
        import trimesh
        m = trimesh.Trimesh(source.vertices, source.faces, process=False)
        part = Part(m.bounds[0], m.bounds[1], mesh=m)
    else:
        if not isinstance(source, dict) and os.path.realpath(source) == os.path.realpath(out):
            raise InputError(f"{out} is the input: refusing to overwrite it")
        part = from_source(source, base)
    import contextlib

    from .io.atomic import output_set
    with output_set() if mesh_out is not None else contextlib.nullcontext():  # both files, or neither
        report = slice_to(part, out, prof, pixel=pixel, layer=layer, fmt=fmt, orient=orient, force=force,
                          strict=strict, check=check, progress=progress, scheduler=scheduler,
                          keep_part=mesh_out is not None, memory_limit=memory_limit)
        if mesh_out is not None:
            printed = report.pop("part")
            if printed.mesh is not None:
                m = Mesh(np.asarray(printed.mesh.vertices), np.asarray(printed.mesh.faces))
            else:
                m = polygonise(printed.field, voxel=mesh_voxel or 4 * report["pixel"], bounds=(printed.lo, printed.hi))
            report["mesh_file"] = str(save(m, mesh_out, force=force))
    report.update(report_fields(report["warnings"]))
    return report


def export(recipe, path, implicit: bool = True, force: bool = False, base=None) -> dict:
    """Write a tpms or infill recipe's design (a dict or ``.toml``) as an implicit 3MF (docs/printing.md).

    The TPMS, structure, threshold (a porosity resolved by porecad's calibration) and domain become a
    3MF Volumetric & Implicit function graph and level set; needs ``porecad[3mf]`` (lib3mf 2.5).
    Returns the report (``file``, ``bytes``, ``nodes``, ``threshold``, ...).
    """
    if not implicit:
        raise InputError("export writes the implicit 3MF only (implicit=True); save() writes a mesh")
    from .jobs.implicit_export import export_implicit
    return export_implicit(recipe, path, base=base, force=force)


# ---------------------------------------------------------------------------------------------- jobs
def run(recipe: dict, base=None, threads=None) -> Scaffold:
    """Run a recipe's job and return its mesh and report without writing anything.

    Examples
    --------
    >>> import porecad as pc
    >>> s = pc.run({"job": "tis", "domain": {"kind": "regular-tet"}, "tis": {"type": "P", "relative": 0.176},
    ...             "mesh": {"resolution": 24}})
    >>> s.closed and 0.4 < s.report["porosity"] < 0.5
    True
    """
    from .jobs import run_in_memory
    return Scaffold(*run_in_memory(recipe, base=base, threads=threads))


def _clean(d: dict) -> dict:
    return {k: v for k, v in d.items() if v is not None}


def infill(body, type, porosity=None, threshold=None, structure=_d("infill", "tpms.structure"),  # noqa: A002
           cell_size=_d("infill", "tpms.cell_size"), boundary=_d("infill", "domain.boundary"), skin=None, voxel=None,
           **tables) -> Scaffold:
    """Fill a body (mesh or image file) with a TPMS scaffold: job ``infill`` (see ``porecad infill --help``).

    ``porosity`` and ``threshold`` take a number or an expression string in
    ``x, y, z, d, dn``; extra recipe tables (``grading``, ``analysis``) as keywords.
    """
    tp = _clean({"type": type, "structure": structure, "cell_size": cell_size})
    rec = {"job": "infill", "tpms": tp,
           "domain": _clean({"kind": "mesh", "path": str(body), "boundary": boundary, "skin": skin}),
           "sampling": _clean({"voxel": voxel})}
    for key, value in (("porosity", porosity), ("threshold", threshold)):
        if isinstance(value, str):
            rec["grading"] = {"kind": "expression", "of": key, "expr": value}
        elif value is not None:
            tp[key] = value
    rec.update(tables)
    return run(rec)


def tbss(body="disc", type="G", structure=_d("tbss", "tpms.structure"), periods=_d("tbss", "tpms.periods"),  # noqa: A002
         tdf=_d("tbss", "tdf.method"), resolution=_d("tbss", "mesh.resolution"), **tables) -> Scaffold:
    """A heterogeneous TPMS scaffold in a trivariate B-spline solid (document 001): job ``tbss``.

    ``body``: ``"disc"``, ``"box"``, ``"cylinder"``, ``"tube"`` or a mesh file; ``tdf``:
    ``"layer"``, ``"fill"`` or an expression in ``u, v, w``.
    """
    b = {"kind": body} if body in ("disc", "box", "cylinder", "tube") else {"kind": "mesh", "path": str(body)}
    t = {"method": tdf} if tdf in ("layer", "fill") else {"method": "function", "expr": tdf}
    rec = {"job": "tbss", "body": b, "tpms": {"type": type, "structure": structure, "periods": list(periods)},
           "tdf": t, "mesh": {"resolution": resolution}}
    for k, v in tables.items():
        rec[k] = {**rec.get(k, {}), **v} if isinstance(v, dict) else v
    return run(rec)


def hex_scaffold(body, type, grid, threshold=None, porosity=None, structure=_d("hex", "tpms.structure"),  # noqa: A002
                 element=_d("hex", "element"), resolution=_d("hex", "mesh.resolution"), **tables) -> Scaffold:
    """TPMS cells mapped into a hexahedral mesh (000 ch.3, 004): job ``hex``.

    ``body``: ``"frustum"``, ``"cylinder"``, a closed surface mesh file or a hex-mesh file.
    """
    from .volmesh import is_volume_mesh_path
    if body in ("frustum", "cylinder"):
        b = {"kind": body}
    else:
        b = {"kind": "hexfile" if is_volume_mesh_path(body) else "mesh", "path": str(body)}
    rec = {"job": "hex", "body": b, "tpms": _clean({"type": type, "structure": structure, "threshold": threshold,
                                                    "porosity": porosity}),
           "element": element, "mesh": {"resolution": resolution}, **tables}
    if grid is not None:
        rec["grid"] = list(grid)
    return run(rec)


def tis(domain="regular-tet", type="P", relative=None, threshold=None, resolution=None, tets=None,  # noqa: A002
        **tables) -> Scaffold:
    """Tetrahedral implicit surfaces over a tet mesh (002, 000 ch.4): job ``tis``.

    ``domain``: ``"regular-tet"``, ``"two-tets"``, ``"icosahedron"``, a tet-mesh file or a closed surface.
    """
    from .volmesh import is_volume_mesh_path
    if domain in ("regular-tet", "two-tets", "icosahedron"):
        d = {"kind": domain}
    else:
        d = _clean({"kind": "tet-mesh" if is_volume_mesh_path(domain) else "body", "path": str(domain),
                    "tets": tets})
    rec = {"job": "tis", "domain": d, "tis": _clean({"type": type, "relative": relative, "threshold": threshold}),
           "mesh": _clean({"resolution": resolution}), **tables}
    return run(rec)


def arbf(domain=_d("arbf", "domain.kind"), basis=_d("arbf", "arbf.basis"), shape=_d("arbf", "arbf.shape"),
         iso=_d("arbf", "arbf.iso"), local=_d("arbf", "arbf.local"), resolution=_d("arbf", "mesh.resolution"),
         **tables) -> Scaffold:
    """Anisotropic-RBF pore networks (000 ch.5): job ``arbf``.

    ``domain``: a built-in mesh (``"tet"``, ``"hex"``, ...), a volume mesh file or a closed surface.
    """
    from .jobs.arbf_job import BUILTIN_HEX, BUILTIN_TET
    from .volmesh import is_volume_mesh_path
    if domain in BUILTIN_TET + BUILTIN_HEX:
        d = {"kind": domain}
    else:
        d = {"kind": "mesh-file" if is_volume_mesh_path(domain) else "body", "path": str(domain)}
    rec = {"job": "arbf", "domain": d, "arbf": {"basis": basis, "shape": shape, "iso": iso, "local": local},
           "mesh": {"resolution": resolution}, **tables}
    return run(rec)


def vessel(centreline, voxel, wall=None, porous=None, blend=_d("vessel", "blend"), **keys) -> Scaffold:
    """An implicit vessel model or porous graft from a centreline file (003): job ``vessel``.

    ``wall``: layer thicknesses (mm); ``porous``: ``{"layer": K, "type": "G", "cell_size": L}``.
    """
    rec = _clean({"job": "vessel", "input": {"kind": "centreline", "path": str(centreline)}, "voxel": voxel,
                  "blend": blend, "wall": list(wall) if wall else None, "porous": porous, **keys})
    return run(rec)
