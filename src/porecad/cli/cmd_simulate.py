"""``porecad volmesh`` and ``porecad properties``: volume meshes, stiffness and permeability (issue 23).

A thin layer: options are parsed here and passed to :mod:`porecad.simulate`,
which holds all the logic.
"""

from __future__ import annotations

import json

import click

from ..errors import InputError
from ..io.jsonable import json_default
from .console import Progress

EXAMPLES_VOLMESH = """
\b
Examples:
  porecad volmesh gyroid.stl -o gyroid.msh --size 0.05 --json
  porecad volmesh gyroid.toml -o cell.inp --periodic --order 2 --size 0.05
  porecad volmesh femur_infill.stl -o femur.vtu --order 2
"""

EXAMPLES_PROPERTIES = """
\b
Examples:
  porecad properties gyroid.toml --stiffness --E 110000 --nu 0.34 --voxels 64 --json
  porecad properties gyroid.toml --permeability --voxels 64
  porecad properties gyroid.toml --stiffness --sweep 0.5,0.6,0.7,0.8 --voxels 48 --report props.json
  porecad properties gyroid.toml --voxels 48 --report mechanics.html
  porecad properties scaffold.stl --permeability --block --voxels 96
"""


def volmesh_run(source, out, order=1, size=None, periodic=False, force=False, progress=None) -> dict:
    """Build the volume mesh of a mesh file or recipe and write it (the body of ``porecad volmesh``)."""
    from pathlib import Path

    import numpy as np

    from ..io.atomic import check_output_path
    from ..jobs.design_source import load_source, periodic_cell, solid_mesh_of
    from ..simulate.tetmesh_solid import VOLUME_MESH_FORMATS, periodic_volume_mesh, volume_mesh, write_volume_mesh

    if not out:
        raise InputError("give the output file with -o OUT.msh (or .vtu, .inp, .mesh)")
    suffix = Path(out).suffix.lower()
    if suffix not in VOLUME_MESH_FORMATS:
        raise InputError(f"{out}: unsupported volume mesh format (use {', '.join(VOLUME_MESH_FORMATS)})")
    if order == 2 and suffix == ".mesh":
        raise InputError(f"{out}: Medit .mesh files hold linear tets only; use .msh, .vtu or .inp for --order 2")
    check_output_path(out, force=force)  # before any work
    src = load_source(source)
    if periodic:
        if src["kind"] != "recipe":
            raise InputError("--periodic needs a tpms recipe of a box of whole cells (the periodic field)")
        cell = periodic_cell(src["recipe"])
        lo, hi = cell["lo"], cell["hi"]
        h = float(size) if size is not None else float(np.min(hi - lo)) / 24
        mesh = periodic_volume_mesh(cell["field"], lo, hi, h, order=order)
    else:
        v, f, _ = solid_mesh_of(src, progress)
        mesh = volume_mesh(v, f, size=size, order=order, progress=progress)
    path = write_volume_mesh(out, mesh["points"], mesh["cells"], mesh["cell_type"], force=force)
    report = {k: mesh[k] for k in ("quality", "surface", "sliver_repair", "surface_volume", "volume_error",
                                   "cell_type", "order") if k in mesh}
    report["element"] = "C3D10" if mesh["order"] == 2 else "C3D4"
    report["nodes"] = int(len(mesh["points"]))
    if "periodic" in mesh:
        report["periodic"] = mesh["periodic"]
    report["mesh_file"] = str(path)
    return report


@click.command(epilog=EXAMPLES_VOLMESH)
@click.argument("source", metavar="MESH_OR_RECIPE")
@click.option("-o", "--out", type=click.Path(dir_okay=False), help="Output volume mesh (.msh .vtu .inp .mesh).")
@click.option("--order", type=click.Choice(["1", "2"]), default="1", show_default=True,
              help="1: linear tets (C3D4); 2: quadratic tets (C3D10).")
@click.option("--size", type=float, help="Target element edge length in mm (default: the surface's edge length).")
@click.option("--periodic", is_flag=True,
              help="Periodic mesh of a unit-cell recipe: nodes on opposite faces match.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--force", is_flag=True, help="Overwrite an existing output.")
def volmesh(source, out, order, size, periodic, as_json, force):
    """Tetrahedral volume mesh of a closed solid (a mesh file, or a recipe that builds one).

    The surface is remeshed to remove marching-cubes slivers, meshed by TetGen
    (needs porecad[simulate]; TetGen is AGPL-3.0) and checked: no inverted
    tets, volume within 0.5 % of the surface's; the report gives the quality
    (dihedral angles, radius ratio, aspect ratio).
    """
    report = volmesh_run(source, out, order=int(order), size=size, periodic=periodic, force=force,
                         progress=Progress())
    if as_json:
        click.echo(json.dumps(report, default=json_default))
        return
    q = report["quality"]
    click.echo(f"{'mesh_file':>18}: {report['mesh_file']}")
    click.echo(f"{'elements':>18}: {q['tets']} {report['element']}, {report['nodes']} nodes")
    click.echo(f"{'dihedral_deg':>18}: min {q['dihedral_deg']['min']:.2f}, max {q['dihedral_deg']['max']:.2f}, "
               f"below 5 deg: {q['below_5deg']}")
    d = q["dihedral_deg"]
    click.echo(f"{'dihedral_pct_deg':>18}: tets' smallest angle p0.1 {d['p01']:.2f}, p1 {d['p1']:.2f}, "
               f"p5 {d['p5']:.2f}; all angles median {d['median']:.2f}")
    hist = d["histogram"]
    click.echo(f"{'dihedral_hist':>18}: " + ", ".join(f"{a:g}-{b:g}: {c}" for a, b, c in
                                                       zip(hist["edges"][:-1], hist["edges"][1:], hist["counts"])))
    click.echo(f"{'radius_ratio_min':>18}: {q['radius_ratio']['min']:.4f}")
    click.echo(f"{'volume_error':>18}: {100 * report['volume_error']:.3f} %")
    if "periodic" in report:
        click.echo(f"{'periodic':>18}: {'matched' if report['periodic']['matched'] else 'NOT matched'}")


