"""Checks on an image file before its voxels are read: complete, sane geometry, fits in memory.

SimpleITK reads a truncated NIfTI file (``.nii`` or ``.nii.gz``) without
complaint and fills the missing voxels with garbage, and it allocates
whatever size a header announces. :func:`check_image_info` checks what
:meth:`SimpleITK.ImageFileReader.ReadImageInformation` returns — the
dimension, the memory the voxels need (refused up front with the estimate),
finite positive spacings and finite origins within :data:`MAX_COORDINATE`,
an invertible direction matrix — and :func:`check_nifti_complete` compares
the bytes a NIfTI-1/-2 header announces with the bytes present (streaming a
``.nii.gz`` through :mod:`gzip` in bounded memory). MetaImage and NRRD
headers, which may name a detached data file, are parsed and read by
:mod:`porecad.io.image_header` (one parser for the check and the read).

NIfTI header layout: NIfTI-1 (``sizeof_hdr = 348``): ``dim`` int16[8] at
byte 40, ``bitpix`` int16 at 72, ``vox_offset`` float32 at 108; NIfTI-2
(``sizeof_hdr = 540``): ``bitpix`` int16 at 14, ``dim`` int64[8] at 16,
``vox_offset`` int64 at 168 (nifti.nimh.nih.gov, nifti1.h and nifti2.h).
"""

from __future__ import annotations

import gzip
import struct
import zlib

import numpy as np

from ..errors import InputError, ResourceError
from .bounded import check_memory

__all__ = ["check_image_info", "check_nifti_complete", "MAX_COORDINATE", "MAX_SPACING", "MIN_SPACING",
           "MAX_IMAGE_VOXELS"]

#: largest |origin| or extent accepted (mm): 100 km
MAX_COORDINATE = 1e8
#: largest voxel spacing accepted (mm)
MAX_SPACING = 1e4
#: smallest voxel spacing accepted (mm)
MIN_SPACING = 1e-6
#: most voxels an image header may declare (2**28: a 512 x 512 x 1024 CT); counted before anything is read
MAX_IMAGE_VOXELS = 1 << 28


def check_image_info(path, size, bytes_per_voxel: int, spacing, origin, direction, copies: float = 4.0) -> None:
    """Refuse an image whose header is absurd, before its voxels are read.

    Parameters
    ----------
    path : path
        For messages.
    size : sequence of int
        Voxels per axis.
    bytes_per_voxel : int
        Bytes of one voxel (all components).
    spacing, origin : sequence of float
    direction : sequence of float
        Row-major direction matrix.
    copies : float
        How many copies of the voxel array the reader and the job hold.
    """
    size = [int(n) for n in size]
    if any(n < 1 for n in size):
        raise InputError(f"{path}: the image has an empty axis ({'x'.join(map(str, size))} voxels)")
    n = float(np.prod(np.asarray(size, dtype=np.float64)))
    if n > MAX_IMAGE_VOXELS:
        raise ResourceError(f"{path}: the header declares {'x'.join(map(str, size))} = {n:.4g} voxels; porecad "
                            f"reads at most {MAX_IMAGE_VOXELS:,} (crop or resample the image)")
    check_memory(n * max(int(bytes_per_voxel), 1) * copies,
                 f"{path}: this {'x'.join(map(str, size))}-voxel image")
    sp = np.asarray(spacing, dtype=np.float64)
    if not (np.all(np.isfinite(sp)) and np.all(sp >= MIN_SPACING) and np.all(sp <= MAX_SPACING)):
        raise InputError(f"{path}: voxel spacings must lie in [{MIN_SPACING:g}, {MAX_SPACING:g}] mm, got "
                         f"{', '.join(f'{x:.3g}' for x in sp)}")
    org = np.asarray(origin, dtype=np.float64)
    if not (np.all(np.isfinite(org)) and np.all(np.abs(org) <= MAX_COORDINATE)):
        raise InputError(f"{path}: the image origin must be finite and within {MAX_COORDINATE:g} mm, got "
                         f"{', '.join(f'{x:.3g}' for x in org)}")
    extent = sp * np.asarray(size, dtype=np.float64)
    if np.any(extent > MAX_COORDINATE):
        raise InputError(f"{path}: the image spans more than {MAX_COORDINATE:g} mm")
    d = np.asarray(direction, dtype=np.float64)
    dim = len(size)
    if d.size != dim * dim or not np.all(np.isfinite(d)):
        raise InputError(f"{path}: the image direction matrix is not a finite {dim}x{dim} matrix")
    m = d.reshape(dim, dim)
    with np.errstate(over="ignore", invalid="ignore"):
        orthonormal = np.allclose(m @ m.T, np.eye(dim), atol=1e-3)
    if not orthonormal:
        raise InputError(f"{path}: the image direction matrix is not orthonormal (its columns must be unit "
                         "axis directions)")


