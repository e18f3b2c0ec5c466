"""MetaImage and NRRD images: one header parser, and a reader that reads exactly what it checked.

A MetaImage (``.mha``, ``.mhd``) or NRRD (``.nrrd``, ``.nhdr``) header may
name a detached data file. A check that reads the header one way while
SimpleITK reads it another (other line ends, another separator, a length
cut-off, a symlink beside the header) lets a shared image read any file, so
porecad reads these two formats itself: :func:`read_header` parses the header
and checks its data file, :func:`read_voxels` reads the voxels from that very
file (opened by its resolved path, checked again once open) as the parsed
header says, and SimpleITK never sees either format.

The grammar is ITK's (MetaIO, and teem's NrrdIO, which ITK uses):

* a line ends at CR, LF or CRLF; a header longer than :data:`MAX_HEADER`
  bytes is refused, never cut;
* MetaImage: ``Key = value`` or ``Key: value`` (MetaIO ends a key at either),
  keys compared without case, a repeated key refused; ``ElementDataFile``
  ends the header: ``LOCAL`` (the voxels follow that line) or one file name;
* NRRD: a ``NRRD000N`` line, ``# comments``, ``field: value`` and
  ``key:=value`` lines; the header ends at an empty line (the voxels follow)
  or at the end of the file; ``data file`` (or ``datafile``) names one file.

``LIST`` and ``%d`` patterns of data files are refused. A data file must be a
plain name of a regular file in the header's own folder, also once symlinks
are followed (:func:`os.path.realpath`); anything else is a one-line
:class:`~porecad.errors.InputError`. Geometry follows ITK: MetaImage
``TransformMatrix`` rows are the index axes; NRRD ``space directions`` are
the axes times the spacing, converted to LPS from RAS or LAS spaces.
"""

from __future__ import annotations

import bz2
import os
import re
import stat
import zlib
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .confine import detached_file

__all__ = ["ImageHeader", "read_header", "read_voxels", "header_kind", "data_file_name", "MAX_HEADER"]

#: longest header read (bytes); a longer one is refused
MAX_HEADER = 1 << 20
#: most bytes of text per voxel accepted in an ASCII or hex encoded data file
MAX_TEXT_PER_VOXEL = 64
_LINE_END = re.compile(rb"\r\n|\r|\n")
_META_TYPES = {"MET_CHAR": "i1", "MET_UCHAR": "u1", "MET_SHORT": "i2", "MET_USHORT": "u2", "MET_INT": "i4",
               "MET_UINT": "u4", "MET_LONG": "i4", "MET_ULONG": "u4", "MET_LONG_LONG": "i8",
               "MET_ULONG_LONG": "u8", "MET_FLOAT": "f4", "MET_DOUBLE": "f8"}
_NRRD_TYPES = {**dict.fromkeys(("signed char", "int8", "int8_t"), "i1"),
               **dict.fromkeys(("uchar", "unsigned char", "uint8", "uint8_t"), "u1"),
               **dict.fromkeys(("short", "short int", "signed short", "signed short int", "int16", "int16_t"), "i2"),
               **dict.fromkeys(("ushort", "unsigned short", "unsigned short int", "uint16", "uint16_t"), "u2"),
               **dict.fromkeys(("int", "signed int", "int32", "int32_t"), "i4"),
               **dict.fromkeys(("uint", "unsigned int", "uint32", "uint32_t"), "u4"),
               **dict.fromkeys(("longlong", "long long", "long long int", "signed long long",
                                "signed long long int", "int64", "int64_t"), "i8"),
               **dict.fromkeys(("ulonglong", "unsigned long long", "unsigned long long int", "uint64",
                                "uint64_t"), "u8"),
               "float": "f4", "double": "f8"}
_NRRD_ENCODINGS = {"raw": "raw", "txt": "ascii", "text": "ascii", "ascii": "ascii", "hex": "hex", "gz": "zlib",
                   "gzip": "zlib", "bz2": "bz2", "bzip2": "bz2"}
#: NRRD field names, lower case without spaces (teem accepts "data file" and "datafile" alike)
_NRRD_FIELDS = {"content", "number", "type", "blocksize", "dimension", "space", "spacedimension", "sizes",
                "spacings", "thicknesses", "axismins", "axismaxs", "spacedirections", "centers", "centerings",
                "kinds", "labels", "units", "min", "max", "oldmin", "oldmax", "endian", "encoding", "lineskip",
                "byteskip", "sampleunits", "spaceunits", "spaceorigin", "measurementframe", "datafile"}
