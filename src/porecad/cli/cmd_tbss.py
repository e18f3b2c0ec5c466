"""``porecad tbss``: heterogeneous TPMS scaffolds in trivariate B-spline solids (document 001)."""

from __future__ import annotations

import os

import click

from ..errors import InputError
from .console import run_job
from .options import check_intersections_option, keyed, keyed_in, output_options, outputs, threads_option

option = keyed_in("tbss")

EXAMPLES = """
\b
Examples:
  porecad tbss disc G --structure sheet --tdf layer --periods 4 4 2 --resolution 16 -o disc.stl --save-tdf disc.tdf
  porecad tbss cylinder P --structure pore --tdf "0.5 + 0.5 * w" --periods 4 4 6 --resolution 12 -o cyl.stl
  porecad tbss femur.stl D --structure rod --tdf fill --fit sliced --periods 3 3 24 --resolution 12 -o femur.stl
  porecad tbss cylinder G --structure sheet --porosity-range 0.6 0.6 --cell-size 6 -o cyl-6mm.stl
  porecad tbss --from-tdf disc.tdf --resolution 24 -o disc-fine.stl
  porecad tbss --from-tdf disc.tdf --edit "(w > 0.75) & (u < 0.5)" 0.9 --save-tdf disc-edited.tdf -o edited.stl
"""


def tbss_recipe(body, tpms_type, structure, tdf, periods, resolution, out, save_tdf, report, layer_by, layers,
                threshold_range, porosity_range, tdf_grid, tdf_control, fit, body_control, from_tdf,
                allow_closed_pores=False, edits=(), recipe_out=None, clip=None, margin=None, cell_size=None,
                skin=None) -> dict:
    """The recipe of a ``porecad tbss`` command line."""
    output = outputs(out, report, recipe_out, tdf=save_tdf)
    mesh = {"resolution": resolution}
    edit_specs = [{"where": where, "threshold": value} for where, value in (edits or ())]
    if from_tdf:
        if body or tpms_type:
            raise InputError("--from-tdf regenerates a stored scaffold: give no BODY or TYPE")
        if periods or cell_size is not None:
            raise InputError("--from-tdf regenerates a stored scaffold with its own periods: give no --periods "
                             "or --cell-size")
        spec = {"file": from_tdf, **({"edits": edit_specs} if edit_specs else {})}
        recipe = {"job": "tbss", "tdf": spec, "mesh": mesh, "output": output}
        if allow_closed_pores:
            recipe["tpms"] = {"allow_closed_pores": True}
        return recipe
    if not body or not tpms_type:
        raise InputError("give BODY (disc, box, cylinder, tube or a mesh file) and TYPE, or --from-tdf FILE")
    if body in ("disc", "box", "cylinder", "tube"):
        body_spec = {"kind": body}
    else:
        if not os.path.exists(body):
            raise InputError(f"{body}: no such body (use disc, box, cylinder, tube or a mesh file)")
        body_spec = {"kind": "mesh", "path": body, "fit": fit, "control": body_control}
        if clip is not None:
            body_spec["clip"] = bool(clip)
        if margin is not None:
            body_spec["margin"] = margin
        if skin is not None:
            body_spec["skin"] = skin
    if body_spec["kind"] != "mesh" and (fit != "auto" or body_control != 8 or clip is not None or margin is not None
                                        or skin is not None):
        raise InputError("--fit, --body-control, --clip/--no-clip, --margin and --skin fit a mesh BODY; this body is "
                         "built in")
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
    if cell_size is not None and periods:
        raise InputError("give --periods or --cell-size, not both")
    cells = {"cell_size": cell_size} if cell_size is not None else {"periods": list(periods or (4, 4, 4))}
    return {"job": "tbss", "body": body_spec,
            "tpms": {"type": tpms_type, "structure": structure, **cells,
                     **({"allow_closed_pores": True} if allow_closed_pores else {})},
            "tdf": tdf_spec, "mesh": mesh, "output": output}


@click.command(epilog=EXAMPLES)
@click.argument("body", required=False)
@click.argument("tpms_type", metavar="TYPE", required=False)
@option("tpms.structure", "--structure", type=click.Choice(["pore", "rod", "sheet"]))
@option(("tdf.method", "tdf.expr"), "--tdf", type=str,
       help="Threshold distribution field: layer, fill (mean curvature), fill-gaussian, or an "
                   "expression in u, v, w (and x, y, z), mapped linearly into the threshold range.")