def _nifti_header(head: bytes):
    """``(expected data bytes from the file start, )`` from a NIfTI-1/-2 header, or None if not NIfTI."""
    if len(head) < 348:
        return None
    for order in ("<", ">"):
        (sizeof_hdr,) = struct.unpack(order + "i", head[:4])
        if sizeof_hdr == 348:
            dim = struct.unpack(order + "8h", head[40:56])
            (bitpix,) = struct.unpack(order + "h", head[72:74])
            pixdim = struct.unpack(order + "8f", head[76:108])
            (vox_offset,) = struct.unpack(order + "f", head[108:112])
            break
        if sizeof_hdr == 540 and len(head) >= 540:
            (bitpix,) = struct.unpack(order + "h", head[14:16])
            dim = struct.unpack(order + "8q", head[16:80])
            pixdim = struct.unpack(order + "8d", head[104:168])
            (vox_offset,) = struct.unpack(order + "q", head[168:176])
            break
    else:
        return None
    ndim = int(dim[0])
    if not 1 <= ndim <= 7:
        return -1
    count = 1
    for n in dim[1:ndim + 1]:
        if n < 1:
            return -1
        count *= int(n)
    if bitpix <= 0 or bitpix % 8 or not np.isfinite(vox_offset) or vox_offset < 0:
        return -1
    spacing = np.asarray(pixdim[1:min(ndim, 3) + 1], dtype=np.float64)
    if not (np.all(np.isfinite(spacing)) and np.all(spacing > 0)):
        return -2  # ITK would quietly read a spacing of 0, NaN or inf as 1
    return int(vox_offset) + count * (int(bitpix) // 8)


def check_nifti_complete(path) -> None:
    """Refuse a NIfTI file (``.nii``, ``.nii.gz``) that holds fewer voxel bytes than its header announces."""
    name = str(path).lower()
    if not (name.endswith(".nii") or name.endswith(".nii.gz")):
        return
    try:
        if name.endswith(".gz"):
            with gzip.open(path, "rb") as fh:
                head = fh.read(540)
                expected = _nifti_header(head)
                if expected is None or expected < 0:
                    return _bad_header(path, expected)
                have = len(head)
                while have < expected:
                    block = fh.read(min(1 << 22, expected - have))
                    if not block:
                        break
                    have += len(block)
        else:
            with open(path, "rb") as fh:
                head = fh.read(540)
                expected = _nifti_header(head)
                if expected is None or expected < 0:
                    return _bad_header(path, expected)
                fh.seek(0, 2)
                have = fh.tell()
    except (OSError, EOFError, zlib.error, gzip.BadGzipFile):
        raise InputError(f"{path}: not a readable image (corrupt or truncated compressed data)") from None
    if have < expected:
        raise InputError(f"{path}: truncated image: the header announces {expected:,} bytes, the file holds "
                         f"{have:,}")


def _bad_header(path, expected):
    if expected is None:
        return None  # not a NIfTI header: let the reader say so
    if expected == -2:
        raise InputError(f"{path}: the NIfTI header's voxel spacing (pixdim) must be finite and positive")
    raise InputError(f"{path}: not a readable image (inconsistent NIfTI header)")
