"""The studio's HTTP server: Starlette routes behind a token check, served by uvicorn on 127.0.0.1.

Every request must carry the session's token as the first part of its path
(``/s/TOKEN/...``, compared in constant time) and name this server in its
``Host`` header (127.0.0.1 or localhost at this port: a page elsewhere cannot
reach it through DNS rebinding); anything else gets 403 before any route
runs. The page, its script and three.js are files of the installed package
(``studio/static``), sent with a content security policy that allows only
this origin. Bodies are bounded: JSON requests at :data:`MAX_JSON` bytes,
uploads at the session's limit (a declared length over it is refused before
a byte is read; the count is checked as the bytes arrive). Every error is a
JSON ``{"error": "one line", "field": ...}`` and the server goes on serving.
"""

from __future__ import annotations

import hmac
import json
import socket
import threading
from pathlib import Path

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.convertors import Convertor, register_url_convertor
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, PlainTextResponse, RedirectResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from ..errors import InputError, PorecadError, ResourceError
from . import design as ds
from . import preview as pv
from .print_panel import Prints
from ..io.mesh_formats import mesh_formats
from .session import SUFFIXES, Session
from .tasks import Exports, Previews, message

STATIC = Path(__file__).resolve().parent / "static"
VENDOR = STATIC.parent.parent / "vendor"  # three.js, shared with the report's 3D view
#: largest JSON request body (a design, a recipe text)
MAX_JSON = 1 << 20
CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
       "connect-src 'self'; frame-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")


def _error(exc: BaseException, status: int = 400) -> JSONResponse:
    if isinstance(exc, ResourceError):
        status = 413 if "upload" in str(exc) else status
    return JSONResponse(message(exc), status_code=status)


class _Number(Convertor):
    """A job or preview number in a URL: at most 9 digits (a longer one is no page, not a server error)."""

    regex = "[0-9]{1,9}"

    def convert(self, value: str) -> int:
        return int(value)

    def to_string(self, value) -> str:
        return str(int(value))


register_url_convertor("num", _Number())


class TokenGate:
    """ASGI middleware: ``/s/TOKEN/rest`` with a local ``Host`` goes on (as ``/rest``); the rest gets 403."""

    def __init__(self, app, token: str, port_ref):
        self.app = app
        self.token = token.encode()
        self.port_ref = port_ref

    async def __call__(self, scope, receive, send):
        if scope["type"] == "lifespan":
            return await self.app(scope, receive, send)
        if scope["type"] == "websocket":  # the studio has none: refused at the handshake (HTTP 403), no server error
            return await send({"type": "websocket.close", "code": 1008})
        if scope["type"] != "http":
            return
        path = scope.get("path", "")
        parts = path.split("/", 3)
        ok = len(parts) >= 3 and parts[1] == "s" and hmac.compare_digest(parts[2].encode(), self.token)
        host = dict(scope.get("headers") or []).get(b"host", b"").decode("latin-1").lower()
        port = self.port_ref()
        if ok and host not in (f"127.0.0.1:{port}", f"localhost:{port}"):
            ok = False
        origin = dict(scope.get("headers") or []).get(b"origin")
        if ok and origin is not None and origin.decode("latin-1").lower() not in (
                f"http://127.0.0.1:{port}", f"http://localhost:{port}"):
            ok = False  # a request sent by a page from another site
        if not ok:
            resp = PlainTextResponse("porecad studio: this address needs the session's token; open the link that "
                                     "`porecad studio` printed\n", status_code=403)
            return await resp(scope, receive, send)
        prefix = f"/s/{parts[2]}"
        if len(parts) == 3:
            return await RedirectResponse(prefix + "/", status_code=307)(scope, receive, send)
        scope = dict(scope, root_path=scope.get("root_path", "") + prefix)

        async def send_with_headers(msg):
            if msg["type"] == "http.response.start":
                headers = list(msg.get("headers") or [])
                headers += [(b"content-security-policy", CSP.encode()), (b"x-content-type-options", b"nosniff"),
                            (b"referrer-policy", b"no-referrer"), (b"cache-control", b"no-store")]
                msg = dict(msg, headers=headers)
            await send(msg)
        return await self.app(scope, receive, send_with_headers)


