"""VTK XML files (``.vtp``, ``.vtu``): safe parsing and bounded decoding of their DataArrays.

A VTK XML file is XML (parsed here by :mod:`porecad.io.safe_xml`: no DTD, no
entities, bounded depth) whose DataArrays are ``ascii`` text, inline
``binary`` (base64 of a byte-count header and the data) or ``appended``
(raw or base64 bytes in ``<AppendedData>``), optionally compressed by
``vtkZLibDataCompressor`` (``[nblocks, blocksize, lastsize, csize_1..n]``
then the zlib blocks) or ``vtkLZMADataCompressor``. Every size in a header
is checked against the bytes present and :data:`MAX_ARRAY_BYTES` before
anything is allocated or inflated, and each block is inflated with a hard
output bound, so a compression bomb is refused without being expanded.

:func:`read_vtk_xml` returns the root element, the appended bytes and their
encoding; :func:`data_array` decodes one DataArray; :func:`check_vtk_xml`
decodes every DataArray of a file and discards them (used before a
third-party reader, meshio, opens a ``.vtu``).
"""

from __future__ import annotations

import base64
import binascii
from pathlib import Path

import numpy as np

from ..errors import InputError
from .bounded import check_file_size, check_memory

__all__ = ["read_vtk_xml", "data_array", "check_vtk_xml", "VTK_TYPES", "MAX_ARRAY_BYTES", "MAX_FILE_BYTES"]

VTK_TYPES = {"Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4", "UInt32": "u4",
             "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8"}
#: largest decoded DataArray (bytes)
MAX_ARRAY_BYTES = 2 << 30
#: largest VTK XML file read (bytes)
MAX_FILE_BYTES = 4 << 30
#: most a compressed DataArray of over 64 MiB may inflate, in times its compressed size (real numbers: 2-50x;
#: only a block of one repeated byte nears zlib's limit of about 1000x)
MAX_INFLATE_RATIO = 200


class VtkFile:
    """A parsed VTK XML file: ``root`` element and the ``<AppendedData>`` bytes (if any)."""

    def __init__(self, root, appended, encoding, what):
        self.root = root
        self.appended = appended
        self.encoding = encoding
        self.what = what
        self.header_type = np.dtype("<u8" if root.get("header_type", "UInt32") == "UInt64" else "<u4")
        comp = root.get("compressor")
        if comp is not None and comp not in ("vtkZLibDataCompressor", "vtkLZMADataCompressor"):
            raise InputError(f"{what}: unsupported compressor (use vtkZLibDataCompressor or vtkLZMADataCompressor)")
        self.compressor = comp


def read_vtk_xml(path) -> VtkFile:
    """Parse a VTK XML file safely (bounded file size, no DTD, bounded depth); cut out raw appended data."""
    from .safe_xml import parse
    p = Path(path)
    what = str(p)
    size = check_file_size(p, MAX_FILE_BYTES, "a VTK XML file")
    check_memory(size * 3.0, f"{what}: reading this VTK XML file")
    data = p.read_bytes()
    appended, encoding = None, "raw"
    k = data.find(b"<AppendedData")
    if k >= 0:
        start = data.find(b">", k) + 1
        end = data.rfind(b"</AppendedData>")
        if start <= 0 or end < start:
            raise InputError(f"{what}: AppendedData is not closed")
        head = data[k:start]
        body = data[start:end]
        u = body.find(b"_")
        appended = body[u + 1:].rstrip() if u >= 0 else b""
        encoding = "base64" if b'encoding="base64"' in head else "raw"
        data = data[:k] + b"<AppendedData/>" + data[end + len(b"</AppendedData>"):]
    root = parse(data, what)
    if root.tag != "VTKFile":
        raise InputError(f"{what}: not a VTK XML file")
    if root.get("byte_order", "LittleEndian") != "LittleEndian":
        raise InputError(f"{what}: big-endian VTK files are not supported")
    return VtkFile(root, appended, encoding, what)


def _b64(raw: bytes, what: str) -> bytes:
    try:
        return base64.b64decode(raw)
    except (binascii.Error, ValueError):
        raise InputError(f"{what}: corrupt base64 data") from None


def _count(n: int, what: str) -> int:
    if not 0 <= n <= MAX_ARRAY_BYTES:
        raise InputError(f"{what}: a DataArray declares {n:,} bytes (at most {MAX_ARRAY_BYTES:,})")
    return n


