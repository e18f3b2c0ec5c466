"""``porecad export``: a tpms/infill recipe's design as a 3MF level set of its function (no triangles)."""

from __future__ import annotations

import click

from .console import emit

EXAMPLES = """
\b
Examples:
  porecad tpms G --structure sheet --porosity 0.7 --cells 8 8 8 --cell-size 2.5 -o cube.stl --recipe cube.toml
  porecad export cube.toml -o cube.3mf --implicit      # the gyroid sheet as a function graph, a few kB
  porecad export infill.toml -o part.3mf --implicit --force --json
"""


@click.command("export", epilog=EXAMPLES)
@click.argument("recipe_file", type=click.Path(dir_okay=False))
@click.option("-o", "--out", required=True, type=click.Path(dir_okay=False), help="The .3mf file to write.")
@click.option("--implicit", is_flag=True,
              help="Write the design as a 3MF Volumetric & Implicit level set (needs porecad[3mf]: lib3mf 2.5).")
@click.option("--force", is_flag=True, help="Overwrite an existing file.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
def export(recipe_file, out, implicit, force, as_json):
    """Write a tpms or infill recipe's design as an implicit 3MF (a function graph and its level set).

    The TPMS, its cell size and origin, the structure, the threshold (a porosity resolved with porecad's
    calibration; a linear or radial threshold ramp) and the domain (the box, cut in the function; a
    body's mesh, as the level set's evaluation mesh) become nodes of a 3MF implicit function; see
    docs/printing.md. The mesh of the same recipe is written by porecad build.
    """
    if not implicit:
        raise click.UsageError("give --implicit: export writes the design as an implicit 3MF (the mesh is "
                               "written by porecad build)")
    from ..jobs.implicit_export import export_implicit
    report = export_implicit(recipe_file, out, force=force)
    emit(report, as_json, ("file", "bytes", "nodes", "type", "structure", "threshold", "domain"))
