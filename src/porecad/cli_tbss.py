"""``porecad tbss``: heterogeneous TPMS scaffolds in trivariate B-spline solids (document 001)."""

from __future__ import annotations

import os
import sys

import click

from .errors import InputError

EXAMPLES_TBSS = """
\b
Examples:
  porecad tbss disc G --structure sheet --tdf layer --periods 4 4 2 --resolution 16 -o disc.stl --save-tdf disc.tdf
  porecad tbss cylinder P --structure pore --tdf "0.5 + 0.5 * w" --periods 4 4 6 --resolution 12 -o cyl.stl
  porecad tbss femur.stl D --structure rod --tdf fill --fit sliced --periods 3 3 24 --resolution 12 -o femur.stl
  porecad tbss --from-tdf disc.tdf --resolution 24 -o disc-fine.stl
  porecad tbss --from-tdf disc.tdf --edit "(w > 0.75) & (u < 0.5)" 0.9 --save-tdf disc-edited.tdf -o edited.stl
"""


def tbss_recipe(body, tpms_type, structure, tdf, periods, resolution, out, save_tdf, report, layer_by, layers,
                threshold_range, porosity_range, tdf_grid, tdf_control, fit, body_control, from_tdf,
                allow_closed_pores=False, edits=()) -> dict:
    """The recipe of a ``porecad tbss`` command line."""
    output = {k: v for k, v in (("mesh", out), ("tdf", save_tdf), ("report", report)) if v}
    mesh = {"resolution": resolution}
    edit_specs = [{"where": where, "threshold": value} for where, value in (edits or ())]
    if from_tdf:
        if body or tpms_type:
            raise InputError("--from-tdf regenerates a stored scaffold: give no BODY or TYPE")
        spec = {"file": from_tdf, **({"edits": edit_specs} if edit_specs else {})}
        return {"job": "tbss", "tdf": spec, "mesh": mesh, "output": output,
                "tpms": {"allow_closed_pores": allow_closed_pores}}
    if not body or not tpms_type:
        raise InputError("give BODY (disc, box, cylinder, tube or a mesh file) and TYPE, or --from-tdf FILE")
    if body in ("disc", "box", "cylinder", "tube"):
        body_spec = {"kind": body}
    else:
        if not os.path.exists(body):
            raise InputError(f"{body}: no such body (use disc, box, cylinder, tube or a mesh file)")
        body_spec = {"kind": "mesh", "path": body, "fit": fit, "control": body_control}
    if tdf in ("layer", "fill"):
        tdf_spec = {"method": tdf}
    elif tdf in ("fill-gaussian", "fill-mean"):
        tdf_spec = {"method": "fill", "quantity": tdf.split("-")[1]}
    else:
        tdf_spec = {"method": "function", "expr": tdf}
    if tdf_spec["method"] == "layer":
        tdf_spec["by"] = layer_by
        if layers:
            tdf_spec["layers"] = layers
    tdf_spec.update(grid=tdf_grid, control=tdf_control)
    if edit_specs:
        tdf_spec["edits"] = edit_specs
    if threshold_range:
        tdf_spec["threshold_range"] = list(threshold_range)
    if porosity_range:
        tdf_spec["porosity_range"] = list(porosity_range)
    return {"job": "tbss", "body": body_spec,
            "tpms": {"type": tpms_type, "structure": structure, "periods": list(periods),
                     "allow_closed_pores": allow_closed_pores},
            "tdf": tdf_spec, "mesh": mesh, "output": output}


@click.command(epilog=EXAMPLES_TBSS)
@click.argument("body", required=False)
@click.argument("tpms_type", metavar="TYPE", required=False)
@click.option("--structure", default="sheet", show_default=True, type=click.Choice(["pore", "rod", "sheet"]))
@click.option("--tdf", default="layer", show_default=True,
              help="Threshold distribution field: layer, fill (mean curvature), fill-gaussian, or an "
                   "expression in u, v, w (and x, y, z), mapped linearly into the threshold range.")