def _inflate_blocks(vf: VtkFile, raw: bytes, b64: bool) -> bytes:
    """``[nblocks, blocksize, lastsize, csizes...]`` + blocks, each inflated to at most its declared size."""
    import lzma
    import zlib

    hdt, what = vf.header_type, vf.what
    hs = hdt.itemsize
    if b64:
        first = _b64(raw[: 4 * ((3 * hs + 2) // 3)], what)
        if len(first) < hs:
            raise InputError(f"{what}: truncated compressed DataArray header")
        nb = int(np.frombuffer(first[:hs], hdt)[0])
        if nb > MAX_ARRAY_BYTES // max(hs, 1) or nb > len(raw):
            raise InputError(f"{what}: a compressed DataArray declares {nb:,} blocks")
        hlen = (3 + nb) * hs
        henc = 4 * ((hlen + 2) // 3)
        header_bytes = _b64(raw[:henc], what)[:hlen]
        body = _b64(raw[henc:], what)
    else:
        if len(raw) < hs:
            raise InputError(f"{what}: truncated compressed DataArray header")
        nb = int(np.frombuffer(raw[:hs], hdt)[0])
        if nb > len(raw):
            raise InputError(f"{what}: a compressed DataArray declares {nb:,} blocks")
        hlen = (3 + nb) * hs
        header_bytes = raw[:hlen]
        body = raw[hlen:]
    if len(header_bytes) < hlen:
        raise InputError(f"{what}: truncated compressed DataArray header")
    header = np.frombuffer(header_bytes, hdt).astype(np.int64)
    blocksize, lastsize = int(header[1]), int(header[2])
    total = (nb - 1) * blocksize + (lastsize or blocksize) if nb else 0
    _count(total, what)
    if total > (64 << 20) and total > MAX_INFLATE_RATIO * max(len(body), 1):
        raise InputError(f"{what}: a compressed DataArray of {len(body):,} bytes declares {total:,} bytes (more than "
                         f"{MAX_INFLATE_RATIO} times its size: refused as a decompression bomb)")
    check_memory(total, f"{what}: decoding a DataArray")
    sizes = header[3:3 + nb]
    if np.any(sizes < 0) or int(sizes.sum()) > len(body):
        raise InputError(f"{what}: compressed block sizes exceed the data present")
    out = bytearray()
    pos = 0
    for b, s in enumerate(sizes.tolist()):
        limit = blocksize if b < nb - 1 or not lastsize else lastsize
        chunk = body[pos:pos + s]
        pos += s
        try:
            if vf.compressor == "vtkLZMADataCompressor":
                d = lzma.LZMADecompressor()
                piece = d.decompress(chunk, max_length=limit + 1)
            else:
                d = zlib.decompressobj()
                piece = d.decompress(chunk, limit + 1)
        except (zlib.error, lzma.LZMAError):
            raise InputError(f"{what}: corrupt compressed DataArray block") from None
        if len(piece) > limit:
            raise InputError(f"{what}: a compressed block inflates beyond its declared {limit:,} bytes")
        out += piece
    return bytes(out)


def data_array(vf: VtkFile, el) -> np.ndarray:
    """Decode one ``<DataArray>`` element (1-D, or ``(n, NumberOfComponents)``)."""
    what = vf.what
    t = el.get("type")
    if t not in VTK_TYPES:
        raise InputError(f"{what}: unsupported DataArray type")
    dt = np.dtype("<" + VTK_TYPES[t])
    hdt, hs = vf.header_type, vf.header_type.itemsize
    fmt = el.get("format", "ascii")
    if fmt == "ascii":
        text = (el.text or "").split()
        try:
            vals = np.array(text, dtype=dt)
        except (ValueError, OverflowError):
            raise InputError(f"{what}: an ascii DataArray holds something that is not a number") from None
    elif fmt == "binary":
        raw = "".join((el.text or "").split()).encode("ascii", errors="replace")
        if vf.compressor:
            buf = _inflate_blocks(vf, raw, b64=True)
        else:
            buf = _b64(raw, what)
            if len(buf) < hs:
                raise InputError(f"{what}: truncated binary DataArray")
            n = _count(int(np.frombuffer(buf[:hs], hdt)[0]), what)
            buf = buf[hs:hs + n]
        vals = _frombuffer(buf, dt, what)
    elif fmt == "appended":
        if vf.appended is None:
            raise InputError(f"{what}: appended DataArray but no AppendedData")
        try:
            off = int(el.get("offset", 0))
        except ValueError:
            raise InputError(f"{what}: a DataArray offset is not an integer") from None
        if not 0 <= off <= len(vf.appended):
            raise InputError(f"{what}: a DataArray offset lies outside the appended data")
        blob = vf.appended[off:]
        if vf.encoding == "base64":
            if vf.compressor:
                buf = _inflate_blocks(vf, blob, b64=True)
            else:
                first = _b64(blob[:4 * ((hs + 2) // 3)], what)
                if len(first) < hs:
                    raise InputError(f"{what}: truncated appended DataArray")
                n = _count(int(np.frombuffer(first[:hs], hdt)[0]), what)
                buf = _b64(blob[:4 * ((hs + n + 2) // 3)], what)[hs:hs + n]
        else:
            if vf.compressor:
                buf = _inflate_blocks(vf, blob, b64=False)
            else:
                if len(blob) < hs:
                    raise InputError(f"{what}: truncated appended DataArray")
                n = _count(int(np.frombuffer(blob[:hs], hdt)[0]), what)
                buf = blob[hs:hs + n]
        vals = _frombuffer(buf, dt, what)
    else:
        raise InputError(f"{what}: unknown DataArray format (use ascii, binary or appended)")
    try:
        nc = int(el.get("NumberOfComponents", 1))
    except ValueError:
        raise InputError(f"{what}: NumberOfComponents is not an integer") from None
    if not 1 <= nc <= 64:
        raise InputError(f"{what}: NumberOfComponents must be 1 to 64")
    if vals.size % nc:
        raise InputError(f"{what}: a DataArray's length is not a multiple of its NumberOfComponents")
    return vals.reshape(-1, nc) if nc > 1 else vals


def _frombuffer(buf: bytes, dt, what: str) -> np.ndarray:
    if len(buf) % dt.itemsize:
        raise InputError(f"{what}: a DataArray's byte count is not a multiple of its value size")
    return np.frombuffer(buf, dt)


def check_vtk_xml(path) -> None:
    """Decode (and discard) every DataArray of a VTK XML file: refuses bombs and corrupt headers up front."""
    vf = read_vtk_xml(path)
    for el in vf.root.iter("DataArray"):
        data_array(vf, el)
