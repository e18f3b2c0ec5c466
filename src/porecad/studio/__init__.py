"""porecad studio: a local web designer with a live 3D preview.

``porecad studio`` serves a page on 127.0.0.1 (Starlette routes under uvicorn;
three.js and every other file the page loads ship in ``studio/static``) where
a design is a filled form: :mod:`~porecad.studio.design` turns it into the
recipe that ``porecad build`` runs, :mod:`~porecad.studio.preview` runs that
recipe's job on a coarser sampling (and a window at full sampling) for the
preview, and :mod:`~porecad.studio.tasks` exports it with the same job code.
:mod:`~porecad.studio.session` keeps each session's token, uploads and work
folder; :mod:`~porecad.studio.server` is the HTTP layer. Install with
``pip install "porecad[studio]"``.
"""

from __future__ import annotations

__all__ = ["launch"]


def launch(source=None, port: int = 0, open_browser: bool = True, max_upload: int | None = None, echo=print):
    """Start a studio (optionally on a body or recipe file) and serve until interrupted.

    Parameters
    ----------
    source : path, optional
        A body (mesh, image), a centreline, a tet mesh or a recipe (``.toml``):
        copied into the session and opened in the form.
    port : int
        TCP port on 127.0.0.1 (0: any free one).
    open_browser : bool
        Open the page in the default browser.
    max_upload : int, optional
        Largest upload in bytes.
    echo : callable
        Where the address is printed.
    """
    from .launcher import make_studio, serve
    studio = make_studio(source, max_upload)
    serve(studio, port, open_browser, echo)
