"""``porecad slice``: layer files for a printer, straight from a design's field (or a mesh), with printability."""

from __future__ import annotations

import click

from .console import Progress, emit, warn
from .options import max_memory_option, memory_limit

EXAMPLES = """
\b
Examples:
  porecad slice g.toml -o g.zip                     # PNG layers (DLP/SLA) from the recipe's field
  porecad slice g.toml -o g.svg --pixel 0.025 --layer 0.025
  porecad slice part.stl -o part.cli --printer slm.toml --orient auto
  porecad slice g.toml -o g.zip --printer dlp.toml --strict   # refuse a part the printer cannot print
  porecad slice g.toml -o g.sl1 --printer prusa-sl1 --report g-slices.json   # Prusa SL1 (a preset), and the report
  porecad slice g.toml -o g.zip --pixel-x 0.019 --pixel-y 0.024   # non-square pixels
"""


@click.command("slice", epilog=EXAMPLES)
@click.argument("source", type=click.Path(dir_okay=False))
@click.option("-o", "--out", required=True, type=click.Path(dir_okay=False),
              help="Slice file: .zip (PNG layers), .sl1 / .sl1s (Prusa), .uvj (UVtools), .svg (layered SVG), "
                   ".cli / .clib (Common Layer Interface; a large .cli is binary).")
@click.option("--format", "fmt", type=click.Choice(["png", "sl1", "uvj", "svg", "cli", "cli-binary"]),
              help="Slice format (default: from the output's extension).")
@click.option("--pixel", type=float, help="Pixel size in mm, x and y (default: the printer's).")
@click.option("--pixel-x", "pixel_x", type=float, help="Pixel size along x in mm (with --pixel-y: not square).")
@click.option("--pixel-y", "pixel_y", type=float, help="Pixel size along y in mm (default: --pixel-x's).")
@click.option("--layer", type=float, help="Layer height in mm (default: the printer's).")
@click.option("--printer", "printer_file",
              help="Printer profile: a TOML file (build, pixel, pixel_x, pixel_y, layer, min_feature, min_channel, "
                   "max_overhang, layer_time, exposure, bottom_exposure, bottom_layers, place, display_*, model, "
                   "format) or a preset's name: prusa-sl1, prusa-sl1s, elegoo-saturn-4-ultra, generic-slm.")
@click.option("--orient", help="Build direction: 'auto' (the least unsupported area of 26) or x,y,z.")
@click.option("--strict", is_flag=True, help="Refuse (write nothing) when the part has printability findings.")
@click.option("--no-check", "no_check", is_flag=True, help="Skip the wall, channel and closed-pore checks.")
@click.option("--scheduler", help="Spread a field's layer bands over dask workers: local:N or tcp://HOST:PORT "
                                   "(dask exchanges pickles with it: only a scheduler you trust).")
@click.option("--mesh", "mesh_out", type=click.Path(dir_okay=False),
              help="Also write the part's mesh as printed (turned by --orient); a field part is meshed at --mesh-voxel.")
@click.option("--mesh-voxel", type=float, help="Voxel (mm) of --mesh for a field part (default: 4 pixels).")
@click.option("--report", "report_out", type=click.Path(dir_okay=False),
              help="Also write the slice report (JSON).")
@click.option("--force", is_flag=True, help="Overwrite an existing slice file (and report).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@max_memory_option
def slice_command(source, out, fmt, pixel, pixel_x, pixel_y, layer, printer_file, orient, strict, no_check, scheduler,
                  mesh_out, mesh_voxel, report_out, force, as_json):
    """Slice a recipe (tpms/infill: from its field; other jobs: their mesh) or a mesh file for a printer."""
    from ..api import slice as slice_part
    from ..io import atomic_write, check_output_path
    from ..io.jsonable import dumps
    if report_out is not None:
        check_output_path(report_out, force=force)
    if pixel is not None and (pixel_x is not None or pixel_y is not None):
        raise click.UsageError("give --pixel, or --pixel-x and --pixel-y, not both")
    if pixel_x is not None or pixel_y is not None:
        pixel = (pixel_x if pixel_x is not None else pixel_y, pixel_y if pixel_y is not None else pixel_x)
    progress = Progress()
    if orient is not None and orient != "auto":
        try:
            orient = [float(v) for v in orient.split(",")]
        except ValueError:
            raise click.BadParameter("give 'auto' or a direction x,y,z", param_hint="--orient") from None
    try:
        report = slice_part(source, out, printer=printer_file, pixel=pixel, layer=layer, fmt=fmt, orient=orient,
                            strict=strict, check=not no_check, force=force, progress=progress,
                            scheduler=scheduler, mesh_out=mesh_out, mesh_voxel=mesh_voxel,
                            memory_limit=memory_limit())
    finally:
        progress.close()
    warn(report)
    if report_out is not None:
        with atomic_write(report_out, force=force) as fh:
            fh.write((dumps(report, indent=1) + "\n").encode())
        report["report_file"] = str(report_out)
    if not as_json:
        report = {k: v for k, v in report.items() if k != "layer_area"}
    emit(report, as_json, ("slices", "route", "format", "layers", "pixel", "layer", "height", "print_time",
                           "report_file", "seconds"))