#: NRRD spaces ITK reads, and the signs that take their axes to LPS
_NRRD_SPACES = {"right-anterior-superior": (-1, -1, 1), "ras": (-1, -1, 1),
                "left-anterior-superior": (1, -1, 1), "las": (1, -1, 1),
                "left-posterior-superior": (1, 1, 1), "lps": (1, 1, 1), "scanner-xyz": (1, 1, 1),
                "3d-right-handed": (1, 1, 1), "3d-left-handed": (1, 1, 1)}
#: NRRD axis kinds of a spatial (domain) axis; any other kind is a vector or colour axis
_DOMAIN_KINDS = {"domain", "space", "time", "???", "none"}


@dataclass
class ImageHeader:
    """A parsed, checked MetaImage or NRRD header.

    Attributes
    ----------
    path : str
        The header file (for messages).
    size : list of int
        Voxels per axis, x fastest.
    dtype : numpy.dtype
        One voxel as stored (byte order included).
    encoding : str
        ``raw``, ``zlib`` (a zlib or gzip stream), ``bz2``, ``ascii`` or ``hex``.
    data : str
        The resolved file holding the voxels (the header itself when they follow it).
    ident : tuple
        ``(st_dev, st_ino)`` of ``data`` when checked: the file opened must be that one.
    offset : int
        Bytes of ``data`` before the (encoded) voxels; -1: the raw voxels end the file.
    skip : int
        Decoded bytes to skip before the voxels (NRRD ``byte skip`` of compressed data).
    spacing, origin : list of float
    direction : list of float
        Row-major direction matrix (columns are the index axes), as ITK returns it.
    """

    path: str
    size: list
    dtype: np.dtype
    encoding: str
    data: str = ""
    ident: tuple = ()
    offset: int = 0
    skip: int = 0
    spacing: list = field(default_factory=list)
    origin: list = field(default_factory=list)
    direction: list = field(default_factory=list)

    @property
    def nbytes(self) -> int:
        """Bytes of the decoded voxels."""
        return int(np.prod(self.size, dtype=np.float64)) * self.dtype.itemsize


def header_kind(path) -> str | None:
    """``"meta"``, ``"nrrd"`` or None (not one of the two), by the file's name."""
    low = str(path).lower()
    if low.endswith((".mha", ".mhd")):
        return "meta"
    if low.endswith((".nrrd", ".nhdr")):
        return "nrrd"
    return None


def _bad(path, why: str = "") -> InputError:
    kind = "MetaImage" if header_kind(path) == "meta" else "NRRD"
    return InputError(f"{path}: not a readable image (inconsistent {kind} header{': ' + why if why else ''})")


def _too_long(path) -> InputError:
    return InputError(f"{path}: the image header is longer than {MAX_HEADER:,} bytes (porecad reads no longer "
                      "header)")


def _lines(path):
    """The header file's lines as ``(text, end offset)``, up to the end of the file or a refusal.

    A line ends at CR, LF or CRLF. Only lines that end within
    :data:`MAX_HEADER` bytes are given; asking for more when the file goes on
    is refused (the header is too long), never cut.
    """
    with open(path, "rb") as fh:
        buf = fh.read(MAX_HEADER + 1)
    start = 0
    for m in _LINE_END.finditer(buf):
        if m.end() > MAX_HEADER:
            break
        yield buf[start:m.start()].decode("latin-1"), m.end()
        start = m.end()
    if len(buf) > MAX_HEADER:
        raise _too_long(path)
    if start < len(buf):
        yield buf[start:].decode("latin-1"), len(buf)


def _meta_fields(path):
    """MetaImage fields (lower-case keys) up to ``ElementDataFile``, and the offset just after that line."""
    fields = {}
    for text, end in _lines(path):
        line = text.strip()
        if not line:
            continue
        m = re.match(r"([^=:]*)[=:](.*)", line)
        if m is None:
            raise _bad(path, "a line without '=' or ':'")
        key = m[1].strip().lower()
        if key in fields:
            raise _bad(path, f"{m[1].strip()[:40]!r} given twice")
        fields[key] = m[2].strip()
        if key == "elementdatafile":
            return fields, end
    raise _bad(path, "no ElementDataFile")


