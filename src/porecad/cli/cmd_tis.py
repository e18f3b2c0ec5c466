"""``porecad tis``: tetrahedral implicit surfaces over tet meshes (documents 002 and 000 ch.4)."""

from __future__ import annotations

import os

import click

from ..errors import InputError
from .console import run_job
from .options import keyed, keyed_in, output_options, outputs

option = keyed_in("tis")

EXAMPLES = """
\b
Examples:
  porecad tis --regular-tet --type G --lambda 1 --relative-threshold 0.529 --resolution 200 -o tet.stl --json
  porecad tis femur.stl --type P --lambda 1 --relative-threshold 0.176 --tets 1000 --smooth 3 -o femur-tis.stl
  porecad tis part.vtu --type D --lambda 2 --relative-threshold 0.667 -o part-tis.stl
  porecad tis icosahedron --type P --lambda 1 --relative-threshold 0.16 -o ico.stl --save-tets ico.vtu
"""


def tis_recipe(body, regular_tet, tis_type, lam, relative, threshold, tets, resolution, method, smooth,
               structure, size, out=None, report=None, save_tets=None, recipe_out=None) -> dict:
    """The recipe of a ``porecad tis`` command line."""
    from ..volmesh import is_volume_mesh_path
    if regular_tet and body:
        raise InputError("give either BODY or --regular-tet, not both")
    if regular_tet or body == "regular-tet":
        domain = {"kind": "regular-tet", "size": size}
    elif body in ("two-tets", "icosahedron"):
        domain = {"kind": body, "size": size}
    elif not body:
        raise InputError("give BODY (a closed surface mesh, a tet-mesh file, two-tets or icosahedron) "
                         "or --regular-tet")
    else:
        if not os.path.exists(body):
            raise InputError(f"{body}: no such file (BODY is a closed surface mesh, a tet-mesh file, "
                             "two-tets, icosahedron or regular-tet)")
        domain = {"kind": "tet-mesh", "path": body} if is_volume_mesh_path(body) else \
            {"kind": "body", "path": body, "tets": tets}
    if tets is not None and domain["kind"] != "body":
        raise InputError("--tets sets the tet count of a tetrahedralised surface BODY; this domain is given")
    tis = {"type": tis_type, "lambda": lam, "structure": structure, "relative": relative, "threshold": threshold}
    mesh = {"resolution": resolution, "method": method, "smooth": smooth}
    return {"job": "tis", "domain": {k: v for k, v in domain.items() if v is not None},
            "tis": {k: v for k, v in tis.items() if v is not None},
            "mesh": {k: v for k, v in mesh.items() if v is not None},
            "output": outputs(out, report, recipe_out, tets=save_tets)}


@click.command(epilog=EXAMPLES)
@click.argument("body", required=False)
@click.option("--regular-tet", is_flag=True, help="One regular tetrahedron (edge --size) as the domain.")
@option("tis.type", "--type", "tis_type", type=click.Choice(["P", "D", "G"], case_sensitive=False),
       help="TIS type (002 eq. 3; G in its cyclic form).")
@option("tis.lambda", "--lambda", "lam", type=float, help="Periods along each tetrahedral coordinate (002 eq. 2).")
@option("tis.relative", "--relative-threshold", "relative", type=float,
       help="R in [0, 1]: C = min + R (max - min) over the computed TIS values (002 eq. 7).")
@option("tis.threshold", "--threshold", type=float, help="The absolute level C instead.")
@option("domain.tets", "--tets", default=None, type=int,
       help="Target tetrahedron count when BODY is a surface mesh [default: 1000].")
@option("mesh.resolution", "--resolution", "-n", default=None, type=int,
       help="Samples per tetrahedron edge [default: 200 for --regular-tet, else 17].")
@option("mesh.method", "--method", help="Polygonise per tetrahedron on its barycentric lattice, or on a Cartesian grid "
            "(RESOLUTION samples per mean tet edge) with point location.")
@option("mesh.smooth", "--smooth", type=int,
       help="Smoothing iterations: Laplacian (Taubin) then curvature-based (cotangent flow).")
@option("tis.structure", "--structure", help="Material where the TIS value is ≥ C (pore) or ≤ C (rod).")
@option("domain.size", "--size", type=float,
       help="Edge length (mm) of the built-in domains (regular-tet, two-tets; icosahedron radius).")
@output_options(extra=[keyed("output.tets", "--save-tets", type=click.Path(dir_okay=False),
                             help="Also write the tet mesh (.vtu .vtk .msh .inp .mesh).")])
def tis(body, regular_tet, tis_type, lam, relative, threshold, tets, resolution, method, smooth, structure, size,
        out, save_tets, report, recipe_out, force, as_json):
    """Build a porous solid from tetrahedral implicit surfaces (TIS) over a tet mesh. BODY: a closed
    surface mesh (tetrahedralised on a BCC lattice, the result cut to the body), a tet-mesh file
    (.vtu .vtk .msh .inp .mesh), two-tets or icosahedron; or --regular-tet."""
    recipe = tis_recipe(body, regular_tet, tis_type.upper(), lam, relative, threshold, tets, resolution, method,
                        smooth, structure, size, out, report, save_tets, recipe_out)
    run_job(recipe, force, as_json)