async def _json(request: Request):
    size = request.headers.get("content-length")
    if size is not None and (not size.isdigit() or int(size) > MAX_JSON):
        raise InputError(f"a request body is at most {MAX_JSON:,} bytes")
    body = b""
    async for chunk in request.stream():
        body += chunk
        if len(body) > MAX_JSON:
            raise InputError(f"a request body is at most {MAX_JSON:,} bytes")
    try:
        return json.loads(body.decode("utf-8"))
    except (ValueError, RecursionError):  # JSONDecodeError, bad UTF-8, a number past Python's digit limit
        raise InputError("the request is not valid JSON (or holds a number too long to read)") from None


class Studio:
    """A studio: the session, its workers and the ASGI app.

    Parameters
    ----------
    session : Session, optional
    design : dict, optional
        The form's first values (from a recipe or a body given on the command line).
    threads : int, optional
        Worker threads of the jobs.
    """

    def __init__(self, session: Session | None = None, design: dict | None = None, threads=None):
        self.session = session or Session()
        self.design = design or {"job": "tpms"}
        self.previews = Previews(self.session, threads)
        self.exports = Exports(self.session, threads)
        self.prints = Prints(self.session)
        self.port = 0
        self.notices: list[str] = []
        r = Route
        routes = [
            r("/", self.index), r("/api/schema", self.schema), r("/api/preview", self.preview, methods=["POST"]),
            r("/api/preview/{gen:num}", self.preview_state), r("/api/preview/{gen:num}/{name:str}", self.preview_blob),
            r("/api/upload", self.upload, methods=["PUT", "POST"]), r("/api/recipe", self.open_recipe, methods=["POST"]),
            r("/api/export", self.export, methods=["POST"]), r("/api/export/{n:num}", self.export_state),
            r("/api/export/{n:num}/cancel", self.export_cancel, methods=["POST"]),
            r("/api/export/{n:num}/file/{name:str}", self.export_file),
            r("/api/export/{n:num}/report/{name:str}", self.export_report),
            r("/api/export/{n:num}/bundle", self.export_bundle),
            r("/api/print/profile", self.print_profile, methods=["GET", "POST"]),
            r("/api/print/slice", self.print_slice, methods=["POST"]), r("/api/print/status", self.print_status),
            r("/api/print/cancel", self.print_cancel, methods=["POST"]),
            r("/api/print/layer/{k:num}.png", self.print_layer), r("/api/print/zip", self.print_zip),
            r("/api/print/report", self.print_report),
            Mount("/static/vendor", app=StaticFiles(directory=VENDOR), name="vendor"),
            Mount("/static", app=StaticFiles(directory=STATIC), name="static"),
        ]
        inner = Starlette(routes=routes, exception_handlers={Exception: self._on_error, 404: self._not_found,
                                                              405: self._not_found})
        self.app = TokenGate(inner, self.session.token, lambda: self.port)

    # ------------------------------------------------------------------ helpers
    async def _on_error(self, request, exc):
        return _error(exc, 500)

    async def _not_found(self, request, exc):
        return JSONResponse({"error": "no such page or method"}, status_code=getattr(exc, "status_code", 404))

    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/s/{self.session.token}/"

    def _recipe(self, design):
        return ds.recipe_of(design, self.session.resolve, self.session.body_bounds)

    def _checked(self, recipe):
        from ..jobs import parse
        parse(recipe)  # every job check, errors naming recipe keys
        ds.check_range(recipe)
        return recipe

    # ------------------------------------------------------------------ routes
    async def index(self, request):
        return FileResponse(STATIC / "index.html", media_type="text/html")

    async def schema(self, request):
        from ..fields.tpms import list_types
        types = [t["name"] for t in list_types()]
        return JSONResponse({"jobs": [{"name": j, "title": ds.JOB_TITLES[j]} for j in ds.JOBS],
                             "fields": ds.fields(types), "built_in": ds.BUILT_IN, "upload_kinds": ds.UPLOAD_KINDS,
                             "suffixes": SUFFIXES, "export_formats": mesh_formats("write"), "max_upload": self.session.max_upload,
                             "uploads": list(self.session.uploads.values()), "design": self.design,
                             "notices": self.notices})

    async def _design_request(self, request, shape: str):
        """``(body, recipe)`` of a request whose JSON body carries a form ``design``: its recipe, checked."""
        body = await _json(request)
        if not isinstance(body, dict) or not isinstance(body.get("design"), dict):
            raise InputError(f"send {shape}")
        recipe = await run_in_threadpool(lambda: self._checked(self._recipe(body["design"])))
        return body, recipe

    async def preview(self, request):
        try:
            body, recipe = await self._design_request(request, "{\"design\": {...}}")
            gen = self.previews.submit(body["design"], recipe)
            from ..io.recipe import dump_recipe
            curve = points = None
            tp = recipe.get("tpms") or {}
            if tp.get("structure") in ("pore", "rod", "sheet"):
                curve = pv.curve(tp["type"], tp["structure"])
                points = pv.operating_points(recipe, None)
            return JSONResponse({"gen": gen, "recipe": dump_recipe(recipe), "curve": curve, "points": points})
        except Exception as exc:  # noqa: BLE001 - a message in the page
            return _error(exc)

    async def preview_state(self, request):
        s = self.previews.state(request.path_params["gen"])
        if s is None:
            return JSONResponse({"error": "no such preview"}, status_code=404)
        return JSONResponse(s)

    async def preview_blob(self, request):
        b = self.previews.blob(request.path_params["gen"], request.path_params["name"])
        if b is None:
            return JSONResponse({"error": "not ready"}, status_code=404)
        return Response(b, media_type="application/octet-stream")

    async def upload(self, request):
        try:
            size = request.headers.get("content-length")
            declared = int(size) if size and size.isdigit() else None
            receiver = self.session.receive(request.query_params.get("name", ""), declared)
            try:
                async for chunk in request.stream():
                    receiver.write(chunk)
                info = await run_in_threadpool(receiver.finish)
            finally:
                receiver.abort()
            return JSONResponse({"upload": info, "uploads": list(self.session.uploads.values())})
        except Exception as exc:  # noqa: BLE001
            resp = _error(exc)
            if resp.status_code == 413:
                resp.headers["connection"] = "close"
            return resp

    async def open_recipe(self, request):
        try:
            body = await _json(request)
            text = body.get("text") if isinstance(body, dict) else None
            if not isinstance(text, str):
                raise InputError("send {\"text\": \"...toml...\"}")
            import tomllib
            try:
                recipe = tomllib.loads(text)
            except (tomllib.TOMLDecodeError, RecursionError) as exc:
                raise InputError(f"not a valid TOML recipe: {' '.join(str(exc).split())}") from None
            design = ds.design_of(recipe, self.session.upload_name)
            missing = [p for p in _input_paths(recipe) if self.session.upload_name(p) is None]
            note = (f"upload {', '.join(Path(str(p)).name for p in missing)} to build this recipe" if missing
                    else None)
            return JSONResponse({"design": design, "notice": note})
        except Exception as exc:  # noqa: BLE001
            return _error(exc)

    async def export(self, request):
        try:
            body, recipe = await self._design_request(request, "{\"design\": {...}, \"format\": \"stl\"}")
            n = self.exports.start(recipe, str(body.get("format", "stl")), bool(body.get("report", True)))
            return JSONResponse({"id": n})
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 409 if "export is running" in str(exc) else 400)

    async def export_state(self, request):
        s = self.exports.state(request.path_params["n"])
        return JSONResponse(s) if s else JSONResponse({"error": "no such export"}, status_code=404)

    async def export_cancel(self, request):
        return JSONResponse({"cancelling": self.exports.cancel(request.path_params["n"])})

    def _export_path(self, n, *parts):
        folder = self.exports.folder(n)
        if folder is None:
            raise InputError("no such finished export")
        name = parts[-1]
        check_plain(name)
        p = self.session.inside(folder.joinpath(*parts))
        if not p.is_file():
            raise InputError(f"{name}: no such file in this export")
        return p

    async def export_file(self, request):
        try:
            p = self._export_path(request.path_params["n"], request.path_params["name"])
            return FileResponse(p, filename=p.name, content_disposition_type="attachment")
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 404)

    async def export_report(self, request):
        try:
            p = self._export_path(request.path_params["n"], "report", request.path_params["name"])
            return FileResponse(p)
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 404)

    async def export_bundle(self, request):
        try:
            n = request.path_params["n"]
            folder = self.exports.folder(n)
            if folder is None:
                raise InputError("no such finished export")
            z = await run_in_threadpool(_zip_folder, folder, self.session.exports / f"{n}.zip")
            stem = self.exports.state(n).get("stem", "scaffold")
            return FileResponse(z, filename=f"{stem}-export.zip", content_disposition_type="attachment")
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 404)

    # ------------------------------------------------------------------ print panel (print_panel.py)
    async def print_profile(self, request):
        try:
            if request.method == "GET":
                return JSONResponse(self.prints.profile())
            body = await _json(request)
            return JSONResponse(self.prints.set_profile(body.get("text") if isinstance(body, dict) else None))
        except Exception as exc:  # noqa: BLE001
            return _error(exc)

    async def print_slice(self, request):
        try:
            body, recipe = await self._design_request(request, "{\"design\": {...}, \"orient\": \"auto\"}")
            n = self.prints.start(recipe, body.get("orient"), body.get("pixel"), body.get("layer"))
            return JSONResponse({"id": n})
        except Exception as exc:  # noqa: BLE001
            return _error(exc)

    async def print_status(self, request):
        return JSONResponse(self.prints.state())

    async def print_cancel(self, request):
        return JSONResponse({"cancelling": self.prints.cancel()})

    async def print_layer(self, request):
        try:
            png = await run_in_threadpool(self.prints.layer, request.path_params["k"])
            return Response(png, media_type="image/png")
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 404)

    async def print_zip(self, request):
        try:
            j = self.prints.done()
            return FileResponse(j["path"], filename=f"{j['stem']}-slices.zip",
                                content_disposition_type="attachment")
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 404)

    async def print_report(self, request):
        try:
            return JSONResponse(self.prints.done()["report"])
        except Exception as exc:  # noqa: BLE001
            return _error(exc, 404)

    # ------------------------------------------------------------------ serving
    def close(self):
        self.previews.close()
        self.prints.cancel()
        self.session.close()