def _nrrd_fields(path):
    """NRRD fields (lower-case keys without spaces), and the offset of attached voxels (None: none follow)."""
    lines = _lines(path)
    if not re.fullmatch(r"NRRD000[1-9]", next(lines, ("", 0))[0].strip()):
        raise InputError(f"{path}: not a readable image (no NRRD magic line)")
    fields = {}
    for text, end in lines:
        if not text:
            return fields, end
        if text.startswith("#") or ":=" in text:
            continue  # a comment, a key/value pair (teem tests ":=" first)
        key, sep, value = text.partition(": ")
        name = key.strip().lower().replace(" ", "")
        if not sep or name not in _NRRD_FIELDS:
            raise _bad(path, f"unknown line {text[:30]!r}")
        if name in fields:
            raise _bad(path, f"{key.strip()[:40]!r} given twice")
        fields[name] = value.strip()
        if name == "datafile" and fields[name].upper().startswith("LIST"):
            return fields, None  # the file names follow, one a line (refused as a list)
    return fields, None


def data_file_name(path, name=None) -> str | None:
    """The data file a MetaImage or NRRD header at ``path`` names (``name``: the file's own name, for its
    suffix), None when the voxels are in the file itself; parsed as :func:`read_header` parses it."""
    kind = header_kind(name or path)
    if kind == "meta":
        data = _meta_fields(path)[0]["elementdatafile"]
        return None if data.upper() == "LOCAL" else data
    if kind == "nrrd":
        return _nrrd_fields(path)[0].get("datafile")
    return None


def _data_file(path, name: str, need: int | None) -> str:
    """The resolved data file ``name`` of header ``path``: a regular file in the header's own folder."""
    n = name.strip()
    if n.upper().startswith("LIST") or "%" in n or len(n.split()) > 1:
        raise InputError(f"{path}: the header names a list or pattern of data files; porecad reads one image "
                         "file, or a header with one data file beside it")
    p = detached_file(path, n, need)
    real = os.path.realpath(p)
    if os.path.dirname(real) != os.path.realpath(os.path.dirname(os.path.abspath(path))):
        raise InputError(f"{path}: its data file {n} is a link to a file outside its own folder; a detached "
                         "data file must lie beside the header")
    return real


def _ident(real: str) -> tuple:
    st = os.stat(real)
    return st.st_dev, st.st_ino


def _numbers(path, text: str, count: int, what: str, integer: bool = False) -> list:
    try:
        vals = [float(t) for t in text.split()]
    except ValueError:
        raise _bad(path, f"{what} is not a list of numbers") from None
    if len(vals) != count or not all(np.isfinite(vals)):
        raise _bad(path, f"{what} needs {count} finite numbers")
    if integer and not all(v.is_integer() and 1 <= v <= 2**31 for v in vals):
        raise _bad(path, f"{what} needs {count} positive whole numbers")
    return [int(v) for v in vals] if integer else vals


def _first(fields: dict, *keys):
    return next((fields[k] for k in keys if k in fields), None)


def _true(value) -> bool:
    """A MetaIO boolean: true when it starts with T, t or 1."""
    return bool(value) and value[0] in "Tt1"


def _meta_header(path) -> ImageHeader:
    """The checked header of a MetaImage file."""
    f, end = _meta_fields(path)
    try:
        ndims = int(f.get("ndims", ""))
        channels = int(f.get("elementnumberofchannels", "1"))
        header_size = int(f.get("headersize", "0"))
    except ValueError:
        raise _bad(path) from None
    if not 1 <= ndims <= 4 or header_size < -1:
        raise _bad(path)
    if channels != 1:
        raise InputError(f"{path}: an image must have one value per voxel, this one has {channels}")
    size = _numbers(path, f.get("dimsize", ""), ndims, "DimSize", integer=True)
    kind = _META_TYPES.get(f.get("elementtype", "").upper())
    if kind is None:
        raise _bad(path, f"element type {f.get('elementtype', '')[:20]!r}")
    dtype = np.dtype(kind).newbyteorder(">" if _true(_first(f, "binarydatabyteordermsb", "elementbyteordermsb"))
                                        else "<")
    encoding = "zlib" if _true(f.get("compresseddata")) else "raw" if _true(f.get("binarydata", "T")) else "ascii"
    if header_size == -1 and encoding != "raw":
        raise _bad(path, "HeaderSize -1 with compressed or text data")
    h = ImageHeader(str(path), size, dtype, encoding)
    name = f["elementdatafile"]
    if name.upper() == "LOCAL":
        if header_size:
            raise _bad(path, "HeaderSize with LOCAL data")
        h.data, h.offset = os.path.realpath(path), end
    else:
        need = h.nbytes + max(header_size, 0) if encoding == "raw" else None
        h.data, h.offset = _data_file(path, name, need), header_size
    h.ident = _ident(h.data)
    spacing = _first(f, "elementspacing", "elementsize")
    h.spacing = _numbers(path, spacing, ndims, "ElementSpacing") if spacing else [1.0] * ndims
    origin = _first(f, "offset", "origin", "position")
    h.origin = _numbers(path, origin, ndims, "Offset") if origin else [0.0] * ndims
    matrix = _first(f, "transformmatrix", "rotation", "orientation")
    m = np.reshape(_numbers(path, matrix, ndims * ndims, "TransformMatrix"), (ndims, ndims)) if matrix \
        else np.eye(ndims)
    h.direction = m.T.ravel().tolist()  # ITK: row i of the matrix is index axis i
    return h