@option("tpms.periods", "--periods", nargs=3, type=float, default=None,
              help="Whole periods A B C along u, v, w (001's period coefficients; default 4 4 4).")
@option("tpms.cell_size", "--cell-size", type=float,
       help="Instead of --periods: cell size (mm); periods along u, v, w = the solid's mean line lengths / cell "
            "size, rounded (reported under cell_size).")
@option("mesh.resolution", "--resolution", "-n", type=int, help="Samples per period edge in the parameter cube.")
@option("tdf.by", "--layer-by", help="Layer method: layers of constant u/v/w or by distance from the faces.")
@option("tdf.layers", "--layers", type=int, help="Number of layers (default: one per period along --layer-by).")
@option("tdf.threshold_range", "--threshold-range", nargs=2, type=float,
       help="Map the TDF onto [LO, HI] (default: valid range, inset 10%).")
@option("tdf.porosity_range", "--porosity-range", nargs=2, type=float,
       help="Map the TDF onto porosities [LO, HI] instead.")
@option("tdf.grid", "--tdf-grid", type=int, help="Parametric grid N (N^3 vertices).")
@option("tdf.control", "--tdf-control", type=int, help="TDF control grid M (M^3).")
@option("body.fit", "--fit", help="How a mesh BODY is fitted: radial (star-shaped), sliced (elongated; ends trimmed), hex (any "
            "closed genus-0 body, by the cube parameterisation of 000 ch.3), auto (radial if star-shaped, "
            "else hex). A fit that folds is untangled against its Jacobian.")
@option("body.control", "--body-control", type=int, help="TBSS control grid of a fitted body.")
@option("body.clip", "--clip/--no-clip", default=None,
       help="Fit a mesh BODY a margin larger and cut the scaffold to the body in field space, so that it fills "
            "the body and keeps to its extents (default: on).")
@option("body.margin", "--margin", type=float,
       help="Margin (mm) the fit of a mesh BODY is inflated by (default: radial fit a tenth of its mean "
            "thickness 3V/A; hex fit none: it is pushed out over every surface vertex it passes inside of).")
@option("body.skin", "--skin", type=float,
       help="Wrap the scaffold cut to a mesh BODY in a solid shell this thick (mm), so that its outside is the "
            "body's (default: none).")
@option("tdf.file", "--from-tdf", type=click.Path(dir_okay=False), help="Regenerate the scaffold stored in a TDF file.")
@option("tdf.edits", "--edit", "edits", nargs=2, type=(str, float), multiple=True, metavar="WHERE C",
              help="Local modification: set threshold C where the expression WHERE (in u, v, w) holds; "
                   "only the TDF control points over that region move (local LSPIA). Repeatable.")
@output_options(extra=[keyed("output.tdf", "--save-tdf", type=click.Path(dir_okay=False),
                             help="Also store the scaffold as a TDF file.")])
@threads_option
@check_intersections_option
@option("tpms.allow_closed_pores", "--allow-closed-pores", is_flag=True,
       help="Accept a TDF outside the valid threshold range.")
def tbss(body, tpms_type, structure, tdf, periods, cell_size, resolution, layer_by, layers, threshold_range, porosity_range,
         tdf_grid, tdf_control, fit, body_control, clip, margin, skin, from_tdf, edits, out, save_tdf, report,
         recipe_out, force, as_json, threads, check_intersections, allow_closed_pores):
    """Build a heterogeneous TPMS scaffold in a trivariate B-spline solid (BODY: disc, box, cylinder,
    tube or a mesh file to fit), or regenerate one from a TDF file."""
    recipe = tbss_recipe(body, tpms_type, structure, tdf, periods, resolution, out, save_tdf, report, layer_by,
                         layers, threshold_range, porosity_range, tdf_grid, tdf_control, fit, body_control,
                         from_tdf, allow_closed_pores, edits, recipe_out, clip, margin, cell_size, skin)
    result = run_job(recipe, force, as_json, threads=threads, check_intersections=check_intersections)
    if not as_json:
        for layer in result.get("layers", []):
            click.echo(f"{'layer ' + str(layer['layer']):>18}: porosity {layer['porosity']:.4f} "
                       f"(target {layer['target_porosity']:.4f})")
