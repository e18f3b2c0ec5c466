"""Meshes written slab by slab: binary STL and PLY without holding the mesh.

:class:`StreamedMeshWriter` takes the welded slabs of the chunked pipeline
(:func:`porecad.mesh.polygonise.welded_slabs`) in order and writes a file that
is byte for byte the one :func:`porecad.io.write_mesh` writes for the whole
mesh:

* **STL** - the 80-byte header and a zero triangle count, then the records
  of each slab as it arrives; the count is patched in at the end.
* **PLY** - the header holds both counts, so vertices and face records go to
  two hidden spill files next to the output; at the end the header is written
  and the spill files are appended.
* **STL without its islands** (``drop=True``) - the records and each one's
  piece id go to two spill files; :meth:`StreamedMeshWriter.close` is given
  the piece ids to keep (known only when the last slab has been joined) and
  copies the kept records into the file.

Everything lands in the temporary file of :func:`porecad.io.atomic.atomic_write`
and is renamed onto the target only when :meth:`close` is called after a
successful run; :meth:`abort` (or an exception inside the ``with`` block)
removes the temporary and spill files. Memory is bounded by two slabs.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path

import numpy as np

from porecad.errors import InputError, OutputError
from porecad.io._stl_kernel import RECORD_BYTES, fill_stl_records
from porecad.io.atomic import atomic_write, check_output_path, forget_temp, temp_file
from porecad.io.mesh_formats import mesh_formats, mesh_suffixes
from porecad.io.meshfiles import PLY_FACE_DTYPE, format_of
from porecad.io.streaming import StreamedWriter

__all__ = ["StreamedMeshWriter", "STREAM_FORMATS"]

STREAM_FORMATS = mesh_formats("stream")
_STL_HEADER = b"porecad binary STL, units: millimetre".ljust(80, b" ")
_BLOCK = 1 << 18


class StreamedMeshWriter:
    """Write a mesh slab by slab, atomically (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        Output ``.stl`` or ``.ply``.
    force : bool
        Replace an existing file.
    expected_bytes : int
        Expected size; large files are written with a bounded page cache
        (:class:`porecad.io.streaming.StreamedWriter`).
    drop : bool
        An STL whose pieces may be dropped: :meth:`add` takes each face's piece
        id and :meth:`close` the ids to keep (the module docstring).

    Use as a context manager; call :meth:`add` for each slab with the
    positions and faces of :meth:`porecad.mesh.stream_check.SlabWindow.local`,
    then :meth:`close` to publish the file. Leaving the block without
    :meth:`close` (an exception, a failed check) discards everything.
    """

    def __init__(self, path, force: bool = False, expected_bytes: int = 0, drop: bool = False):
        self.path = Path(os.fspath(path))
        self.kind = format_of(self.path, None, mesh_formats("write"))
        if self.kind not in STREAM_FORMATS:
            raise InputError(f"{self.path}: streamed output writes {mesh_suffixes('stream', ' or ')}, not .{self.kind}")
        check_output_path(self.path, force=force)
        self.force = force
        self.expected_bytes = int(expected_bytes)
        self.n_faces = 0
        self.n_vertices = 0
        self._ctx = None
        self._fh = None
        self._spills = []
        self._closed = False
        self.drop = bool(drop) and self.kind == "stl"
        self.kept = None  # after close with ``keep``: {"triangles", "bounds"} of the records written

    # -- lifecycle -----------------------------------------------------------------

    def __enter__(self):
        self._ctx = atomic_write(self.path, force=self.force)
        self._fh = self._ctx.__enter__()
        try:
            if self.kind == "stl":
                self._fh.write(_STL_HEADER + b"\0\0\0\0")
                self._out = StreamedWriter(self._fh, self.expected_bytes)
                if self.drop:
                    self._rec, self._ids = self._spill("rec"), self._spill("ids")
            else:
                self._vtx = self._spill("vtx")
                self._fac = self._spill("fac")
        except BaseException as exc:
            self._discard(exc)
            raise
        return self

    def _spill(self, what):
        try:
            fd, tmp = temp_file(self.path, what)
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot create spill file: {exc.strerror or exc}") from None
        fh = os.fdopen(fd, "wb")
        self._spills.append((tmp, fh))
        return fh

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None and self._closed:
            return False
        self._discard(exc if exc is not None else RuntimeError("streamed mesh not closed"))
        return False

    def _discard(self, exc):
        for tmp, fh in self._spills:
            with contextlib.suppress(OSError):
                fh.close()
            forget_temp(tmp, remove=True)
        self._spills = []
        if self._ctx is not None:
            ctx, self._ctx = self._ctx, None
            with contextlib.suppress(BaseException):
                ctx.__exit__(type(exc), exc, None)  # removes the temporary file

    def abort(self):
        """Discard the output (no file is written)."""
        self._discard(RuntimeError("aborted"))

    def close(self, keep=None):
        """Finish the file and rename it onto the target (``keep``: the piece ids kept, for ``drop``)."""
        if self.drop:
            self._copy_kept(np.ones(0, bool) if keep is None else np.asarray(keep, bool))
        if self.kind == "stl":
            if self.n_faces >= 2**32:
                raise InputError(f"binary STL holds at most 2**32-1 triangles, got {self.n_faces}")
            self._fh.flush()
            self._fh.seek(80)
            self._fh.write(np.array([self.n_faces], dtype="<u4").tobytes())
        else:
            if self.n_vertices > np.iinfo(np.int32).max:
                raise InputError(f"PLY output supports at most 2**31-1 vertices, got {self.n_vertices}")
            header = ("ply\nformat binary_little_endian 1.0\ncomment porecad mesh, units: millimetre\n"
                      f"element vertex {self.n_vertices}\nproperty float x\nproperty float y\n"
                      f"property float z\nelement face {self.n_faces}\n"
                      "property list uchar int vertex_indices\nend_header\n")
            self._fh.write(header.encode("ascii"))
            for tmp, fh in self._spills:
                fh.close()
                with open(tmp, "rb") as src:
                    shutil.copyfileobj(src, self._fh, 16 << 20)
                forget_temp(tmp, remove=True)
            self._spills = []
        ctx, self._ctx = self._ctx, None
        self._closed = True
        ctx.__exit__(None, None, None)  # flush and rename

    # -- data ----------------------------------------------------------------------

    def add(self, slab, positions, faces, ids=None):
        """Append a welded slab (``positions``/``faces`` local to the two-slab window; ``ids``: each face's
        piece, for ``drop``)."""
        try:
            if self.drop:
                self._ids.write(np.ascontiguousarray(ids, dtype="<i8").tobytes())
                self._add_stl(positions, faces, self._rec)
            elif self.kind == "stl":
                self._add_stl(positions, faces, self._out)
            else:
                self._vtx.write(np.ascontiguousarray(slab.vertices, dtype="<f4").tobytes())
                rec = np.empty(len(slab.faces), dtype=PLY_FACE_DTYPE)
                rec["n"] = 3
                rec["i"] = slab.faces
                self._fac.write(memoryview(rec).cast("B"))
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot write: {' '.join(str(exc.strerror or exc).split())}") from exc
        self.n_faces += len(slab.faces)
        self.n_vertices += len(slab.vertices)

    def _add_stl(self, positions, faces, to):
        buf = np.empty(min(len(faces), _BLOCK) * RECORD_BYTES, np.uint8)
        for start in range(0, len(faces), _BLOCK):
            stop = min(len(faces), start + _BLOCK)
            out = buf[: (stop - start) * RECORD_BYTES]
            fill_stl_records(positions, faces, start, out)
            to.write(memoryview(out))

    def _copy_kept(self, keep):
        """Copy the records of the kept pieces from the spill files into the output; count and bound them."""
        (rec_tmp, rec_fh), (ids_tmp, ids_fh) = self._spills[-2:]
        rec_fh.close()
        ids_fh.close()
        n, lo, hi = 0, np.full(3, np.inf), np.full(3, -np.inf)
        try:
            with open(rec_tmp, "rb") as recs, open(ids_tmp, "rb") as ids:
                while True:
                    block = np.frombuffer(ids.read(8 * _BLOCK), "<i8")
                    if not len(block):
                        break
                    raw = np.frombuffer(recs.read(RECORD_BYTES * len(block)), np.uint8).reshape(len(block), -1)
                    kept = raw[keep[block]] if len(keep) else raw[:0]
                    if len(kept):
                        xyz = np.ascontiguousarray(kept[:, 12:48]).view("<f4").reshape(-1, 3)
                        lo, hi = np.minimum(lo, xyz.min(axis=0)), np.maximum(hi, xyz.max(axis=0))
                        self._out.write(memoryview(np.ascontiguousarray(kept)).cast("B"))
                    n += len(kept)
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot write: {' '.join(str(exc.strerror or exc).split())}") from exc
        for tmp in (rec_tmp, ids_tmp):
            forget_temp(tmp, remove=True)
        self._spills = self._spills[:-2]
        self.n_faces = n
        self.kept = {"triangles": n, "bounds": [lo.tolist(), hi.tolist()] if n else None}
