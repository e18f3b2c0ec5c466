"""Reading and writing triangle meshes (STL, PLY, OBJ, 3MF; OFF read only).

Meshes are plain arrays: ``vertices`` of shape ``(V, 3)`` (float, millimetres)
and ``faces`` of shape ``(F, 3)`` (integer vertex indices, counter-clockwise
seen from outside). Writers are vectorised with numpy and write in blocks, so
that multi-million-triangle scaffolds are written quickly in bounded memory;
every write goes through :func:`porecad.io.atomic.atomic_write`.

Readers use trimesh for STL, OBJ, PLY and OFF and a small standard-library
parser for 3MF (:mod:`porecad.io.mesh_3mf`); duplicate vertices are merged
by exact position afterwards.
"""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np

from porecad.errors import InputError, one_line
from porecad.io._stl_kernel import LITTLE_ENDIAN, RECORD_BYTES, fill_stl_records, merge_exact_ids
from porecad.io.atomic import atomic_write
from porecad.io.bounded import Malformed, check_memory, failure_reason, quiet_third_party
from porecad.io.confine import regular_file
from porecad.io.mesh_formats import mesh_formats
from porecad.io.mesh_3mf import NS_3MF, REL_3MF, read_3mf
from porecad.io.streaming import StreamedWriter

__all__ = ["write_mesh", "read_mesh"]

_WRITE_FORMATS = mesh_formats("write")
_READ_FORMATS = mesh_formats("read")

#: triangles per block for the binary writers (50 MB of STL records)
_BLOCK = 1 << 20
#: rows per block for the text writers (OBJ, 3MF)
_TEXT_BLOCK = 1 << 17

#: triangles per block of the STL writer (13 MB of records, two blocks in flight)
_STL_BLOCK = 1 << 18

#: binary STL of at most this many triangles: numpy records, not the compiled kernel
NUMPY_STL_FACES = 2_000_000
_STL_DTYPE = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
PLY_FACE_DTYPE = np.dtype([("n", "u1"), ("i", "<i4", (3,))])


def format_of(path: Path, fmt: str | None, allowed: tuple[str, ...]) -> str:
    if fmt is not None:
        name = str(fmt).lower().lstrip(".")
        if name not in allowed:
            raise InputError(f"unknown mesh format {fmt!r} (supported: {', '.join(allowed)})")
        return name
    name = path.suffix.lower().lstrip(".")
    if name not in allowed:
        what = f"extension {path.suffix!r}" if path.suffix else "no extension"
        raise InputError(
            f"{path}: {what} is not a supported mesh format "
            f"(supported: {', '.join('.' + a for a in allowed)})"
        )
    return name


