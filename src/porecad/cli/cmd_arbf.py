"""``porecad arbf``: anisotropic-RBF pore networks over tet and hex meshes and point clouds (000 ch.5)."""

from __future__ import annotations

import os

import click

from ..errors import InputError
from .console import run_job
from .options import keyed_in, output_options, outputs

option = keyed_in("arbf")

EXAMPLES = """
\b
Examples:
  porecad arbf --mesh tet --basis imq --shape 0.1 --iso 0 --resolution 40 -o tet.stl --json
  porecad arbf --mesh hex-rod --basis gaussian --shape 5 --iso -0.5 -o rod.stl
  porecad arbf --mesh hex --jitter 1.5 --seed 7 -o random.stl
  porecad arbf femur.stl --tets 1000 --local --basis imq --shape 0.1 --iso 0 -o femur-arbf.stl
  porecad arbf part.vtu --local -o part-arbf.stl
  porecad arbf --points cloud.csv --basis gaussian --shape 4 --iso -0.3 -o cloud.stl

\b
The pores are {Φ < iso} (vertices +1, channel skeleton -1, so -1 < iso < 1; the
pores grow with iso); distances are in units of the mean element edge, so
--shape is dimensionless. A point cloud's domain is its bounding box.
"""

MESHES = ("tet", "two-tets", "icosahedron", "hex", "hex2x2x2", "hex-rod")


def arbf_recipe(meshfile, mesh, points, basis, shape, iso, local, ring, jitter, seed, resolution, size, tets,
                out=None, report=None, recipe_out=None, keep_islands=False) -> dict:
    """The recipe of a ``porecad arbf`` command line."""
    from ..volmesh import is_volume_mesh_path
    given = [x for x in (meshfile, mesh, points) if x]
    if len(given) != 1:
        raise InputError("give exactly one domain: --mesh NAME, a MESHFILE or --points FILE" if given else
                         "give a domain: --mesh {" + ",".join(MESHES) + "}, a MESHFILE or --points FILE")
    if mesh:
        domain = {"kind": mesh, "size": size}
    elif points:
        if not os.path.exists(points):
            raise InputError(f"{points}: no such file")
        domain = {"kind": "points", "path": points}
    elif meshfile in MESHES:
        domain = {"kind": meshfile, "size": size}
    else:
        if not os.path.exists(meshfile):
            raise InputError(f"{meshfile}: no such file (MESHFILE is a tet/hex volume mesh or a closed surface)")
        if is_volume_mesh_path(meshfile):
            domain = {"kind": "mesh-file", "path": meshfile}
        else:
            domain = {"kind": "body", "path": meshfile, "tets": 1000 if tets is None else tets}
    if tets is not None and domain["kind"] != "body":
        raise InputError("--tets sets the tet count of a tetrahedralised surface MESHFILE; this domain is given")
    if seed is not None and not jitter:
        raise InputError("--seed needs --jitter S (the random displacement of the centres, mm)")
    spec = {"basis": basis, "shape": shape, "iso": iso, "local": local, "ring": ring}
    if keep_islands:
        spec["islands"] = "keep"
    if jitter:
        spec.update(jitter=jitter, seed=0 if seed is None else seed)
    return {"job": "arbf", "domain": domain, "arbf": spec, "mesh": {"resolution": resolution},
            "output": outputs(out, report, recipe_out)}


@click.command(epilog=EXAMPLES)
@click.argument("meshfile", required=False)
@option("domain.kind", "--mesh", default=None, type=click.Choice(MESHES),
              help="A built-in domain: one regular tet, two tets, an icosahedron of 20 tets, one hex, "
                   "2x2x2 hexes or a rod of 4 hexes (000 Figs. 5.6-5.7).")
@click.option("--points", type=click.Path(dir_okay=False),
              help="A point cloud with values: 'x y z value' per row (.txt/.csv/.xyz, or .npy (N, 4)); "
                   "the domain is the points' bounding box.")
@option("arbf.basis", "--basis", type=click.Choice(["gaussian", "mq", "imq", "tps"], case_sensitive=False),
              help="Radial basis function (000 Table 5.1).")
@option("arbf.shape", "--shape", type=float,
       help="Shape parameter c (distances in mean element edges; 000 uses IMQ with c = 0.1).")
@option("arbf.iso", "--iso", type=float, help="Iso-value: pores where the interpolant is below it (-1 < iso < 1).")
@option("arbf.local", "--local", is_flag=True,
              help="Solve per cell with its first ring of neighbours (000 Fig. 5.5) instead of one global system.")
@option("arbf.ring", "--ring", help="The neighbour ring of a local system: cells sharing a vertex (closest to the global "
                   "solve) or a face (smaller, smoother systems for the long-tailed IMQ/MQ on large meshes).")
@option("arbf.jitter", "--jitter", type=float,
       help="Move every centre at random by up to S mm (000 Fig. 5.10); boundary centres stay on "
                   "their boundary plane.")
@option("arbf.seed", "--seed", default=None, type=int, help="Random seed of --jitter [default: 0].")
@option("mesh.resolution", "--resolution", "-n", type=int,
       help="Grid samples per mean element edge (point cloud: per mean nearest-neighbour distance).")
@option("domain.size", "--size", type=float,
       help="Edge length (mm) of the built-in domains (icosahedron: circumradius).")
@option("domain.tets", "--tets", default=None, type=int,
       help="Target tet count when MESHFILE is a closed surface [default: 1000].")
@option("arbf.islands", "--keep-islands", is_flag=True,
       help="Keep loose pieces of material that do not touch the largest one (dropped and reported by default).")
@output_options()
def arbf(meshfile, mesh, points, basis, shape, iso, local, ring, jitter, seed, resolution, size, tets, keep_islands,
         out, report, recipe_out, force, as_json):
    """Build a porous solid from an anisotropic-RBF pore network (000 ch.5) over a tet or hex mesh or a
    point cloud. MESHFILE: a volume mesh (.vtu .vtk .msh .inp .mesh: tets or hexes) or a closed surface
    (tetrahedralised on a BCC lattice, the scaffold cut to it); or --mesh NAME, or --points FILE."""
    recipe = arbf_recipe(meshfile, mesh, points, basis.lower(), shape, iso, local, ring, jitter, seed, resolution,
                         size, tets, out, report, recipe_out, keep_islands=keep_islands)
    run_job(recipe, force, as_json)
