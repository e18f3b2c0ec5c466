"""``porecad analyze``: the metrics of a mesh made anywhere."""

from __future__ import annotations

import click

from .console import emit

EXAMPLES = """
\b
Examples:
  porecad analyze scaffold.stl --json
  porecad analyze scaffold.stl --pores --voxel 0.05 --min-feature 0.3 --json
  porecad analyze scaffold.stl --pores --report scaffold-report/
  porecad analyze infill.stl --pores --domain body.stl --json
"""


@click.command(epilog=EXAMPLES)
@click.argument("mesh_file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--domain-volume", type=float,
              help="Volume of the design domain for the porosity (default: the bounding box).")
@click.option("--check-intersections/--no-check-intersections", default=True, show_default=True)
@click.option("--pores", is_flag=True,
              help="Pore and strut sizes (local thickness), interconnectivity, permeability estimate.")
@click.option("--voxel", type=float,
              help="Voxel size in mm for --pores (default: a quarter of the mean wall or pore width, 2V/S).")
@click.option("--min-feature", type=float, help="Flag struts/walls thinner than this (mm).")
@click.option("--min-pore", type=float, help="Flag pores smaller than this (mm).")
@click.option("--domain", "domain_file", type=click.Path(dir_okay=False),
              help="Design domain: the closed body mesh the scaffold fills (porosity, sizes, connectivity "
                   "are measured inside it, not in the bounding box).")
@click.option("--skin", type=float, help="Thickness (mm) of a closing shell: split the closed pores it makes.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False),
              help="Write report.json, report.html and PNG plots to this directory.")
@click.option("--force", is_flag=True, help="Overwrite an existing report directory's files.")
def analyze(mesh_file, as_json, domain_volume, check_intersections, pores, voxel, min_feature, min_pore,
            domain_file, skin, report_dir, force):
    """Analyse a mesh: volume, area, porosity, topology, validity; with --pores sizes and connectivity."""
    from ..analysis.report import analyze_mesh, check_report_dir, write_report
    if report_dir is not None:
        check_report_dir(report_dir, force)  # before any work
    report, fields = analyze_mesh(mesh_file, domain_volume=domain_volume, check_intersections=check_intersections,
                                  pores=pores or report_dir is not None or domain_file is not None
                                  or skin is not None, voxel=voxel, min_feature=min_feature,
                                  min_pore=min_pore, keep_fields=report_dir is not None, domain=domain_file,
                                  skin=skin)
    if report_dir is not None:
        report["report_dir"] = str(write_report(report_dir, report, fields, force=force))
    emit(report, as_json, ("porosity", "volume", "surface_area", "specific_surface", "area_per_volume",
                           "pore_size_mean", "strut_size_mean", "self_intersections", "oriented"))
