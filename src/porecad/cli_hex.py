"""``porecad hex``: TPMS cells mapped into hexahedral meshes (documents 000 ch.3 and 004)."""

from __future__ import annotations

import os
import sys

import click

from .errors import InputError

EXAMPLES_HEX = """
\b
Examples:
  porecad hex cylinder P --grid 4 4 6 --element hex20 --structure pore --porosity 0.6 --resolution 16 -o cyl.stl --json
  porecad hex frustum IWP --grid 4 4 4 --structure pore --threshold 0 -o frustum.stl
  porecad hex frustum P --grid 4 4 4 --threshold 0 --refine-point 1 1 1 -o frustum-refined.stl --json
  porecad hex cylinder IWP --grid 4 4 4 --threshold 0 --refine-box 1 1 1 3 3 3 -o cyl-refined.stl
  porecad hex femur.stl P --grid 5 7 20 --structure pore --threshold 0 --resolution 12 -o femur-hex.stl
"""


def hex_recipe(body, tpms_type, grid, element, structure, threshold, porosity, resolution, smooth, intersect,
               out, report, refine=(), refine_box=None, corners=None, cut=None, untangle_limit=None) -> dict:
    if body in ("frustum", "cylinder"):
        body_spec = {"kind": body}
    else:
        if not os.path.exists(body):
            raise InputError(f"{body}: no such file (BODY is frustum, cylinder or a closed surface mesh)")
        from .volmesh import is_volume_mesh_path
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
    output = {k: v for k, v in (("mesh", out), ("report", report)) if v}
    return {"job": "hex", "body": body_spec, "tpms": tpms, "grid": list(grid) if grid else None, "element": element,
            "mesh": {"resolution": resolution, "smooth": smooth}, "intersect": intersect, "output": output,
            "cut": "none" if not intersect else (cut or "field"),
            "refine": [list(r) for r in refine], "refine_box": list(refine_box) if refine_box else None}


@click.command(epilog=EXAMPLES_HEX)
@click.argument("body")
@click.argument("tpms_type", metavar="TYPE")
@click.option("--grid", nargs=3, type=int, help="Cells NU NV NW of the structured hex mesh (not for hex-mesh files).")
@click.option("--element", type=click.Choice(["hex8", "hex20"]), default="hex8", show_default=True,
              help="8-node trilinear or 20-node serendipity shape functions.")
@click.option("--structure", type=click.Choice(["pore", "rod", "sheet"]), default="pore", show_default=True)
@click.option("--threshold", type=float, help="TPMS threshold C.")
@click.option("--porosity", type=float, help="Target porosity (of the parameter cells) instead of C.")
@click.option("--resolution", "-n", type=int, default=16, show_default=True, help="Samples per cell edge.")
@click.option("--smooth", type=int, default=0, show_default=True,
              help="Laplacian smoothing iterations (004 eqs. 4-5), boundary vertices fixed.")
@click.option("--refine-point", "refine", nargs=3, type=int, multiple=True, metavar="I J K",
              help="Refine around grid vertex (I, J, K) with the point template (004 Fig. 6): cells of a third "
                   "of the size there, pores a third of the size. Repeatable (no two in one cell).")
@click.option("--refine-box", nargs=6, type=int, metavar="I0 J0 K0 I1 J1 K1",
              help="Refine the cells I0..I1-1, J0..J1-1, K0..K1-1 into 27 each (004's full template) with "
                   "face/edge/point transition templates around them: pores a third of the size there.")
@click.option("--corners", nargs=8, type=int, metavar="V0 ... V7",
              help="Mesh vertex ids of the 8 cube corners of a surface BODY (default: chosen automatically).")
@click.option("--untangle-limit", type=float, metavar="SECONDS",
              help="Time for untangling the parameterisation of a surface BODY (default 90 s; 0: no limit); past it "
                   "the best valid grid is kept, or the job stops with the reason.")
@click.option("--cut", type=click.Choice(["field", "boolean", "none"]), default="field", show_default=True,
              help="How a mesh body cuts the scaffold: in field space (max of the structure and the body's "
                   "signed distance, one marching-cubes pass), by a mesh Boolean (manifold3d, 004 §4), or not.")
@click.option("--no-intersect", "intersect", is_flag=True, flag_value=False, default=True,
              help="Do not cut the result to the body (same as --cut none).")
@click.option("-o", "--out", type=click.Path(dir_okay=False), help="Output mesh (.stl .ply .obj .3mf).")
@click.option("--report", type=click.Path(), help="Report: a .json file or a directory.")
@click.option("--force", is_flag=True, help="Overwrite existing outputs.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
def hex(body, tpms_type, grid, element, structure, threshold, porosity, resolution, smooth, refine, refine_box,
        corners, untangle_limit, cut, intersect, out, report, force, as_json):
    """Map one TPMS cell into every hexahedron of a hex mesh (BODY: frustum, cylinder, a closed surface
    mesh parameterised as a deformed cube (000 ch.3), or a hex-mesh file (.vtu .vtk .msh .inp .mesh;
    cube-symmetric types P, IWP, FRD, neovius, tubular_P))."""
    from .cli import _emit, _Progress
    from .hex_pipeline import run_hex
    recipe = hex_recipe(body, tpms_type, grid, element, structure, threshold, porosity, resolution, smooth,
                        intersect, out, report, refine, refine_box, corners, cut, untangle_limit)
    result = run_hex(recipe, force=force, progress=_Progress(sys.stderr.isatty()))
    _emit(result, as_json)