def _check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must have shape (F, 3), got {f.shape}")
    if not (np.issubdtype(v.dtype, np.floating) or np.issubdtype(v.dtype, np.integer)):
        raise InputError(f"vertices must be numeric, got dtype {v.dtype}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise InputError(f"faces must be integer indices, got dtype {f.dtype}")
    v = v.astype(np.float64, copy=False)
    f = f.astype(np.int32 if f.dtype == np.int32 else np.int64, copy=False)
    if not np.isfinite(v).all():
        raise InputError("vertices contain NaN or infinite coordinates")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise InputError(f"faces index outside 0..{len(v) - 1}")
    return v, f


# --------------------------------------------------------------------------
# writers
# --------------------------------------------------------------------------


def write_mesh(path, vertices, faces, force: bool = False, fmt: str | None = None,
               header: str | None = None) -> Path:
    """Write a triangle mesh to a file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Output file. The format is taken from the extension (``.stl``,
        ``.ply``, ``.obj``, ``.3mf``, case-insensitive) unless `fmt` is given.
    vertices : array_like, shape (V, 3)
        Vertex coordinates in millimetres; must be finite.
    faces : array_like of int, shape (F, 3)
        Triangles as indices into `vertices`.
    force : bool, optional
        Replace an existing file.
    fmt : {'stl', 'ply', 'obj', '3mf'}, optional
        Format, overriding the extension.
    header : str, optional
        STL only: ASCII text appended to porecad's 80-byte header, e.g.
        ``SPACE=RAS`` (3D Slicer's frame mark).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        Unknown format, or malformed `vertices` / `faces`.
    OutputError
        The file exists (without `force`) or cannot be written.

    Notes
    -----
    STL is binary with float32 coordinates and the unit normals of those
    float32 triangles (zero for degenerate ones); PLY is binary little-endian with float32
    coordinates and int32 indices; OBJ and 3MF store the shortest decimal
    that round-trips each float64 coordinate exactly (the jobs hand over
    coordinates already rounded to float32, :func:`porecad.mesh.validate.stored_coordinates`:
    the solid they checked). 3MF uses the core
    namespace with ``unit="millimeter"`` and a single object.
    """
    p = Path(os.fspath(path))
    kind = format_of(p, fmt, _WRITE_FORMATS)
    v, f = _check_mesh(vertices, faces)
    writer = {"stl": _write_stl, "ply": _write_ply, "obj": _write_obj, "3mf": _write_3mf}[kind]
    with atomic_write(p, force=force) as fh:
        writer(fh, v, f, header) if kind == "stl" else writer(fh, v, f)
    return p


def _write_stl(fh, v: np.ndarray, f: np.ndarray, note: str | None = None) -> None:
    if len(f) >= 2**32:
        raise InputError(f"binary STL holds at most 2**32-1 triangles, got {len(f)}")
    header = b"porecad binary STL, units: millimetre" + (b", " + str(note).encode("ascii") if note else b"")
    if len(header) > 80:
        raise InputError(f"an STL header holds 80 bytes, got {len(header)}")
    fh.write(header.ljust(80, b" "))
    fh.write(np.array([len(f)], dtype="<u4").tobytes())
    if not LITTLE_ENDIAN or len(f) <= NUMPY_STL_FACES:
        # numpy: big-endian hosts, and meshes small enough that compiling the kernel (about
        # 0.6 s on a first run, issue 22) would cost more than it saves (0.09 s against 0.03 s
        # for 640 k triangles); the same bytes either way
        rec = np.zeros(min(len(f), _STL_BLOCK), dtype=_STL_DTYPE)
        for start in range(0, len(f), _STL_BLOCK):     # blocks of 13 MB records (50 MB of temporaries)
            tri = np.take(v, f[start : start + _STL_BLOCK], axis=0)  # (n, 3, 3) float64
            block = rec[: len(tri)]
            block["v"] = tri
            block["normal"] = _unit_normals(block["v"].astype(np.float64))  # of the stored (float32) triangles
            fh.write(memoryview(block).cast("B"))
        return
    # double buffering: one block is written (the GIL is released) while the
    # next is filled, its parts on the other threads (the serial kernel is GIL-free)
    from concurrent.futures import ThreadPoolExecutor

    from porecad.kernel_threads import thread_count
    n_block = min(len(f), _STL_BLOCK)
    buffers = [np.empty(n_block * RECORD_BYTES, np.uint8) for _ in range(2 if len(f) > n_block else 1)]
    out = StreamedWriter(fh, len(f) * RECORD_BYTES)
    n_fill = thread_count() if len(f) > _STL_BLOCK // 2 else 1
    with ThreadPoolExecutor(max_workers=1) as pool, ThreadPoolExecutor(max_workers=n_fill) as fillers:
        pending = None
        for b, start in enumerate(range(0, len(f), _STL_BLOCK)):
            stop = min(len(f), start + _STL_BLOCK)
            buf = buffers[b % len(buffers)][: (stop - start) * RECORD_BYTES]
            cuts = np.linspace(start, stop, n_fill + 1).astype(np.int64)
            parts = [fillers.submit(fill_stl_records, v, f, int(a),
                                    buf[(a - start) * RECORD_BYTES:(e - start) * RECORD_BYTES])
                     for a, e in zip(cuts[:-1], cuts[1:]) if e > a]
            for part in parts:
                part.result()
            if pending is not None:
                pending.result()
            pending = pool.submit(out.write, memoryview(buf))
        if pending is not None:
            pending.result()


def _unit_normals(tri: np.ndarray) -> np.ndarray:
    """Unit normals of triangles ``(n, 3, 3)``; zero where degenerate."""
    with np.errstate(all="ignore"):  # overflow / 0-division fixed up below
        a = tri[:, 1] - tri[:, 0]
        b = tri[:, 2] - tri[:, 0]
        normal = np.empty_like(a)
        # explicit cross product: faster than np.cross on (n, 3) arrays
        np.subtract(a[:, 1] * b[:, 2], a[:, 2] * b[:, 1], out=normal[:, 0])
        np.subtract(a[:, 2] * b[:, 0], a[:, 0] * b[:, 2], out=normal[:, 1])
        np.subtract(a[:, 0] * b[:, 1], a[:, 1] * b[:, 0], out=normal[:, 2])
        length = np.sqrt(np.einsum("ij,ij->i", normal, normal))
        normal /= length[:, None]
    bad = ~(np.isfinite(length) & (length > 0))
    if bad.any():
        normal[bad] = 0.0
    return normal


def _write_ply(fh, v: np.ndarray, f: np.ndarray) -> None:
    if len(v) > np.iinfo(np.int32).max:
        raise InputError(f"PLY output supports at most 2**31-1 vertices, got {len(v)}")
    header = (
        "ply\n"
        "format binary_little_endian 1.0\n"
        "comment porecad mesh, units: millimetre\n"
        f"element vertex {len(v)}\n"
        "property float x\n"
        "property float y\n"
        "property float z\n"
        f"element face {len(f)}\n"
        "property list uchar int vertex_indices\n"
        "end_header\n"
    )
    fh.write(header.encode("ascii"))
    for start in range(0, len(v), _BLOCK):
        fh.write(np.ascontiguousarray(v[start : start + _BLOCK], dtype="<f4").tobytes())
    rec = np.zeros(min(len(f), _BLOCK), dtype=PLY_FACE_DTYPE)
    rec["n"] = 3
    for start in range(0, len(f), _BLOCK):
        block = rec[: len(f[start : start + _BLOCK])]
        block["i"] = f[start : start + _BLOCK]
        fh.write(memoryview(block).cast("B"))


def _float_strings(a: np.ndarray) -> list[str]:
    # repr of a Python float is the shortest string that round-trips exactly.
    # Adding 0.0 turns -0.0 into 0.0.
    return list(map(repr, (a + 0.0).ravel().tolist()))


def _write_obj(fh, v: np.ndarray, f: np.ndarray) -> None:
    fh.write(f"# porecad mesh, units: millimetre\n# {len(v)} vertices, {len(f)} faces\n".encode())
    for start in range(0, len(v), _TEXT_BLOCK):
        block = v[start : start + _TEXT_BLOCK]
        fh.write((("v %s %s %s\n" * len(block)) % tuple(_float_strings(block))).encode())
    for start in range(0, len(f), _TEXT_BLOCK):
        block = f[start : start + _TEXT_BLOCK] + 1
        fh.write((("f %d %d %d\n" * len(block)) % tuple(block.ravel().tolist())).encode())


def _write_3mf(fh, v: np.ndarray, f: np.ndarray) -> None:
    content_types = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
        '<Default Extension="rels" '
        'ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
        '<Default Extension="model" '
        'ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
        "</Types>\n"
    )
    rels = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
        f'<Relationship Target="/3D/3dmodel.model" Id="rel0" Type="{REL_3MF}"/>'
        "</Relationships>\n"
    )
    head = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<model unit="millimeter" xml:lang="en-US" xmlns="{NS_3MF}">\n'
        ' <metadata name="Application">porecad</metadata>\n'
        " <resources>\n"
        '  <object id="1" type="model">\n'
        "   <mesh>\n"
        "    <vertices>\n"
    )
    middle = "    </vertices>\n    <triangles>\n"
    tail = (
        "    </triangles>\n"
        "   </mesh>\n"
        "  </object>\n"
        " </resources>\n"
        ' <build>\n  <item objectid="1"/>\n </build>\n'
        "</model>\n"
    )
    with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as zf:
        zf.writestr("[Content_Types].xml", content_types)
        zf.writestr("_rels/.rels", rels)
        with zf.open("3D/3dmodel.model", "w", force_zip64=True) as model:
            model.write(head.encode())
            vfmt = '     <vertex x="%s" y="%s" z="%s"/>\n'
            for start in range(0, len(v), _TEXT_BLOCK):
                block = v[start : start + _TEXT_BLOCK]
                model.write(((vfmt * len(block)) % tuple(_float_strings(block))).encode())
            model.write(middle.encode())
            tfmt = '     <triangle v1="%d" v2="%d" v3="%d"/>\n'
            for start in range(0, len(f), _TEXT_BLOCK):
                block = f[start : start + _TEXT_BLOCK]
                model.write(((tfmt * len(block)) % tuple(block.ravel().tolist())).encode())
            model.write(tail.encode())


