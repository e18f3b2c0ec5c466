"""Starting a studio: the session with the user's file in it, the server, the browser."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError


def require_server():
    """The studio needs Starlette and uvicorn (the ``studio`` extra): a one-line error without them."""
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError:
        raise InputError("the studio needs its extra: pip install 'porecad[studio]'") from None


def first_design(session, source) -> tuple[dict, list[str]]:
    """The form's first values for a file named on the command line (copied into the session)."""
    from .design import design_of
    from .session import upload_kind
    if source is None:
        return {"job": "tpms"}, []
    p = Path(source)
    if p.suffix.lower() == ".toml":
        from ..io.recipe import read_recipe
        recipe = read_recipe(p)
        notes = []
        for table in ("domain", "body", "input"):
            t = recipe.get(table)
            if isinstance(t, dict) and isinstance(t.get("path"), str):
                src = Path(t["path"])
                src = src if src.is_absolute() else p.resolve().parent / src
                session.adopt(src)  # the user named this recipe: its inputs come with it
        notes.append(f"opened {p.name}")
        return design_of(recipe, session.upload_name), notes
    kind = upload_kind(p.name)
    info = session.adopt(p)
    job = {"mesh": "infill", "image": "infill", "volume": "tis", "centreline": "vessel"}[kind]
    design = {"job": job, ("centreline" if job == "vessel" else "body"): info["name"]}
    if job == "infill":
        lo, hi = info.get("bounds") or ([0, 0, 0], [50, 50, 50])
        ext = min(float(b) - float(a) for a, b in zip(lo, hi))
        design["cell_size"] = round(max(ext / 8.0, 0.1), 1)  # a few cells across the body
    return design, [f"{p.name} opened ({kind})"]


def make_studio(source=None, max_upload: int | None = None, threads=None):
    """A :class:`~porecad.studio.server.Studio` (its session holds ``source`` if given)."""
    require_server()
    from .server import Studio
    from .session import MAX_UPLOAD, Session
    session = Session(max_upload=max_upload or MAX_UPLOAD)
    try:
        design, notes = first_design(session, source)
    except BaseException:
        session.close()
        raise
    studio = Studio(session, design, threads=threads)
    studio.notices = notes
    return studio


def serve(studio, port: int = 0, open_browser: bool = True, echo=print) -> None:
    """Serve ``studio`` on 127.0.0.1 until interrupted; its work folder is removed afterwards."""
    from .server import Server
    server = Server(studio, port)
    echo(f"porecad studio: {server.url}")
    echo("porecad studio: the address holds this session's key; press Ctrl-C to stop")
    if open_browser:
        import webbrowser
        try:
            webbrowser.open(server.url)
        except Exception:  # noqa: BLE001 - no browser: the printed address is enough
            pass
    try:
        server.run()
    finally:
        server.sock.close()
        studio.close()