def _sweep_values(text):
    if text is None:
        return None
    try:
        vals = [float(t) for t in str(text).replace(";", ",").split(",") if t.strip()]
    except ValueError:
        raise InputError(f"--sweep takes comma-separated porosities, got {text!r}") from None
    return vals


@click.command(epilog=EXAMPLES_PROPERTIES)
@click.argument("source", metavar="MESH_OR_RECIPE")
@click.option("--stiffness", is_flag=True, help="Homogenised 6x6 stiffness by periodic voxel FE.")
@click.option("--permeability", is_flag=True, help="Darcy permeability tensor by a Stokes solve.")
@click.option("--E", "E", type=float, default=1.0, show_default=True, help="Solid Young's modulus (MPa).")
@click.option("--nu", type=float, default=0.3, show_default=True, help="Solid Poisson ratio.")
@click.option("--voxels", type=int, default=64, show_default=True, help="Voxels along the cell's shortest edge.")
@click.option("--sweep", help="Porosities for a Gibson-Ashby sweep, e.g. 0.5,0.6,0.7 (recipes only).")
@click.option("--block", is_flag=True, help="Permeability of a non-periodic sample block (diagonal only).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--report", type=click.Path(dir_okay=False),
              help="Write the report to this file: .html the 'Mechanics and flow' page (tensor, "
                   "directional-modulus map, permeability, sweep plot), else JSON.")
@click.option("--force", is_flag=True, help="Overwrite an existing report.")
def properties(source, stiffness, permeability, E, nu, voxels, sweep, block, as_json, report, force):
    """Effective stiffness and permeability of a design (a recipe or a closed mesh).

    Without --stiffness or --permeability both are computed.
    """
    from ..io.atomic import check_output_path
    from ..jobs.design_source import design_properties

    if report:
        check_output_path(report, force=force)
    values = _sweep_values(sweep)
    if not stiffness and not permeability and not values:
        stiffness = permeability = True
    out = design_properties(source, stiffness=stiffness, permeability=permeability, E=E, nu=nu, voxels=voxels,
                            sweep=values, block=block, progress=Progress())
    if report:
        from ..simulate.properties_page import write_properties_report
        write_properties_report(report, out, force=force)
        out["report_file"] = str(report)
    if as_json:
        click.echo(json.dumps(out, default=json_default))
        return
    if "cell" in out:
        c = out["cell"]
        click.echo(f"cell: {c['grid']} voxels of {c['voxel_mm']:.4g} mm, porosity {c['porosity_voxel']:.4f}")
    if "stiffness" in out:
        s = out["stiffness"]
        click.echo("stiffness C (MPa, Voigt 11 22 33 23 13 12):")
        for row in s["C_MPa"]:
            click.echo("  " + " ".join(f"{x:11.4g}" for x in row))
        e = s["engineering"]
        click.echo(f"E1 E2 E3 = {e['E1']:.4g} {e['E2']:.4g} {e['E3']:.4g} MPa; G23 G13 G12 = {e['G23']:.4g} "
                   f"{e['G13']:.4g} {e['G12']:.4g} MPa; nu12 = {e['nu12']:.4f}; Zener = {e['zener_ratio']:.4f}")
        d = s["directional_modulus"]
        click.echo(f"directional E: max {d['E_max']:.4g} along {d['E_max_direction']}, "
                   f"min {d['E_min']:.4g} along {d['E_min_direction']}")
    if "permeability" in out:
        p = out["permeability"]
        click.echo("permeability (mm^2):")
        for row in p["permeability_mm2"]:
            click.echo("  " + " ".join(f"{x:11.4g}" for x in row))
        click.echo(f"tortuosity: {p['tortuosity']}; {p['note']}")
        if "kozeny_carman_mm2" in p:
            click.echo(f"Kozeny-Carman estimate: {p['kozeny_carman_mm2']:.4g} mm^2")
    if "sweep" in out:
        sw = out["sweep"]
        click.echo("porosity  rel.density  E/Es")
        for r in sw["rows"]:
            if "error" in r:
                click.echo(f"{r['porosity']:8.3f}  error: {r['error']}")
            else:
                click.echo(f"{r['porosity']:8.3f}  {r['relative_density']:11.4f}  {r['relative_modulus']:.5g}")
        if sw["fit"]:
            click.echo(f"Gibson-Ashby fit: E/Es = {sw['fit']['C']:.4g} (rho)^{sw['fit']['n']:.3f}")