def _vectors(path, text: str, count: int, dim: int, what: str) -> np.ndarray:
    """``count`` NRRD vectors ``(a,b,c)`` of ``dim`` numbers each, as rows."""
    vecs = re.findall(r"\(([^()]*)\)", text)
    if len(vecs) != count or re.sub(r"\([^()]*\)", "", text).strip():
        raise _bad(path, f"{what} needs {count} vectors (x,y,z)")
    return np.array([_numbers(path, v.replace(",", " "), dim, what) for v in vecs])


def _nrrd_geometry(path, f: dict, dim: int):
    """``(spacing, origin, direction)`` of an NRRD header as ITK reads it (LPS)."""
    if "space" in f and "spacedimension" in f:
        raise _bad(path, "both space and space dimension")
    if "space" in f or "spacedimension" in f:
        signs = _NRRD_SPACES.get(f.get("space", "").lower()) if "space" in f else (1,) * dim
        sdim = len(signs or ()) if "space" in f else \
            _numbers(path, f["spacedimension"], 1, "space dimension", True)[0]
        if signs is None or sdim != dim:
            raise InputError(f"{path}: NRRD space {f.get('space', sdim)!r} is not one porecad reads for a "
                             f"{dim}-D image (right-anterior-superior, left-anterior-superior, "
                             "left-posterior-superior, scanner-xyz)")
        axes = _vectors(path, f.get("spacedirections", ""), dim, dim, "space directions") * np.asarray(signs)
        spacing = np.linalg.norm(axes, axis=1)
        direction = (axes / np.where(spacing > 0, spacing, 1.0)[:, None]).T
        origin = _vectors(path, f["spaceorigin"], 1, dim, "space origin")[0] * np.asarray(signs) \
            if "spaceorigin" in f else np.zeros(dim)
        return spacing.tolist(), origin.tolist(), direction.ravel().tolist()
    spacing = [1.0] * dim
    if "spacings" in f:
        toks = f["spacings"].split()
        if len(toks) != dim:
            raise _bad(path, f"spacings needs {dim} values")
        try:
            spacing = [1.0 if t.lower() == "nan" else float(t) for t in toks]
        except ValueError:
            raise _bad(path, "spacings is not a list of numbers") from None
    return spacing, [0.0] * dim, np.eye(dim).ravel().tolist()


def _nrrd_header(path) -> ImageHeader:
    """The checked header of an NRRD file."""
    f, end = _nrrd_fields(path)
    dim = _numbers(path, f.get("dimension", ""), 1, "dimension", integer=True)[0]
    if dim > 16:
        raise _bad(path, "dimension")
    size = _numbers(path, f.get("sizes", ""), dim, "sizes", integer=True)
    kinds = f.get("kinds", "").lower().split() or ["domain"] * dim
    if len(kinds) != dim:
        raise _bad(path, f"kinds needs {dim} values")
    if any(k not in _DOMAIN_KINDS for k in kinds):
        raise InputError(f"{path}: an image must have one value per voxel, this one has a "
                         f"{next(k for k in kinds if k not in _DOMAIN_KINDS)[:20]!r} axis")
    kind = _NRRD_TYPES.get(" ".join(f.get("type", "").lower().split()))
    encoding = _NRRD_ENCODINGS.get(f.get("encoding", "").lower())
    if kind is None or encoding is None:
        raise _bad(path, "type" if kind is None else "encoding")
    endian = f.get("endian", "").lower()
    if endian not in ("little", "big") and np.dtype(kind).itemsize > 1 and encoding != "ascii":
        raise _bad(path, "no endian")
    dtype = np.dtype(kind).newbyteorder(">" if endian == "big" else "<")
    try:
        byte_skip, line_skip = int(f.get("byteskip", "0")), int(f.get("lineskip", "0"))
    except ValueError:
        raise _bad(path, "byte skip") from None
    if line_skip or byte_skip < -1 or (encoding != "raw" and not 0 <= byte_skip <= MAX_HEADER):
        raise _bad(path, "line skip" if line_skip else "byte skip")
    h = ImageHeader(str(path), size, dtype, encoding)
    raw = encoding == "raw"
    h.offset = byte_skip if raw else 0
    h.skip = 0 if raw else byte_skip
    if "datafile" in f:
        h.data = _data_file(path, f["datafile"], h.nbytes + max(byte_skip, 0) if raw else None)
    elif end is None:
        raise _bad(path, "no data")
    else:
        h.data = os.path.realpath(path)
        h.offset = -1 if byte_skip == -1 else end + h.offset
    h.ident = _ident(h.data)
    h.spacing, h.origin, h.direction = _nrrd_geometry(path, f, dim)
    return h


