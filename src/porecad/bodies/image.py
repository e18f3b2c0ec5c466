"""Image bodies: a closed surface from a label value or an intensity threshold.

Reads NIfTI (``.nii``, ``.nii.gz``) and DICOM series (a directory, or one
``.dcm`` file of the series) with SimpleITK (the ``images`` extra), each with
its own ImageIO only, and MetaImage (``.mha``, ``.mhd``) and NRRD (``.nrrd``,
``.nhdr``) with porecad's own reader (:mod:`porecad.io.image_header`: the
file a header's data check accepts is the file read); any other file is
refused. It keeps the image's geometry: a voxel with index ``(i, j, k)`` lies at

.. math:: \\mathbf p = \\mathbf o + D \\, \\mathrm{diag}(\\mathbf s) \\, (i, j, k)^T

with origin ``o``, direction matrix ``D`` and spacing ``s`` — ITK's physical
space (millimetres, LPS axes for DICOM and NIfTI alike).

The body is the level set of an indicator sampled at the voxel centres:

* ``threshold=t`` (e.g. bone in CT): inside where the intensity is at least
  ``t``; the surface is interpolated between voxels (sub-voxel, so partial
  volume at the boundary is used). Only the largest connected component is
  kept unless ``keep_all=True`` (thresholded CT has specks).
* ``label=v`` (a segmentation): inside where the voxel equals ``v``; the
  staircase of the 0/1 mask is taken at the half level and lightly Taubin
  smoothed (volume-preserving, 004 eqs. 4–5).

The surface is extracted by porecad's marching cubes (closed, manifold,
outward by construction) on the image cropped to the body, then mapped to
physical coordinates (faces are flipped when ``det D < 0``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError

#: file name endings read as images
IMAGE_SUFFIXES = (".nii", ".nii.gz", ".mha", ".mhd", ".nrrd", ".nhdr", ".dcm")


def is_image_path(path) -> bool:
    """True for image files (by name) and for directories (DICOM series)."""
    p = Path(os.fspath(path))
    name = p.name.lower()
    return p.is_dir() or any(name.endswith(s) for s in IMAGE_SUFFIXES)


def sitk_module():
    """SimpleITK, or a one-line error naming the extra that installs it."""
    try:
        import SimpleITK as sitk
    except ImportError:  # pragma: no cover - the images extra is part of the test extras
        raise InputError("reading images needs SimpleITK: pip install 'porecad[images]'") from None
    return sitk


def read_image(path):
    """Read an image or DICOM series.

    Returns
    -------
    array : (nx, ny, nz) ndarray
        Voxel values indexed ``[i, j, k]`` (x fastest in the file).
    geometry : dict
        ``spacing`` (3,), ``origin`` (3,), ``direction`` (3, 3) (columns are
        the index axes in physical space), all float lists.
    """
    p = Path(os.fspath(path))
    if not p.exists():
        raise InputError(f"{p}: no such file or directory")
    if not p.is_dir():  # a folder is a DICOM series
        from ..io.confine import regular_file
        regular_file(p, "an image")
        if not is_image_path(p):
            raise InputError(f"{p}: not an image file porecad reads (use {', '.join(IMAGE_SUFFIXES)} or a "
                             "DICOM folder)")
    from ..io.image_header import header_kind
    if header_kind(p) is not None:
        return _read_header_image(p)
    sitk = sitk_module()
    from ..io.bounded import quiet_third_party
    try:
        with quiet_third_party():
            return _read_image(sitk, p)
    except RuntimeError:
        # ITK's message may quote the file's header: say what failed, not what was read
        raise InputError(f"{p}: not a readable image (unknown format, corrupt or truncated)") from None


def _read_header_image(p: Path):
    """A MetaImage or NRRD image: porecad's own reader (:mod:`porecad.io.image_header`), which reads the
    voxels from exactly the data file it checked."""
    from ..io.image_guard import check_image_info
    from ..io.image_header import read_header, read_voxels
    h = read_header(p)
    check_image_info(p, h.size, h.dtype.itemsize, h.spacing, h.origin, h.direction)
    if len(h.size) != 3:
        raise InputError(f"{p}: a body image must be 3-D, this one is {len(h.size)}-D")
    array = np.ascontiguousarray(np.transpose(read_voxels(h), (2, 1, 0)))
    geometry = {"spacing": [float(v) for v in h.spacing], "origin": [float(v) for v in h.origin],
                "direction": np.asarray(h.direction, dtype=float).reshape(3, 3).tolist()}
    return array, geometry


def _read_image(sitk, p: Path):
    """A NIfTI image or DICOM series at ``p`` and its geometry (header checked first, see :func:`_check_header`);
    each read with its own ImageIO only, never one SimpleITK picks by the file's content."""
    if p.is_dir() or p.name.lower().endswith(".dcm"):
        folder = p if p.is_dir() else p.parent
        reader = sitk.ImageSeriesReader()
        reader.SetImageIO("GDCMImageIO")
        ids = reader.GetGDCMSeriesIDs(str(folder))
        if not ids:
            raise InputError(f"{folder}: no DICOM series found")
        if len(ids) > 1 and p.is_dir():
            raise InputError(f"{folder}: {len(ids)} DICOM series; give one file of the series you want")
        sid = ids[0]
        if not p.is_dir():
            info = sitk.ImageFileReader()
            info.SetImageIO("GDCMImageIO")
            info.SetFileName(str(p))
            info.ReadImageInformation()
            if info.HasMetaDataKey("0020|000e"):
                sid = info.GetMetaData("0020|000e").strip()
                if sid not in ids:  # a damaged tag (ITK cannot even take it back as a name)
                    raise InputError(f"{p}: its DICOM series ID is not one of the series in {folder}")
        files = reader.GetGDCMSeriesFileNames(str(folder), sid)
        _check_header(sitk, files[0] if files else str(p), "GDCMImageIO", slices=len(files))
        reader.SetFileNames(files)
        img = reader.Execute()
    else:
        _check_header(sitk, str(p), "NiftiImageIO")
        reader = sitk.ImageFileReader()
        reader.SetImageIO("NiftiImageIO")
        reader.SetFileName(str(p))
        img = reader.Execute()
    if img.GetDimension() != 3:
        raise InputError(f"{p}: a body image must be 3-D, this one is {img.GetDimension()}-D")
    if img.GetNumberOfComponentsPerPixel() != 1:
        raise InputError(f"{p}: a body image must have one value per voxel")
    arr = sitk.GetArrayViewFromImage(img)  # [k, j, i]
    array = np.ascontiguousarray(np.transpose(arr, (2, 1, 0)))
    geometry = {"spacing": list(img.GetSpacing()), "origin": list(img.GetOrigin()),
                "direction": np.asarray(img.GetDirection(), dtype=float).reshape(3, 3).tolist()}
    return array, geometry


