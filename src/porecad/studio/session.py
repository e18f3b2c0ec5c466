"""One studio session: its secret token, its work folder and the files uploaded into it.

Nothing the page sends is ever used as a path: an upload's name is checked
(a plain file name with a known suffix: no folder, no ``..``, no hidden file),
the bytes are streamed into ``inputs/`` of the session's own temporary work
folder with a size limit counted as they arrive, and a design refers to an
upload by that name only (:meth:`Session.resolve`). Exports go into
``exports/N/`` of the same folder. The folder is removed when the session
closes.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import tempfile
import threading
from pathlib import Path

from ..errors import InputError, ResourceError
from ..io.mesh_formats import mesh_suffixes

#: upload kind → file suffixes (lower case)
SUFFIXES = {
    "mesh": mesh_suffixes("read"),
    "image": (".nii", ".nii.gz", ".mha", ".nrrd", ".dcm"),
    "volume": (".vtu", ".vtk", ".msh", ".inp", ".mesh"),
    "centreline": (".json", ".swc", ".vtp"),
}
#: default upload size limit (bytes)
MAX_UPLOAD = 256 << 20
#: most uploads a session keeps
MAX_UPLOADS = 64
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._ ()+-]{0,127}$")


def upload_kind(name: str) -> str:
    """The kind of an upload from its name's suffix (an :class:`InputError` for an unknown one)."""
    low = name.lower()
    for kind, sfx in SUFFIXES.items():
        if any(low.endswith(s) for s in sfx):
            return kind
    every = ", ".join(s for sfx in SUFFIXES.values() for s in sfx)
    raise InputError(f"{name}: unknown file type; upload one of {every}")


def check_name(name) -> str:
    """A plain file name, or an :class:`InputError` (folders, ``..``, hidden and odd names are refused)."""
    if not isinstance(name, str) or not name:
        raise InputError("the upload has no file name")
    if "/" in name or "\\" in name or name in (".", "..") or ".." in name or "\x00" in name:
        raise InputError(f"upload names are plain file names, without folders or '..': {name[:80]!r}")
    if not _NAME.match(name):
        raise InputError(f"upload names use letters, digits, spaces and . _ - ( ) + (at most 128): {name[:80]!r}")
    upload_kind(name)
    return name


class Session:
    """A studio session.

    Parameters
    ----------
    max_upload : int
        Largest upload accepted (bytes).
    root : path, optional
        Where the work folder is made (default: the system's temporary folder).
    """

    def __init__(self, max_upload: int = MAX_UPLOAD, root=None):
        self.token = secrets.token_urlsafe(24)
        self.max_upload = int(max_upload)
        self.work = Path(tempfile.mkdtemp(prefix="porecad-studio-", dir=root)).resolve()
        self.inputs = self.work / "inputs"
        self.exports = self.work / "exports"
        self.inputs.mkdir()
        self.exports.mkdir()
        self.uploads: dict[str, dict] = {}
        self._bodies: dict = {}
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ uploads
    def inside(self, path) -> Path:
        """``path`` resolved, if it lies inside the work folder (an :class:`InputError` otherwise)."""
        p = Path(path).resolve()
        if p != self.work and self.work not in p.parents:
            raise InputError("that file is outside this session's work folder")
        return p

    def receive(self, name: str, declared: int | None = None) -> "Receiver":
        """Start receiving an upload called ``name`` (checked now; a declared size over the limit is refused)."""
        return Receiver(self, name, declared)

    def save_upload(self, name: str, chunks, declared: int | None = None) -> dict:
        """Stream ``chunks`` (an iterable of bytes) into ``inputs/name``; check and describe the file.

        A declared length over the limit is refused before anything is read;
        the count is checked again as the bytes arrive. A file that cannot be
        read as what its name says is removed and refused.
        """
        r = self.receive(name, declared)
        try:
            for chunk in chunks:
                r.write(chunk)
            return r.finish()
        finally:
            r.abort()

    def register(self, info: dict) -> None:
        with self._lock:
            self.uploads[info["name"]] = info
            self._bodies = {k: v for k, v in self._bodies.items() if k[0] != info["name"]}

    def adopt(self, path) -> dict:
        """Copy a file the user named on the command line into the work folder as an upload."""
        from ..io.confine import regular_file
        p = Path(path)
        size = regular_file(p, "an upload")

        def chunks():
            with open(p, "rb") as fh:
                while block := fh.read(1 << 20):
                    yield block
        return self.save_upload(p.name, chunks(), declared=size)

    def resolve(self, name, kinds=None) -> Path:
        """The path of the upload called ``name`` (of one of ``kinds``), inside the work folder."""
        from .design import FieldError
        if not isinstance(name, str) or name not in self.uploads:
            raise FieldError("body", f"{str(name)[:80]!r} is not an uploaded file: upload it first")
        info = self.uploads[name]
        if kinds is not None and info["kind"] not in kinds:
            raise FieldError("body", f"{name} is a {info['kind']} file; this job takes {' or '.join(kinds)}")
        return self.inside(self.inputs / name)

    def upload_name(self, path) -> str | None:
        """The upload standing for an input path of a recipe (matched by file name), or None."""
        if not path:
            return None
        name = Path(str(path)).name
        return name if name in self.uploads else None

    def body_bounds(self, design: dict):
        """``(lo, hi)`` of an infill design's body (loaded once per upload and image rule)."""
        from ..fields.sdf import LumbarDisc
        body = design.get("body") or "disc"
        if body == "disc":
            return LumbarDisc().bounds
        path = self.resolve(body, ("mesh", "image"))
        key = (body, design.get("body_label"), design.get("body_threshold"))
        with self._lock:
            hit = self._bodies.get(key)
        if hit is None:
            from ..bodies import load_body
            opts = {}
            if self.uploads[body]["kind"] == "image":
                for src, k in (("body_label", "label"), ("body_threshold", "threshold")):
                    if design.get(src) not in (None, ""):
                        opts[k] = float(design[src])
            _, _, report = load_body(path, check_intersections=False, **opts)
            hit = report["bounds"]
            with self._lock:
                self._bodies[key] = hit
        return hit

    def new_export_dir(self) -> Path:
        """A fresh ``exports/N`` folder."""
        with self._lock:
            n = 1 + max([int(p.name) for p in self.exports.iterdir() if p.name.isdigit()] or [0])
            d = self.exports / str(n)
            d.mkdir()
        return d

    def close(self) -> None:
        """Remove the work folder."""
        shutil.rmtree(self.work, ignore_errors=True)