def read_header(path) -> ImageHeader:
    """The parsed and checked header of a MetaImage or NRRD file (its data file, if any, checked too)."""
    kind = header_kind(path)
    if kind is None:
        raise InputError(f"{path}: not a MetaImage or NRRD file")
    try:
        return _meta_header(path) if kind == "meta" else _nrrd_header(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__})") from None


def _open_checked(h: ImageHeader):
    """The data file, opened without following a link, and the same file :func:`read_header` checked."""
    try:
        fd = os.open(h.data, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise InputError(f"{h.path}: its data cannot be read ({exc.strerror or type(exc).__name__})") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or (st.st_dev, st.st_ino) != h.ident:
        os.close(fd)
        raise InputError(f"{h.path}: its data file changed while it was read")
    return os.fdopen(fd, "rb"), st.st_size


def _inflate(fh, dec, total: int) -> bytes:
    """At most ``total`` bytes from a zlib or bz2 stream (never more: a bomb stops there)."""
    parts, have = [], 0
    while have < total and not dec.eof:
        if isinstance(dec, bz2.BZ2Decompressor):
            data = fh.read(1 << 20) if dec.needs_input else b""
            if dec.needs_input and not data:
                break
        else:
            data = dec.unconsumed_tail or fh.read(1 << 20)
            if not data:
                break
        block = dec.decompress(data, total - have)
        parts.append(block)
        have += len(block)
    return b"".join(parts)


def _truncated(h: ImageHeader, have: int, need: int) -> InputError:
    return InputError(f"{h.path}: truncated image: the header announces {need:,} bytes, the file holds {have:,}")


def read_voxels(h: ImageHeader) -> np.ndarray:
    """The voxels of a checked header as an array indexed ``[k, j, i]`` (x fastest in the file)."""
    need, count = h.nbytes, int(np.prod(h.size, dtype=np.float64))
    fh, size = _open_checked(h)
    with fh:
        offset = size - need if h.offset == -1 else h.offset
        if offset < 0:
            raise _truncated(h, size, need)
        fh.seek(offset)
        try:
            if h.encoding in ("ascii", "hex"):
                if size - offset > MAX_TEXT_PER_VOXEL * count + (1 << 20):
                    raise InputError(f"{h.path}: its text-encoded data is longer than {count:,} voxels can be")
                text = fh.read()
                if h.encoding == "ascii":
                    values = text.replace(b",", b" ").split()[:count]
                    if len(values) < count:
                        raise _truncated(h, len(values) * h.dtype.itemsize, need)
                    return np.array(values, dtype=h.dtype.newbyteorder("=")).reshape(h.size[::-1])
                buf = bytes.fromhex(re.sub(rb"\s+", b"", text).decode("ascii"))
            elif h.encoding == "raw":
                buf = fh.read(need)
            else:
                dec = zlib.decompressobj(47) if h.encoding == "zlib" else bz2.BZ2Decompressor()
                buf = _inflate(fh, dec, need + h.skip)[h.skip:]
        except InputError:
            raise
        except (ValueError, OverflowError, zlib.error, OSError, EOFError):
            raise InputError(f"{h.path}: not a readable image (corrupt or truncated data)") from None
    if len(buf) < need:
        raise _truncated(h, len(buf), need)
    arr = np.frombuffer(buf, dtype=h.dtype, count=count).reshape(h.size[::-1])
    return arr.astype(h.dtype.newbyteorder("="), copy=False)
