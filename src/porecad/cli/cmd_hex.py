"""``porecad hex``: TPMS cells mapped into hexahedral meshes (documents 000 ch.3 and 004)."""

from __future__ import annotations

import os

import click

from ..errors import InputError
from .console import run_job
from .options import keyed_in, output_options, outputs

option = keyed_in("hex")

EXAMPLES = """
\b
Examples:
  porecad hex cylinder P --grid 4 4 6 --element hex20 --structure pore --porosity 0.6 --resolution 16 -o cyl.stl --json
  porecad hex frustum IWP --grid 4 4 4 --structure pore --threshold 0 -o frustum.stl
  porecad hex frustum P --grid 4 4 4 --threshold 0 --refine-point 1 1 1 -o frustum-refined.stl --json
  porecad hex cylinder IWP --grid 4 4 4 --threshold 0 --refine-box 1 1 1 3 3 3 -o cyl-refined.stl
  porecad hex femur.stl P --grid 5 7 20 --structure pore --threshold 0 --resolution 12 -o femur-hex.stl
"""


def hex_recipe(body, tpms_type, grid, element, structure, threshold, porosity, resolution, smooth, intersect,
               out=None, report=None, refine=(), refine_box=None, corners=None, cut=None, recipe_out=None,
               untangle_limit=None, allow_closed_pores=False) -> dict:
    """The recipe of a ``porecad hex`` command line."""
    if body in ("frustum", "cylinder"):
        body_spec = {"kind": body}
    else:
        if not os.path.exists(body):
            raise InputError(f"{body}: no such file (BODY is frustum, cylinder or a closed surface mesh)")
        from ..volmesh import is_volume_mesh_path
        body_spec = {"kind": "hexfile" if is_volume_mesh_path(body) else "mesh", "path": body}
        if corners:
            body_spec["corners"] = list(corners)
        if untangle_limit is not None:
            body_spec["untangle_limit"] = float(untangle_limit)
    if not grid and body_spec["kind"] != "hexfile":
        raise InputError("--grid NU NV NW is required (except for a hex-mesh file BODY)")
    tpms = {"type": tpms_type, "structure": structure}
    if threshold is not None:
        tpms["threshold"] = threshold
    if porosity is not None:
        tpms["porosity"] = porosity
    if allow_closed_pores:
        tpms["allow_closed_pores"] = True
    recipe = {"job": "hex", "body": body_spec, "tpms": tpms, "element": element,
              "mesh": {"resolution": resolution, "smooth": smooth},
              "cut": "none" if not intersect else (cut or "field"), "output": outputs(out, report, recipe_out)}
    if grid:
        recipe["grid"] = list(grid)
    if refine:
        recipe["refine"] = [list(r) for r in refine]
    if refine_box:
        recipe["refine_box"] = list(refine_box)
    return recipe


@click.command("hex", epilog=EXAMPLES)
@click.argument("body")
@click.argument("tpms_type", metavar="TYPE")
@option("grid", "--grid", nargs=3, type=int, help="Cells NU NV NW of the structured hex mesh (not for hex-mesh files).")
@option("element", "--element", help="8-node trilinear or 20-node serendipity shape functions.")
@option("tpms.structure", "--structure", type=click.Choice(["pore", "rod", "sheet"]))
@option("tpms.threshold", "--threshold", type=float, help="TPMS threshold C.")
@option("tpms.porosity", "--porosity", type=float, help="Target porosity (of the parameter cells) instead of C.")
@option("tpms.allow_closed_pores", "--allow-closed-pores", is_flag=True, help="Build outside the valid range.")
@option("mesh.resolution", "--resolution", "-n", type=int, help="Samples per cell edge.")
@option("mesh.smooth", "--smooth", type=int,
       help="Laplacian smoothing iterations (004 eqs. 4-5), boundary vertices fixed.")
@option("refine", "--refine-point", "refine", nargs=3, type=int, multiple=True, metavar="I J K",
              help="Refine around grid vertex (I, J, K) with the point template (004 Fig. 6): cells of a third "
                   "of the size there (the pores come out about half the size: the template's cells are not "
                   "cubes). Repeatable (no two in one cell).")
@option("refine_box", "--refine-box", nargs=6, type=int, metavar="I0 J0 K0 I1 J1 K1",
              help="Refine the cells I0..I1-1, J0..J1-1, K0..K1-1 into 27 each (004's full template) with "
                   "face/edge/point transition templates around them: pores a third of the size there.")
@option("body.corners", "--corners", nargs=8, type=int, metavar="V0 ... V7",
              help="Mesh vertex ids of the 8 cube corners of a surface BODY (default: chosen automatically).")
@option("body.untangle_limit", "--untangle-limit", type=float, metavar="SECONDS",
       help="Time for untangling the parameterisation of a surface BODY (default 60 s, counted from the work "
            "done, not the clock; 0: no limit); past it the best valid grid is kept, or the job stops with the reason.")
@option("cut", "--cut", help="How a mesh body cuts the scaffold: in field space (max of the structure and the body's "
                   "signed distance, one marching-cubes pass), by a mesh Boolean (manifold3d, 004 §4), or not.")
@click.option("--no-intersect", "intersect", is_flag=True, flag_value=False, default=True,
              help="Do not cut the result to the body (same as --cut none).")
@output_options()
def hex_command(body, tpms_type, grid, element, structure, threshold, porosity, allow_closed_pores, resolution, smooth,
                refine, refine_box, corners, untangle_limit, cut, intersect, out, report, recipe_out, force, as_json):
    """Map one TPMS cell into every hexahedron of a hex mesh (BODY: frustum, cylinder, a closed surface
    mesh parameterised as a deformed cube (000 ch.3), or a hex-mesh file (.vtu .vtk .msh .inp .mesh;
    cube-symmetric types P, IWP, FRD, neovius, tubular_P))."""
    recipe = hex_recipe(body, tpms_type, grid, element, structure, threshold, porosity, resolution, smooth,
                        intersect, out, report, refine, refine_box, corners, cut, recipe_out, untangle_limit,
                        allow_closed_pores)
    run_job(recipe, force, as_json)