# --------------------------------------------------------------------------
# readers
# --------------------------------------------------------------------------


def read_mesh(path, fmt: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh and merge vertices that share an exact position.

    Parameters
    ----------
    path : str or os.PathLike
        Mesh file: ``.stl`` (ASCII or binary), ``.obj``, ``.ply``, ``.off`` or
        ``.3mf``, by extension unless `fmt` is given.
    fmt : str, optional
        Format, overriding the extension.

    Returns
    -------
    vertices : numpy.ndarray of float64, shape (V, 3)
        Unique vertex positions, in order of first occurrence in the file.
        3MF coordinates are converted to millimetres; other formats carry no
        unit and are returned as stored.
    faces : numpy.ndarray of int64, shape (F, 3)
        Triangles (polygons are triangulated by the reader), in file order.

    Raises
    ------
    InputError
        The file does not exist, has an unsupported extension, or is empty,
        truncated or otherwise not a readable mesh. Messages are one line.

    Notes
    -----
    Merging is by exact coordinate equality (``-0.0`` equals ``0.0``), never
    by a tolerance, so topology is not altered by the reader. STL stores each
    triangle's corners separately, so merging is what reconnects it. Faces
    are kept as read, including degenerate ones.
    """
    p = Path(os.fspath(path))
    kind = format_of(p, fmt, _READ_FORMATS)
    regular_file(p, "a mesh")
    try:
        if kind == "3mf":
            v, f = read_3mf(p)
        else:
            v, f = _read_trimesh(p, kind)
    except InputError:
        raise
    except MemoryError:
        raise
    except OSError as exc:
        raise InputError(f"{p}: cannot read: {one_line(exc.strerror or exc)}") from exc
    except Malformed as exc:  # our own parsers' reasons (they never quote the file)
        raise InputError(f"{p}: not a readable mesh: {_shorten(one_line(exc))}") from exc
    except Exception as exc:  # any other parser failure on a bad file: its message may quote the file
        reason = "undecodable text" if isinstance(exc, ImportError) else failure_reason(exc)
        raise InputError(f"{p}: not a readable mesh: {reason}") from exc
    return _merge_exact(*_tidy(p, v, f))


#: bytes of memory per byte of file that reading costs at most (text parsed to floats; binary STL ~3)
_READ_COST = {"stl": 4, "ply": 6, "obj": 12, "off": 12}


def _shorten(text: str, limit: int = 160) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _read_trimesh(p: Path, kind: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    check_memory(p.stat().st_size * _READ_COST[kind], f"{p}: reading this {kind.upper()} file")
    data = p.read_bytes()
    if not data.strip():
        raise Malformed("file is empty")
    if kind == "stl":
        _check_stl_size(data)
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0]) if len(data) >= 84 else -1
        if len(data) == 84 + 50 * count and count > 0:
            # binary STL: corners straight from the records (one row per corner, merged later)
            rec = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                                count=count, offset=84)
            v = rec["v"].reshape(-1, 3).astype(np.float64)
            return v, np.arange(3 * count, dtype=np.int64).reshape(-1, 3)
    if kind in ("obj", "off"):
        # trimesh falls back to an optional dependency for non-UTF-8 text;
        # decode Latin-1 here instead (it cannot fail).
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            data = data.decode("latin-1").encode("utf-8")
    with quiet_third_party():  # trimesh logs the tracebacks of the parsers it tries
        mesh = trimesh.load(io.BytesIO(data), file_type=kind, force="mesh", process=False)
    if not hasattr(mesh, "faces") or not hasattr(mesh, "vertices"):
        raise Malformed("no triangle mesh found")
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _check_stl_size(data: bytes) -> None:
    """Give a clear reason for a truncated binary STL (trimesh's is obscure)."""
    if len(data) >= 84:
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) == 84 + 50 * count:
            return  # a well-formed binary STL
    if data.lstrip()[:5].lower() == b"solid":
        return  # ASCII STL (or a binary one with a 'solid' header): let trimesh try
    if len(data) < 84:
        raise Malformed(f"{len(data)} bytes is too short for a binary STL")
    raise Malformed(
        f"binary STL is {len(data)} bytes but its header announces {count} triangles "
        f"({84 + 50 * count} bytes): truncated or corrupt"
    )


def _tidy(p: Path, v, f) -> tuple[np.ndarray, np.ndarray]:
    try:
        v = np.asarray(v, dtype=np.float64)
        f = np.asarray(f)
    except (ValueError, TypeError, OverflowError):
        raise InputError(f"{p}: not a readable mesh: malformed vertices or faces") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"{p}: not a readable mesh: vertices are not 3-D points")
    if f.size == 0:
        raise InputError(f"{p}: not a readable mesh: no triangles found")
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"{p}: not a readable mesh: faces are not triangles")
    f = f.astype(np.int64, copy=False)
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"{p}: not a readable mesh: face index out of range")
    if not np.isfinite(v).all():
        raise InputError(f"{p}: not a readable mesh: non-finite vertex coordinates")
    return v, f


def _merge_exact(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices with identical coordinates, keeping first-occurrence order (hash table, O(V))."""
    if len(v) == 0:
        return v.reshape(0, 3), f
    key = np.ascontiguousarray(v, dtype=np.float64) + 0.0  # -0.0 -> 0.0, so equal values compare equal
    ids, first = merge_exact_ids(key.view(np.uint64))
    return key[first], ids[f]
