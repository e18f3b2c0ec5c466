"""The lattice commands: ``porecad tpms``, ``porecad infill``, ``porecad demo`` and ``porecad build``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ..errors import InputError, OutputError
from .console import run_job
from .options import (check_intersections_option, given_only, islands_option, keyed_in, max_memory_option,
                      output_options, outputs,
                      scale_options, strict_option, threads_option, with_scale)

tpms_option = keyed_in("tpms")
infill_option = keyed_in("infill")

EXAMPLES_TPMS = """
\b
Examples:
  porecad tpms G --structure sheet --porosity 0.6 --cells 2 2 2 --cell-size 2 --resolution 40 -o gyroid.stl
  porecad tpms P --structure pore --threshold 0 --cells 1 1 1 --cell-size 1 --resolution 200 --json
  porecad tpms P --structure surface --threshold 0 --resolution 100 -o p_surface.stl
  porecad tpms G --porosity 0.7 --cells 4 4 4 --resolution 150 --scheduler local:2 --stream -o big.stl
  porecad tpms --list --json
"""


def number_or_expression(text, name):
    """A CLI value that is a number or a grading expression: (number, None) or (None, expr)."""
    if text is None:
        return None, None
    try:
        return float(text), None
    except ValueError:
        if not str(text).strip():
            raise InputError(f"--{name} is empty") from None
        return None, str(text)


def tpms_table(tpms_type, structure, threshold, porosity, cell_size, allow_closed_pores=False,
               porosity_points=None, porosity_map=None, map_scale=1.0, map_offset=0.0, cell_size_ramp=None,
               ramp_axis="z"):
    """The recipe's [tpms] table (and [grading], or None) from CLI options, after the shared checks.

    ``--threshold``/``--porosity`` take a number or an expression in x, y, z
    (and d, dn inside a body); ``--porosity-points`` a CSV for a thin-plate
    RBF; ``--porosity-map`` an image.
    """
    c_val, c_expr = number_or_expression(threshold, "threshold")
    p_val, p_expr = number_or_expression(porosity, "porosity")
    given = [x for x in (threshold, porosity, porosity_points, porosity_map) if x is not None]
    if len(given) > 1:
        raise InputError("give either --threshold, --porosity, --porosity-points or --porosity-map, not several")
    if len(cell_size) not in (1, 3):
        raise InputError("--cell-size takes one value or three (repeat the option)")
    tp = {"type": tpms_type, "structure": structure,
          "cell_size": cell_size[0] if len(cell_size) == 1 else list(cell_size)}
    if cell_size_ramp is not None:
        tp["cell_size"] = {"kind": "linear", "axis": ramp_axis, "from": cell_size_ramp[0],
                           "to": cell_size_ramp[1]}
    grading = None
    if c_val is not None:
        tp["threshold"] = c_val
    elif p_val is not None:
        tp["porosity"] = p_val
    elif c_expr is not None:
        grading = {"kind": "expression", "of": "threshold", "expr": c_expr}
    elif p_expr is not None:
        grading = {"kind": "expression", "of": "porosity", "expr": p_expr}
    elif porosity_points is not None:
        grading = {"kind": "points", "of": "porosity", "file": str(porosity_points)}
    elif porosity_map is not None:  # none given: the job's schema says which to give
        grading = {"kind": "image", "of": "porosity", "path": str(porosity_map), "scale": map_scale,
                   "offset": map_offset}
    if allow_closed_pores:
        tp["allow_closed_pores"] = True
    return tp, grading


def tpms_recipe(tpms_type, structure, threshold, porosity, cell_size, cells, resolution, voxel, out=None,
                smooth="none", smooth_iterations=10, decimate=0.0, report=None, recipe_out=None,
                allow_closed_pores=False) -> dict:
    """The recipe of a ``porecad tpms`` command line."""
    tp, grading = tpms_table(tpms_type, structure, threshold, porosity, cell_size, allow_closed_pores)
    sampling = {"voxel": voxel} if voxel is not None else {"resolution": resolution}
    recipe = {"job": "tpms", "tpms": tp, "domain": {"kind": "box", "cells": list(cells)},
              "sampling": sampling,
              "post": {"smooth": smooth, "smooth_iterations": smooth_iterations, "decimate": decimate},
              "output": outputs(out, report, recipe_out)}
    if grading:
        recipe["grading"] = grading
    return recipe


@click.command(epilog=EXAMPLES_TPMS)
@click.argument("tpms_type", metavar="TYPE", required=False)
@tpms_option("tpms.structure", "--structure",
       help="pore (material φ ≥ C), rod (φ ≤ C), sheet (|φ| ≤ C) or surface (open φ = C).")
@tpms_option(("tpms.threshold", "grading.expr"), "--threshold", "-c",
       help="Threshold C (a number, or an expression in x, y, z).")
@tpms_option(("tpms.porosity", "grading.expr"), "--porosity", "-p",
              help="Target porosity (void fraction 0-1; a number or an expression in x, y, z); solves for C.")
@tpms_option("tpms.cell_size", "--cell-size", "-L", type=float, multiple=True,
       help="Cell size in mm (repeat three times for x, y, z).")
@tpms_option("domain.cells", "--cells", nargs=3, type=int, help="Cells NX NY NZ.")
@tpms_option("sampling.resolution", "--resolution", "-n", type=int, help="Samples per cell edge (both ends included).")
@tpms_option("sampling.voxel", "--voxel", type=float, help="Sample spacing in mm (instead of --resolution).")
@click.option("--list", "list_types", is_flag=True, help="List the TPMS types.")
@tpms_option("post.smooth", "--smooth", help="Smoothing (004 eqs. 4-5; Taubin keeps volume).")
@tpms_option("post.smooth_iterations", "--smooth-iterations", type=int)
@tpms_option("post.decimate", "--decimate", type=float, help="Decimation tolerance in mm (keeps it closed).")
@output_options()
@threads_option
@check_intersections_option
@tpms_option("tpms.allow_closed_pores", "--allow-closed-pores", is_flag=True,
              help="Build outside the valid range (closed pores, floating pieces); the report says so.")
@scale_options
def tpms(tpms_type, structure, threshold, porosity, cell_size, cells, resolution, voxel, list_types, smooth,
         smooth_iterations, decimate, out, report, recipe_out, force, as_json, threads, check_intersections,
         allow_closed_pores, scheduler, stream, zarr_path, retries, chunk_mb, max_output):
    """Build a TPMS scaffold (pore, rod, sheet solid or bare surface) in a box of cells."""
    from ..fields.tpms import list_types as catalogue
    if list_types:
        types = catalogue()
        if as_json:
            from ..calibration import valid_range
            for t in types:
                t["valid_range"] = {s: valid_range(t["name"], s) for s in ("pore", "rod", "sheet")}
            click.echo(json.dumps(types))
        else:
            for t in types:
                click.echo(f"{t['name']:>15}  {t['title']}: {t['formula']}")
        return
    if not tpms_type:
        raise InputError("give a TPMS TYPE (see `porecad tpms --list`)")
    recipe = tpms_recipe(tpms_type, structure, threshold, porosity, cell_size, cells, resolution, voxel,
                          out, smooth, smooth_iterations, decimate, report, recipe_out, allow_closed_pores)
    recipe = with_scale(recipe, scheduler, stream, zarr_path, retries, chunk_mb, max_output)
    run_job(recipe, force, as_json, threads=threads, check_intersections=check_intersections)


@click.command()
@click.argument("body", type=click.Path())
@click.argument("tpms_type")
@infill_option("tpms.structure", "--structure", type=click.Choice(["pore", "rod", "sheet"], case_sensitive=False),
       help="Solid structure.")
@infill_option(("tpms.threshold", "grading.expr"), "--threshold", "-c",
              help="Threshold C: a number, or an expression in x, y, z, d (depth, mm) and dn (d / max depth).")
@infill_option(("tpms.porosity", "grading.expr"), "--porosity", "-p",
              help="Target porosity: a number, or an expression in x, y, z, d, dn, e.g. '0.5 + 0.3 * dn'.")
@infill_option("grading.file", "--porosity-points", type=click.Path(dir_okay=False),
              help="CSV of x, y, z, porosity rows: thin-plate RBF grading.")
@infill_option("grading.path", "--porosity-map", type=click.Path(),
       help="Image whose values (x scale + offset) are the porosity.")
@infill_option("grading.scale", "--map-scale", type=float, help="Scale of --porosity-map values.")
@infill_option("grading.offset", "--map-offset", type=float, help="Offset of --porosity-map values.")
@infill_option("tpms.cell_size", "--cell-size-ramp", default=None, nargs=2, type=float,
              help="Cell size L0 L1 (mm) ramping along --ramp-axis over the body (lattice kept continuous).")
@infill_option("tpms.cell_size.axis", "--ramp-axis")
@infill_option("analysis.regions", "--regions", type=int,
              help="Per-region porosity report: N depth shells and N slabs (default 5 when graded, else 0).")
@infill_option("analysis.region_axis", "--region-axis", help="Slab axis (default: longest).")
@infill_option("tpms.cell_size", "--cell-size", "-L", type=float, multiple=True,
       help="Cell size in mm (once, or three times for x y z).")
@infill_option("sampling.voxel", "--voxel", type=float,
              help="Sample spacing in mm (default for a body: cell / 20 or its smallest extent / 50, whichever is "
                   "smaller, at least that extent / 200 while that keeps the samples per cell its design needs).")
@infill_option("domain.boundary", "--boundary", help="cut: lattice ∩ body; skin: plus a solid shell; whole: only complete cells.")
@infill_option("domain.skin", "--skin", type=float, help="Shell thickness in mm (skin).")
@output_options()
@threads_option
@check_intersections_option
@infill_option("tpms.allow_closed_pores", "--allow-closed-pores", is_flag=True, help="Build outside the valid range.")
@infill_option("domain.label", "--label", type=float, help="Image body: the voxel value of the body in a label map.")
@infill_option("domain.threshold", "--body-threshold", type=float,
              help="Image body: intensity threshold (body = voxels >= it), e.g. 300 HU for bone.")
@infill_option("domain.keep_all", "--keep-all-components", is_flag=True,
              help="Image body by threshold: keep every connected piece (default: the largest).")
@infill_option("domain.units", "--units", default=None, help="Units of the body mesh, scaled to mm on load (default mm; CAD exports are often in m).")
@scale_options
def infill(body, tpms_type, structure, threshold, porosity, porosity_points, porosity_map, map_scale, map_offset,
           cell_size_ramp, ramp_axis, regions, region_axis, cell_size, voxel, boundary, skin, out, report,
           recipe_out, force, as_json, threads, check_intersections, allow_closed_pores, label, body_threshold,
           keep_all_components, units, scheduler, stream, zarr_path, retries, chunk_mb, max_output):
    """Fill a body (a mesh, or an image) with a TPMS scaffold.

    BODY is a mesh (STL, OBJ, PLY, OFF, 3MF) or an image (NIfTI, MHA/MHD,
    NRRD, a DICOM series directory) with --label or --body-threshold; image
    bodies keep the image's physical coordinates (spacing, origin, direction).

    \b
    Examples:
      porecad infill femur.stl G --structure pore --threshold 0 --cell-size 5 -o femur_gyroid.stl
      porecad infill disc.stl G --porosity 0.7 --boundary skin --skin 0.8 -o disc.stl --json
      porecad infill tooth.obj P --porosity 0.6 --boundary whole --cell-size 2 -o tooth.3mf
      porecad infill ct_series/ G --body-threshold 300 --porosity 0.7 -L 3 -o bone.stl
      porecad infill femur.stl G --porosity "0.5 + 0.3 * dn" -L 5 -o graded.stl --json

    The body is checked and repaired where possible (the report lists what
    changed); `porosity` in the report is the void fraction of the body.
    """
    tp, grading = tpms_table(tpms_type, structure, threshold, porosity, cell_size, allow_closed_pores,
                             porosity_points, porosity_map, map_scale, map_offset, cell_size_ramp or None,
                             ramp_axis)
    domain = given_only({"kind": "mesh", "path": str(body), "boundary": boundary, "label": label,
                     "threshold": body_threshold, "keep_all": keep_all_components or None, "units": units,
                     "skin": skin if boundary == "skin" else None})
    sampling = {} if voxel is None else {"voxel": voxel}  # default: lattice.plan.default_voxel
    recipe = {"job": "infill", "tpms": tp, "domain": domain, "sampling": sampling,
              "output": outputs(out, report, recipe_out)}
    if grading:
        recipe["grading"] = grading
    analysis = given_only({"regions": regions, "region_axis": region_axis})
    if analysis:
        recipe["analysis"] = analysis
    recipe = with_scale(recipe, scheduler, stream, zarr_path, retries, chunk_mb, max_output)
    run_job(recipe, force, as_json, threads=threads, check_intersections=check_intersections)


@click.command()
@click.option("-o", "--out", "out_dir", default="porecad-demo", show_default=True,
              type=click.Path(file_okay=False), help="Output directory.")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
def demo(out_dir, force, as_json):
    """Graded gyroid-sheet scaffold in the bundled analytic lumbar disc.

    Writes a closed STL, the recipe that regenerates it and a JSON report.
    """
    from ..jobs.tpms_job import demo_recipe
    d = Path(out_dir)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {d}: {exc.strerror}") from None
    run_job(demo_recipe(d), force, as_json)


@click.command()
@click.argument("recipe_file", type=click.Path(dir_okay=False))
@click.option("--force", is_flag=True, help="Overwrite existing outputs (regular files only).")
@click.option("--out-dir", "out_dir", type=click.Path(file_okay=False),
              help="Write the recipe's outputs in this folder (default: the recipe's own folder).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@strict_option
@islands_option
@threads_option
@max_memory_option
@scale_options
def build(recipe_file, force, out_dir, as_json, threads, scheduler, stream, zarr_path, retries, chunk_mb, max_output):
    """Run a recipe (TOML) written by any porecad command (--recipe) or by hand.

    Input paths inside the recipe are relative to the recipe file. Its
    outputs are relative paths inside the recipe's folder (or inside
    --out-dir): a shared recipe cannot write anywhere else. The recipe file
    itself is never overwritten.
    """
    from ..io.recipe import read_recipe
    recipe = read_recipe(recipe_file)
    if any(v is not None for v in (scheduler, stream, zarr_path, retries, chunk_mb, max_output)):
        if recipe.get("job") not in ("tpms", "infill"):
            raise InputError("--scheduler, --stream, --zarr, --retries, --chunk-mb and --max-output apply to tpms and infill "
                             "recipes")
        recipe = with_scale(recipe, scheduler, stream, zarr_path and str(Path(zarr_path).resolve()), retries,
                            chunk_mb, max_output)
    p = Path(recipe_file)
    folder = p.resolve().parent
    if out_dir is not None:
        folder = Path(out_dir)
        if not folder.is_dir():
            raise InputError(f"--out-dir: {out_dir}: no such folder")
    typed = frozenset(([str(Path(zarr_path).resolve())] if zarr_path else []) + ([scheduler] if scheduler else []))
    run_job(recipe, force, as_json, threads=threads, base=p.resolve().parent, source=p, confine=(folder, typed))