def check_plain(name: str) -> str:
    if not name or "/" in name or "\\" in name or name.startswith(".") or ".." in name:
        raise InputError("not a file of this export")
    return name


def _input_paths(recipe: dict) -> list:
    out = []
    for table in ("domain", "body", "input"):
        t = recipe.get(table)
        if isinstance(t, dict) and isinstance(t.get("path"), str):
            out.append(t["path"])
    return out


def _zip_folder(folder: Path, target: Path) -> Path:
    import zipfile

    from ..io import atomic_write
    if target.is_file():
        return target
    with atomic_write(target) as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file() and not p.name.startswith("."):
                z.write(p, p.relative_to(folder).as_posix())
    return target


def bind(port: int = 0) -> socket.socket:
    """A listening TCP socket on 127.0.0.1 (``port`` 0: any free port)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(("127.0.0.1", int(port)))
    except OSError as exc:
        sock.close()
        raise InputError(f"cannot listen on 127.0.0.1:{port}: {exc.strerror}") from None
    sock.listen(64)
    return sock


class Server:
    """uvicorn serving a :class:`Studio` on a socket bound to 127.0.0.1; ``start()`` runs it in a thread."""

    def __init__(self, studio: Studio, port: int = 0):
        import uvicorn
        self.studio = studio
        self.sock = bind(port)
        studio.port = self.sock.getsockname()[1]
        config = uvicorn.Config(studio.app, log_level="warning", access_log=False, lifespan="off",
                                timeout_graceful_shutdown=2)
        self.server = uvicorn.Server(config)
        self.thread = None

    @property
    def url(self) -> str:
        return self.studio.url()

    def run(self):
        """Serve until interrupted (blocking)."""
        self.server.run(sockets=[self.sock])

    def start(self):
        """Serve in a background thread; returns once it accepts connections."""
        self.thread = threading.Thread(target=self.run, name="porecad-studio-server", daemon=True)
        self.thread.start()
        import time
        for _ in range(200):
            if self.server.started:
                return self
            time.sleep(0.05)
        raise PorecadError("the studio server did not start")

    def stop(self):
        self.server.should_exit = True
        if self.thread is not None:
            self.thread.join(timeout=10)
        self.sock.close()
        self.studio.close()