#: bytes per component of SimpleITK's scalar pixel types (by the type's name; 8 when unknown)
_PIXEL_BYTES = {"8-bit": 1, "16-bit": 2, "32-bit": 4, "64-bit": 8}


def _check_header(sitk, path: str, io: str, slices: int = 1) -> None:
    """Header checks before the voxels are read (:mod:`porecad.io.image_guard`): memory, geometry, truncation."""
    from ..io.image_guard import check_image_info, check_nifti_complete
    info = sitk.ImageFileReader()
    info.SetImageIO(io)
    info.SetFileName(path)
    info.ReadImageInformation()
    kind = sitk.GetPixelIDValueAsString(info.GetPixelID())
    per = next((b for k, b in _PIXEL_BYTES.items() if kind.startswith(k)), 8) * max(info.GetNumberOfComponents(), 1)
    size = list(info.GetSize())
    if slices > 1:
        size = size[:2] + [slices] if len(size) == 2 else size[:2] + [size[2] * slices]
    direction = info.GetDirection() if slices == 1 else (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    if len(size) != int(np.sqrt(len(direction)) + 0.5):
        direction = np.eye(len(size)).ravel()
    check_image_info(path, size, per, info.GetSpacing() if len(info.GetSpacing()) == len(size) else
                     [1.0] * len(size), info.GetOrigin() if len(info.GetOrigin()) == len(size) else
                     [0.0] * len(size), direction)
    check_nifti_complete(path)


def index_to_physical(ijk, geometry) -> np.ndarray:
    """``o + D diag(s) ijk`` for an (N, 3) array of (fractional) indices."""
    m = np.asarray(geometry["direction"], dtype=float) * np.asarray(geometry["spacing"], dtype=float)
    return np.asarray(ijk, dtype=float) @ m.T + np.asarray(geometry["origin"], dtype=float)


def physical_to_index(points, geometry) -> np.ndarray:
    """Inverse of :func:`index_to_physical`."""
    m = np.asarray(geometry["direction"], dtype=float) * np.asarray(geometry["spacing"], dtype=float)
    return np.linalg.solve(m, (np.asarray(points, dtype=float) - np.asarray(geometry["origin"])).T).T


def _indicator(array, label, threshold, keep_all):
    """Indicator (negative inside) and the inside mask."""
    from scipy import ndimage

    if (label is None) == (threshold is None):
        raise InputError("an image body needs exactly one of a label value or an intensity threshold")
    if label is not None:
        mask = array == label
        values = None
    else:
        mask = array >= threshold
        values = array
    if not mask.any():
        what = f"label {label:g}" if label is not None else f"intensity >= {threshold:g}"
        lo, hi = float(array.min()), float(array.max())
        raise InputError(f"no voxel has {what} (values range {lo:g} to {hi:g})")
    removed = 0
    if threshold is not None and not keep_all:
        lab, n = ndimage.label(mask)
        if n > 1:
            sizes = np.bincount(lab.ravel())
            sizes[0] = 0
            keep = lab == int(np.argmax(sizes))
            removed = int(n - 1)
            mask = keep
    if values is None:
        f = np.where(mask, np.float32(-0.5), np.float32(0.5))
    else:
        f = (np.float32(threshold) - values).astype(np.float32)
        if removed:
            # other components: pushed outside, the kept one keeps its sub-voxel values
            other = (values >= threshold) & ~mask
            f[other] = np.float32(max(abs(float(threshold)), 1.0) * 1e-3)
    return f, mask, removed


def image_body(path, label=None, threshold=None, keep_all: bool = False, smooth_iterations: int = 10,
               progress=None):
    """Closed surface mesh of an image body in physical coordinates.

    Parameters
    ----------
    path : str or os.PathLike
        Image file or DICOM directory.
    label : float, optional
        Voxel value of the body in a label map.
    threshold : float, optional
        Intensity threshold: the body is where the image is ``>= threshold``.
    keep_all : bool
        Keep every connected component of a thresholded body (default: the largest).
    smooth_iterations : int
        Taubin iterations on a label body's staircase surface (0: none).
    progress : callable, optional
        ``progress(done, total)`` per slab of the surface extraction.

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    info : dict
        The image geometry, its shape, the rule, inside voxel count and
        their volume, components removed.
    """
    from ..mesh.polygonise import Grid, polygonise

    array, geo = read_image(path)
    f, mask, removed = _indicator(array, label, threshold, keep_all)
    # crop to the body with two voxels of margin, pad with "outside"
    idx = np.nonzero(mask.any(axis=(1, 2)))[0], np.nonzero(mask.any(axis=(0, 2)))[0], \
        np.nonzero(mask.any(axis=(0, 1)))[0]
    lo = np.array([max(int(a[0]) - 2, 0) for a in idx])
    hi = np.array([min(int(a[-1]) + 3, n) for a, n in zip(idx, array.shape)])
    sub = f[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    outside = np.float32(max(float(np.max(sub)), 0.5))
    sub = np.pad(sub, 1, mode="constant", constant_values=outside)
    start = lo - 1
    grid = Grid((float(start[0]), float(start[1]), float(start[2])), (1.0, 1.0, 1.0), tuple(sub.shape))
    planes = np.ascontiguousarray(np.transpose(sub, (2, 1, 0)))  # [k, j, i] as the kernel wants

    def sample(xs, ys, zs):
        k0 = int(round(zs[0] - start[2]))
        return planes[k0:k0 + len(zs)]

    res = polygonise(sample, grid, caps=True, progress=progress)
    v_idx, faces = res.vertices, res.faces.astype(np.int64)
    if label is not None and smooth_iterations > 0:
        from ..mesh.smooth import taubin_smooth
        v_idx = taubin_smooth(v_idx, faces, iterations=int(smooth_iterations))
    vertices = index_to_physical(v_idx, geo)
    if np.linalg.det(np.asarray(geo["direction"])) < 0:
        faces = faces[:, ::-1].copy()
    voxel_volume = float(np.prod(geo["spacing"]))
    n_in = int(np.count_nonzero(mask))
    info = {"source": "image", "shape": list(array.shape), **geo,
            "rule": (f"label == {label:g}" if label is not None else f"intensity >= {threshold:g}"),
            "inside_voxels": n_in, "voxel_volume": voxel_volume, "voxel_count_volume": n_in * voxel_volume,
            "components_removed": removed}
    return vertices, faces, info
