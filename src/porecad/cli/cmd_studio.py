"""``porecad studio``: the local web designer (:mod:`porecad.studio`)."""

from __future__ import annotations

import click


@click.command()
@click.argument("source", metavar="[BODY_OR_RECIPE]", required=False, type=click.Path(dir_okay=False))
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Port on 127.0.0.1 (0: any free port).")
@click.option("--no-browser", is_flag=True, help="Print the address; do not open a browser.")
@click.option("--max-upload-mb", type=click.IntRange(1, 1 << 20), default=256, show_default=True,
              help="Largest upload the page accepts.")
def studio(source, port, no_browser, max_upload_mb):
    """Design scaffolds in the browser, with a live 3D preview (needs `pip install 'porecad[studio]'`).

    Serves a page on 127.0.0.1 only, at an address holding a random key for
    this session. BODY_OR_RECIPE: a body (STL, OBJ, PLY, OFF, 3MF, image), a
    centreline or a recipe to start from. Exports are built by the same job
    code as `porecad build`, which reruns the exported recipe identically.

    \b
    Examples:
      porecad studio
      porecad studio ../shared/data/femur.stl --port 8765
      porecad studio gyroid.toml --no-browser
    """
    from ..studio import launch
    launch(source, port=port, open_browser=not no_browser, max_upload=max_upload_mb << 20,
           echo=lambda text: click.echo(text, err=True))
