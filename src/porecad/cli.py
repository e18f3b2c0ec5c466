"""The ``porecad`` command line: a thin layer that builds a recipe and runs it.

Errors a user can cause print one line (``porecad: error: ...``) on stderr and
exit non-zero; progress goes to stderr; ``--json`` prints exactly one JSON
object on stdout.
"""

from __future__ import annotations

import json
import sys

import click

from . import __version__
from .errors import InputError, OutputError, PorecadError, ResourceError

EXAMPLES_TPMS = """
\b
Examples:
  porecad tpms G --structure sheet --porosity 0.6 --cells 2 2 2 --cell-size 2 --resolution 40 -o gyroid.stl
  porecad tpms P --structure pore --threshold 0 --cells 1 1 1 --cell-size 1 --resolution 200 --json
  porecad tpms P --structure surface --threshold 0 --resolution 100 -o p_surface.stl
  porecad tpms G --porosity 0.7 --cells 4 4 4 --resolution 150 --scheduler local:2 --stream -o big.stl
  porecad tpms --list --json
"""


class _Progress:
    """A minimal per-stage progress bar on stderr (only when stderr is a terminal)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.last = None

    def __call__(self, stage, done, total):
        if not self.enabled:
            return
        width = 30
        fill = int(width * done / max(total, 1))
        sys.stderr.write(f"\r{stage:>8} [{'#' * fill}{'.' * (width - fill)}] {done}/{total}")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _emit(report: dict, as_json: bool):
    from .pipeline import _json_default
    if as_json:
        click.echo(json.dumps(report, default=_json_default))
        return
    keys = ["type", "structure", "threshold", "porosity", "porosity_voxel", "volume", "surface_area",
            "specific_surface", "area_per_volume", "triangles", "closed", "manifold", "oriented",
            "mesh_file", "report_file", "report_dir", "recipe_file"]
    for k in keys:
        if k in report and report[k] is not None:
            v = report[k]
            click.echo(f"{k:>18}: {v:.6g}" if isinstance(v, float) else f"{k:>18}: {v}")
    if "timings" in report:
        click.echo(f"{'time':>18}: {report['timings'].get('total_s', 0):.2f} s")


def _run(recipe, force, as_json, threads=None, check_intersections=False):
    from .pipeline import run_recipe
    progress = _Progress(sys.stderr.isatty())
    report = run_recipe(recipe, force=force, progress=progress, threads=threads,
                        check_intersections=check_intersections)
    for warning in report.get("warnings", []):
        click.echo(f"porecad: warning: {warning}", err=True)
    _emit(report, as_json)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="porecad")
def cli():
    """porecad: porous scaffolds and implicit vascular models as watertight, printable meshes.

    \b
    Quick start:
      porecad demo -o demo-out            # graded gyroid scaffold in a lumbar disc
      porecad tpms --list                 # the TPMS catalogue
      porecad tpms G --structure sheet --porosity 0.6 --cells 2 2 2 --cell-size 2 -o g.stl
      porecad analyze g.stl --json
    """


@cli.command()
@click.option("-o", "--out", "out_dir", default="porecad-demo", show_default=True,
              type=click.Path(file_okay=False), help="Output directory.")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
def demo(out_dir, force, as_json):
    """Graded gyroid-sheet scaffold in the bundled analytic lumbar disc.

    Writes a closed STL, the recipe that regenerates it and a JSON report.
    """
    from pathlib import Path

    from .pipeline import demo_recipe
    d = Path(out_dir)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {d}: {exc.strerror}") from None
    _run(demo_recipe(d), force, as_json)


def _given(table: dict) -> dict:
    """The entries of a recipe table whose value was given (not None)."""
    return {k: v for k, v in table.items() if v is not None}


def _scale_options(fn):
    """The scale-out options shared by the build commands (``docs/scale-out.md``)."""
    opts = [
        click.option("--scheduler",
                     help="Where chunks run: threads (default), local:N (N worker processes) or "
                          "tcp://HOST:PORT (an existing dask cluster); dask needs porecad[dask]."),
        click.option("--stream/--no-stream", default=None,
                     help="Stream the mesh to the .stl/.ply file chunk by chunk (memory bounded by the "
                          "chunks, not the mesh); default: when the mesh would not fit in memory."),
        click.option("--zarr", "zarr_path", type=click.Path(),
                     help="Also store the sampled field (float32, chunked by slab) in this zarr directory."),
        click.option("--retries", type=int, help="Attempts after a chunk fails (default 2)."),
        click.option("--chunk-mb", type=float, help="Samples per chunk in MiB (default 16)."),
    ]
    for opt in reversed(opts):
        fn = opt(fn)
    return fn


def _with_scale(recipe: dict, scheduler=None, stream=None, zarr_path=None, retries=None, chunk_mb=None) -> dict:
    """The recipe with the given scale-out options merged into its ``[scale]`` table."""
    given = _given({"scheduler": scheduler, "stream": stream, "zarr": zarr_path, "retries": retries,
                    "chunk_mb": chunk_mb})
    if given:
        recipe = dict(recipe)
        recipe["scale"] = {**dict(recipe.get("scale") or {}), **given}
    return recipe


def _number_or_expression(text, name):
    """A CLI value that is a number or a grading expression: (number, None) or (None, expr)."""
    if text is None:
        return None, None
    try:
        return float(text), None
    except ValueError:
        if not str(text).strip():
            raise InputError(f"--{name} is empty") from None
        return None, str(text)


def _tpms_spec(tpms_type, structure, threshold, porosity, cell_size, allow_closed_pores=False,
               porosity_points=None, porosity_map=None, map_scale=1.0, map_offset=0.0, cell_size_ramp=None,
               ramp_axis="z"):
    """The recipe's [tpms] table (and [grading], or None) from CLI options, after the shared checks.

    ``--threshold``/``--porosity`` take a number or an expression in x, y, z
    (and d, dn inside a body); ``--porosity-points`` a CSV for a thin-plate
    RBF; ``--porosity-map`` an image.
    """
    c_val, c_expr = _number_or_expression(threshold, "threshold")
    p_val, p_expr = _number_or_expression(porosity, "porosity")
    given = [x for x in (threshold, porosity, porosity_points, porosity_map) if x is not None]
    if len(given) > 1:
        raise InputError("give either --threshold, --porosity, --porosity-points or --porosity-map, not several")
    if not given:
        raise InputError("give --threshold C or --porosity P")
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
    else:
        grading = {"kind": "image", "of": "porosity", "path": str(porosity_map), "scale": map_scale,
                   "offset": map_offset}
    if allow_closed_pores:
        tp["allow_closed_pores"] = True
    return tp, grading


def _tpms_recipe(tpms_type, structure, threshold, porosity, cell_size, cells, resolution, voxel, out,
                 smooth, smooth_iterations, decimate, report, recipe_out, allow_closed_pores=False):
    tp, grading = _tpms_spec(tpms_type, structure, threshold, porosity, cell_size, allow_closed_pores)
    sampling = {"voxel": voxel} if voxel is not None else {"resolution": resolution}
    recipe = {"job": "tpms", "tpms": tp, "domain": {"kind": "box", "cells": list(cells)},
              "sampling": sampling,
              "post": {"smooth": smooth, "smooth_iterations": smooth_iterations, "decimate": decimate},
              "output": {"mesh": out, "report": report, "recipe": recipe_out}}
    if grading:
        recipe["grading"] = grading
    return recipe


@cli.command(epilog=EXAMPLES_TPMS)
@click.argument("tpms_type", metavar="TYPE", required=False)
@click.option("--structure", default="sheet", show_default=True,
              help="pore (material φ ≥ C), rod (φ ≤ C), sheet (|φ| ≤ C) or surface (open φ = C).")
@click.option("--threshold", "-c", help="Threshold C (a number, or an expression in x, y, z).")
@click.option("--porosity", "-p",
              help="Target porosity (void fraction 0-1; a number or an expression in x, y, z); solves for C.")
@click.option("--cell-size", "-L", type=float, multiple=True, default=[1.0], show_default=True,
              help="Cell size in mm (repeat three times for x, y, z).")
@click.option("--cells", nargs=3, type=int, default=(1, 1, 1), show_default=True, help="Cells NX NY NZ.")
@click.option("--resolution", "-n", type=int, default=40, show_default=True,
              help="Samples per cell edge (both ends included).")
@click.option("--voxel", type=float, help="Sample spacing in mm (instead of --resolution).")
@click.option("-o", "--out", type=click.Path(dir_okay=False), help="Output mesh (.stl .ply .obj .3mf).")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--list", "list_types", is_flag=True, help="List the TPMS types.")
@click.option("--smooth", type=click.Choice(["none", "laplacian", "taubin"]), default="none",
              show_default=True, help="Smoothing (004 eqs. 4-5; Taubin keeps volume).")
@click.option("--smooth-iterations", type=int, default=10, show_default=True)
@click.option("--decimate", type=float, default=0.0, help="Decimation tolerance in mm (keeps it closed).")
@click.option("--report", type=click.Path(),
              help="Report: a .json file, or a directory (report.json, report.html, plots: full analysis).")
@click.option("--recipe", "recipe_out", type=click.Path(dir_okay=False),
              help="Write the recipe that regenerates this output.")
@click.option("--threads", type=int, help="Worker threads (default: all cores).")
@click.option("--check-intersections", is_flag=True, help="Also test for self-intersections.")
@click.option("--allow-closed-pores", is_flag=True,
              help="Build outside the valid range (closed pores, floating pieces); the report says so.")
@_scale_options
def tpms(tpms_type, structure, threshold, porosity, cell_size, cells, resolution, voxel, out, force,
         as_json, list_types, smooth, smooth_iterations, decimate, report, recipe_out, threads,
         check_intersections, allow_closed_pores, scheduler, stream, zarr_path, retries, chunk_mb):
    """Build a TPMS scaffold (pore, rod, sheet solid or bare surface) in a box of cells."""
    from .fields.tpms import list_types as catalogue
    if list_types:
        types = catalogue()
        if as_json:
            from .calibration import valid_range
            for t in types:
                t["valid_range"] = {s: valid_range(t["name"], s) for s in ("pore", "rod", "sheet")}
            click.echo(json.dumps(types))
        else:
            for t in types:
                click.echo(f"{t['name']:>15}  {t['title']}: {t['formula']}")
        return
    if not tpms_type:
        raise InputError("give a TPMS TYPE (see `porecad tpms --list`)")
    recipe = _tpms_recipe(tpms_type, structure, threshold, porosity, cell_size, cells, resolution, voxel,
                          out, smooth, smooth_iterations, decimate, report, recipe_out, allow_closed_pores)
    recipe = _with_scale(recipe, scheduler, stream, zarr_path, retries, chunk_mb)
    _run(recipe, force, as_json, threads=threads, check_intersections=check_intersections)


@cli.command()
@click.argument("body", type=click.Path())
@click.argument("tpms_type")
@click.option("--structure", default="pore", show_default=True,
              type=click.Choice(["pore", "rod", "sheet"], case_sensitive=False), help="Solid structure.")
@click.option("--threshold", "-c",
              help="Threshold C: a number, or an expression in x, y, z, d (depth, mm) and dn (d / max depth).")
@click.option("--porosity", "-p",
              help="Target porosity: a number, or an expression in x, y, z, d, dn, e.g. '0.5 + 0.3 * dn'.")
@click.option("--porosity-points", type=click.Path(dir_okay=False),
              help="CSV of x, y, z, porosity rows: thin-plate RBF grading.")
@click.option("--porosity-map", type=click.Path(), help="Image whose values (x scale + offset) are the porosity.")
@click.option("--map-scale", type=float, default=1.0, show_default=True, help="Scale of --porosity-map values.")
@click.option("--map-offset", type=float, default=0.0, show_default=True, help="Offset of --porosity-map values.")
@click.option("--cell-size-ramp", nargs=2, type=float,
              help="Cell size L0 L1 (mm) ramping along --ramp-axis over the body (lattice kept continuous).")
@click.option("--ramp-axis", type=click.Choice(["x", "y", "z"]), default="z", show_default=True)
@click.option("--regions", type=int,
              help="Per-region porosity report: N depth shells and N slabs (default 5 when graded, else 0).")
@click.option("--region-axis", type=click.Choice(["x", "y", "z"]), help="Slab axis (default: longest).")
@click.option("--cell-size", "-L", type=float, multiple=True, default=[5.0], show_default=True,
              help="Cell size in mm (once, or three times for x y z).")
@click.option("--voxel", type=float, help="Sample spacing in mm (default: smallest body extent / 200).")
@click.option("--boundary", type=click.Choice(["cut", "skin", "whole"]), default="cut", show_default=True,
              help="cut: lattice ∩ body; skin: plus a solid shell; whole: only complete cells.")
@click.option("--skin", type=float, default=1.0, show_default=True, help="Shell thickness in mm (skin).")
@click.option("-o", "--out", type=click.Path(dir_okay=False), help="Output mesh (.stl .ply .obj .3mf).")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--report", type=click.Path(),
              help="Report: a .json file, or a directory (report.json, report.html, plots: full analysis).")
@click.option("--recipe", "recipe_out", type=click.Path(dir_okay=False),
              help="Write the recipe (TOML) that regenerates this output.")
@click.option("--threads", type=int, help="Worker threads (default: all cores).")
@click.option("--check-intersections", is_flag=True, help="Also test the output for self-intersections.")
@click.option("--allow-closed-pores", is_flag=True, help="Build outside the valid range.")
@click.option("--label", type=float, help="Image body: the voxel value of the body in a label map.")
@click.option("--body-threshold", type=float,
              help="Image body: intensity threshold (body = voxels >= it), e.g. 300 HU for bone.")
@click.option("--keep-all-components", is_flag=True,
              help="Image body by threshold: keep every connected piece (default: the largest).")
@_scale_options
def infill(body, tpms_type, structure, threshold, porosity, cell_size, voxel, boundary, skin, out, force,
           as_json, report, recipe_out, threads, check_intersections, allow_closed_pores, label,
           body_threshold, keep_all_components, porosity_points, porosity_map, map_scale, map_offset,
           cell_size_ramp, ramp_axis, regions, region_axis, scheduler, stream, zarr_path, retries, chunk_mb):
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
    tp, grading = _tpms_spec(tpms_type, structure, threshold, porosity, cell_size, allow_closed_pores,
                             porosity_points, porosity_map, map_scale, map_offset, cell_size_ramp or None,
                             ramp_axis)
    domain = _given({"kind": "mesh", "path": str(body), "boundary": boundary, "label": label,
                     "threshold": body_threshold, "keep_all": keep_all_components or None,
                     "skin": skin if boundary == "skin" else None})
    sampling = {} if voxel is None else {"voxel": voxel}  # default: smallest body extent / 200
    recipe = {"job": "tpms", "tpms": tp, "domain": domain, "sampling": sampling,
              "output": {"mesh": out, "report": report, "recipe": recipe_out}}
    if grading:
        recipe["grading"] = grading
    analysis = _given({"regions": regions, "region_axis": region_axis})
    if analysis:
        recipe["analysis"] = analysis
    recipe = _with_scale(recipe, scheduler, stream, zarr_path, retries, chunk_mb)
    _run(recipe, force, as_json, threads=threads, check_intersections=check_intersections)


@cli.command()
@click.argument("recipe_file", type=click.Path(dir_okay=False))
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@_scale_options
def build(recipe_file, force, as_json, scheduler, stream, zarr_path, retries, chunk_mb):
    """Run a recipe (TOML) written by porecad or by hand."""
    from .io.recipe import load_recipe
    recipe = _with_scale(load_recipe(recipe_file), scheduler, stream, zarr_path, retries, chunk_mb)
    _run(recipe, force, as_json)


@cli.command()
@click.argument("mesh_file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--domain-volume", type=float,
              help="Volume of the design domain for the porosity (default: the bounding box).")
@click.option("--check-intersections/--no-check-intersections", default=True, show_default=True)
@click.option("--pores", is_flag=True,
              help="Pore and strut sizes (local thickness), interconnectivity, permeability estimate.")
@click.option("--voxel", type=float, help="Voxel size in mm for --pores (default: smallest extent / 60).")
@click.option("--min-feature", type=float, help="Flag struts/walls thinner than this (mm).")
@click.option("--min-pore", type=float, help="Flag pores smaller than this (mm).")
@click.option("--report", "report_dir", type=click.Path(file_okay=False),
              help="Write report.json, report.html and PNG plots to this directory.")
@click.option("--force", is_flag=True, help="Overwrite an existing report directory's files.")
def analyze(mesh_file, as_json, domain_volume, check_intersections, pores, voxel, min_feature, min_pore,
            report_dir, force):
    """Analyse a mesh: volume, area, porosity, topology, validity; with --pores sizes and connectivity.

    \b
    Examples:
      porecad analyze scaffold.stl --json
      porecad analyze scaffold.stl --pores --voxel 0.05 --min-feature 0.3 --json
      porecad analyze scaffold.stl --pores --report scaffold-report/
    """
    from .analysis.report import analyze_mesh, write_report
    if report_dir is not None:
        write_report_check(report_dir, force)
    report, fields = analyze_mesh(mesh_file, domain_volume=domain_volume, check_intersections=check_intersections,
                                  pores=pores or report_dir is not None, voxel=voxel, min_feature=min_feature,
                                  min_pore=min_pore, keep_fields=report_dir is not None)
    if report_dir is not None:
        report["report_dir"] = str(write_report(report_dir, report, fields, force=force))
    _emit(report, as_json)


def write_report_check(report_dir, force):
    """Refuse to overwrite an existing report without --force (before any work)."""
    from .analysis.report import check_report_dir
    check_report_dir(report_dir, force)


from .cli_tbss import tbss as _tbss  # noqa: E402 - registered after the group exists

from .cli_arbf import arbf as _arbf  # noqa: E402
from .cli_hex import hex as _hex  # noqa: E402
from .cli_tis import tis as _tis  # noqa: E402
from .cli_vessel import vessel as _vessel  # noqa: E402
from .cli_ivd import ivd as _ivd  # noqa: E402
from .cli_ivd import phantom as _phantom  # noqa: E402
from .cli_ivd import seg as _seg  # noqa: E402
from .cli_simulate import properties as _properties  # noqa: E402
from .cli_simulate import volmesh as _volmesh  # noqa: E402

cli.add_command(_tbss)
cli.add_command(_tis)
cli.add_command(_arbf)
cli.add_command(_hex)
cli.add_command(_vessel)
cli.add_command(_ivd)
cli.add_command(_phantom)
cli.add_command(_seg)
cli.add_command(_volmesh)
cli.add_command(_properties)


def main(argv=None):
    """Entry point: run the CLI, turning user errors into one-line messages."""
    try:
        cli.main(args=argv, prog_name="porecad", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except click.exceptions.Abort:
        click.echo("porecad: interrupted", err=True)
        return 130
    except click.ClickException as exc:
        msg = exc.format_message().replace("\n", " ")
        click.echo(f"porecad: error: {msg}", err=True)
        return 2
    except KeyboardInterrupt:
        click.echo("porecad: interrupted", err=True)
        return 130
    except PorecadError as exc:
        click.echo(f"porecad: error: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}",
                   err=True)
        return exc.exit_code
    except MemoryError:
        click.echo(f"porecad: error: {ResourceError('out of memory; lower the resolution')}", err=True)
        return 3
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