@click.option("--periods", nargs=3, type=float, default=(4, 4, 4), show_default=True,
              help="Whole periods A B C along u, v, w (001's period coefficients).")
@click.option("--resolution", "-n", type=int, default=16, show_default=True,
              help="Samples per period edge in the parameter cube.")
@click.option("--layer-by", type=click.Choice(["u", "v", "w", "sides", "boundary"]), default="w",
              show_default=True, help="Layer method: layers of constant u/v/w or by distance from the faces.")
@click.option("--layers", type=int, help="Number of layers (default: one per period along --layer-by).")
@click.option("--threshold-range", nargs=2, type=float, help="Map the TDF onto [LO, HI] (default: valid range, inset 10%).")
@click.option("--porosity-range", nargs=2, type=float, help="Map the TDF onto porosities [LO, HI] instead.")
@click.option("--tdf-grid", type=int, default=100, show_default=True, help="Parametric grid N (N^3 vertices).")
@click.option("--tdf-control", type=int, default=20, show_default=True, help="TDF control grid M (M^3).")
@click.option("--fit", type=click.Choice(["auto", "radial", "sliced", "hex"]), default="auto", show_default=True,
              help="How a mesh BODY is fitted: radial (star-shaped), sliced (elongated; ends trimmed), hex (any "
                   "closed genus-0 body, by the cube parameterisation of 000 ch.3), auto (radial if star-shaped, "
                   "else hex). A fit that folds is untangled against its Jacobian.")
@click.option("--body-control", type=int, default=8, show_default=True, help="TBSS control grid of a fitted body.")
@click.option("--from-tdf", type=click.Path(dir_okay=False), help="Regenerate the scaffold stored in a TDF file.")
@click.option("--edit", "edits", nargs=2, type=(str, float), multiple=True, metavar="WHERE C",
              help="Local modification: set threshold C where the expression WHERE (in u, v, w) holds; "
                   "only the TDF control points over that region move (local LSPIA). Repeatable.")
@click.option("-o", "--out", type=click.Path(dir_okay=False), help="Output mesh (.stl .ply .obj .3mf).")
@click.option("--save-tdf", type=click.Path(dir_okay=False), help="Also store the scaffold as a TDF file.")
@click.option("--report", type=click.Path(),
              help="Report: a .json file, or a directory (report.json, report.html, plots: full analysis).")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--threads", type=int, help="Worker threads (default: all cores).")
@click.option("--check-intersections", is_flag=True, help="Also test for self-intersections.")
@click.option("--allow-closed-pores", is_flag=True, help="Accept a TDF outside the valid threshold range.")
def tbss(body, tpms_type, structure, tdf, periods, resolution, layer_by, layers, threshold_range, porosity_range,
         tdf_grid, tdf_control, fit, body_control, from_tdf, edits, out, save_tdf, report, force, as_json, threads,
         check_intersections, allow_closed_pores):
    """Build a heterogeneous TPMS scaffold in a trivariate B-spline solid (BODY: disc, box, cylinder,
    tube or a mesh file to fit), or regenerate one from a TDF file."""
    from .cli import _emit, _Progress
    from .tbss_pipeline import run_tbss
    recipe = tbss_recipe(body, tpms_type, structure, tdf, periods, resolution, out, save_tdf, report, layer_by,
                         layers, threshold_range, porosity_range, tdf_grid, tdf_control, fit, body_control,
                         from_tdf, allow_closed_pores, edits)
    result = run_tbss(recipe, force=force, progress=_Progress(sys.stderr.isatty()), threads=threads,
                      check_intersections=check_intersections)
    for warning in result.get("warnings", []):
        click.echo(f"porecad: warning: {warning}", err=True)
    _emit(result, as_json)
    if not as_json:
        if result.get("tdf_file"):
            click.echo(f"{'tdf_file':>18}: {result['tdf_file']}")
        for layer in result.get("layers", []):
            click.echo(f"{'layer ' + str(layer['layer']):>18}: porosity {layer['porosity']:.4f} "
                       f"(target {layer['target_porosity']:.4f})")