class Receiver:
    """An upload being received: bytes go to a temporary file in ``inputs/``, counted against the limit.

    :meth:`finish` reads the file as its kind (a one-line error if it is not
    one) and moves it to ``inputs/NAME``; :meth:`abort` removes what was
    received (harmless after :meth:`finish`).
    """

    def __init__(self, session: Session, name: str, declared: int | None = None):
        self.session = session
        self.name = check_name(name)
        self.kind = upload_kind(self.name)
        limit = session.max_upload
        if declared is not None and declared > limit:
            raise ResourceError(f"{self.name}: {declared:,} bytes is over the upload limit of {limit:,} bytes")
        if len(session.uploads) >= MAX_UPLOADS and self.name not in session.uploads:
            raise ResourceError(f"at most {MAX_UPLOADS} uploads a session")
        self.target = session.inside(session.inputs / self.name)
        fd, tmp = tempfile.mkstemp(prefix=".upload-", dir=session.inputs)
        self.tmp = Path(tmp)
        self.fh = os.fdopen(fd, "wb")
        self.n = 0
        self.done = False

    def write(self, chunk: bytes) -> None:
        self.n += len(chunk)
        if self.n > self.session.max_upload:
            raise ResourceError(f"{self.name}: over the upload limit of {self.session.max_upload:,} bytes")
        self.fh.write(chunk)

    def finish(self) -> dict:
        self.fh.close()
        if self.n == 0:
            raise InputError(f"{self.name}: the file is empty")
        info = describe_upload(self.tmp, self.name, self.kind)
        os.replace(self.tmp, self.target)
        self.done = True
        info.update(name=self.name, kind=self.kind, bytes=self.n)
        self.session.register(info)
        return info

    def abort(self) -> None:
        if not self.fh.closed:
            self.fh.close()
        if not self.done:
            self.tmp.unlink(missing_ok=True)


def describe_upload(path: Path, name: str, kind: str) -> dict:
    """Read an uploaded file as its kind says; a one-line :class:`InputError` when it is not one.

    Bodies are loaded and checked as a job would (repairs listed, or a
    reason they cannot be used: not closed, not manifold, ...).
    """
    from ..errors import PorecadError
    try:
        if kind == "mesh":
            from ..bodies import load_body
            suffixed = path.with_name(path.name + Path(name).suffix)
            os.link(path, suffixed)
            try:
                _, _, report = load_body(suffixed, check_intersections=False)
            finally:
                suffixed.unlink(missing_ok=True)
            return {"triangles": report["triangles"], "repairs": report["repairs"], "volume": report["volume"],
                    "bounds": [list(map(float, b)) for b in report["bounds"]]}
        if kind == "centreline":
            from ..vessels.readers import read_centreline
            suffixed = path.with_name(path.name + Path(name).suffix)
            os.link(path, suffixed)
            try:
                graph = read_centreline(suffixed)
            finally:
                suffixed.unlink(missing_ok=True)
            return {"points": int(len(getattr(graph, "points", []))) if hasattr(graph, "points") else None}
        if kind == "volume":
            from ..volmesh import read_volume_mesh
            suffixed = path.with_name(path.name + Path(name).suffix)
            os.link(path, suffixed)
            try:
                read_volume_mesh(suffixed)
            finally:
                suffixed.unlink(missing_ok=True)
            return {}
        # images: read when the design gives the label or threshold (the preview says what is wrong);
        # an upload is one self-contained file: a header naming a detached data file is refused
        from ..io.image_header import data_file_name
        if data_file_name(path, name) is not None:
            raise InputError(f"{name}: the header names a separate data file; upload one self-contained image "
                             "(.nii, .nii.gz, .nrrd or .mha with its voxels inside)")
        return {}
    except PorecadError as exc:
        raise InputError(_without_tmp(str(exc), path, name)) from None
    except (ValueError, OSError, KeyError, IndexError, TypeError, RuntimeError) as exc:
        raise InputError(f"{name}: cannot be read as a {kind} file ({type(exc).__name__})") from None


def _without_tmp(text: str, path: Path, name: str) -> str:
    """An error message about the temporary upload file, naming the upload instead."""
    for p in (str(path.with_name(path.name + Path(name).suffix)), str(path)):
        text = text.replace(p, name)
    return " ".join(text.split())
