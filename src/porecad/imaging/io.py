"""Reading and writing volumes and multi-channel stacks with their geometry.

A volume is a 3-D array indexed ``[i, j, k]`` and a geometry dict
(``spacing``, ``origin``, ``direction``), exactly as
:func:`porecad.bodies.image.read_image` returns them (SimpleITK reads NIfTI,
MetaImage, NRRD and DICOM series). A *stack* is several co-registered
channels of one subject — the Dixon in-phase, opposed-phase, fat and water
images of 000 §6.2.1 — which must share size, spacing, origin and direction;
a disagreement is a one-line :class:`~porecad.errors.InputError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, OutputError

#: tolerance on spacing / origin (mm, relative to the spacing) and direction cosines
GEOMETRY_RTOL = 1e-4


def read_volume(path):
    """Read one 3-D scalar volume: ``(array, geometry)``.

    Wrong dimension (2-D, 4-D), vector pixels, missing or corrupted files are
    one-line :class:`InputError` s.
    """
    from ..bodies.image import read_image
    array, geo = read_image(path)
    if min(array.shape) < 2:
        raise InputError(f"{path}: a volume needs at least 2 voxels along each axis, this one is "
                         f"{'x'.join(str(s) for s in array.shape)}")
    return array, geo


def geometry_mismatch(a: dict, b: dict, shape_a, shape_b):
    """A short description of how two geometries differ, or None when they agree."""
    if tuple(shape_a) != tuple(shape_b):
        return f"size {'x'.join(map(str, shape_a))} vs {'x'.join(map(str, shape_b))}"
    sa, sb = np.asarray(a["spacing"], float), np.asarray(b["spacing"], float)
    if not np.allclose(sa, sb, rtol=GEOMETRY_RTOL, atol=0):
        return f"spacing {_fmt(sa)} vs {_fmt(sb)}"
    tol = GEOMETRY_RTOL * float(np.max(sa)) * 10
    oa, ob = np.asarray(a["origin"], float), np.asarray(b["origin"], float)
    if not np.allclose(oa, ob, rtol=0, atol=tol):
        return f"origin {_fmt(oa)} vs {_fmt(ob)}"
    if not np.allclose(np.asarray(a["direction"], float), np.asarray(b["direction"], float), atol=1e-4):
        return "direction matrices differ"
    return None


def _fmt(v):
    return "(" + ", ".join(f"{x:g}" for x in np.asarray(v).ravel()) + ")"


@dataclass
class Stack:
    """Co-registered channels of one subject.

    Attributes
    ----------
    channels : dict
        Channel name → float32 array ``[i, j, k]`` (all the same shape).
    geometry : dict
        The shared ``spacing``, ``origin``, ``direction``.
    labels : ndarray or None
        A label map on the same grid (ground truth), if one was given.
    sources : dict
        Channel name → file it was read from.
    """

    channels: dict
    geometry: dict
    labels: np.ndarray | None = None
    sources: dict = field(default_factory=dict)

    @property
    def shape(self):
        return next(iter(self.channels.values())).shape

    @property
    def names(self):
        return list(self.channels)

    def array(self, names=None) -> np.ndarray:
        """The channels as one ``(C, nx, ny, nz)`` float32 array (in ``names`` order)."""
        names = self.names if names is None else list(names)
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise InputError(f"channel(s) {', '.join(missing)} missing; this stack has {', '.join(self.names)}")
        return np.stack([self.channels[n] for n in names]).astype(np.float32, copy=False)


def read_stack(paths: dict, labels=None) -> Stack:
    """Read channels (name → path) and an optional label map; check they share one geometry.

    Raises
    ------
    InputError
        A channel cannot be read, is not 3-D, or its size, spacing, origin or
        direction differs from the first channel's (one line naming both).
    """
    if not paths:
        raise InputError("no image channels given")
    channels, sources = {}, {}
    geo0 = shape0 = None
    first = None
    for name, path in paths.items():
        arr, geo = read_volume(path)
        if geo0 is None:
            geo0, shape0, first = geo, arr.shape, name
        else:
            why = geometry_mismatch(geo0, geo, shape0, arr.shape)
            if why:
                raise InputError(f"channel {name!r} ({Path(path).name}) does not match channel {first!r}: {why}")
        channels[name] = np.asarray(arr, dtype=np.float32)
        sources[name] = str(path)
    lab = None
    if labels is not None:
        lab_arr, lgeo = read_volume(labels)
        why = geometry_mismatch(geo0, lgeo, shape0, lab_arr.shape)
        if why:
            raise InputError(f"label map {Path(labels).name} does not match channel {first!r}: {why}")
        if not np.all(np.isfinite(lab_arr)) or np.any(lab_arr != np.round(lab_arr)):
            raise InputError(f"label map {Path(labels).name} holds non-integer values")
        lab = lab_arr.astype(np.int32)
        sources["labels"] = str(labels)
    return Stack(channels, geo0, lab, sources)


def write_volume(path, array, geometry, force: bool = False, dtype=None) -> Path:
    """Write a 3-D array ``[i, j, k]`` with its geometry (NIfTI, MHA, NRRD by suffix), atomically."""
    from ..bodies.image import sitk_module
    from ..io import check_output_path
    sitk = sitk_module()
    p = check_output_path(path, force=force)
    arr = np.asarray(array if dtype is None else np.asarray(array).astype(dtype))
    if arr.ndim != 3:
        raise InputError(f"a volume must be 3-D, got shape {arr.shape}")
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8)
    img = sitk.GetImageFromArray(np.ascontiguousarray(np.transpose(arr, (2, 1, 0))))
    img.SetSpacing([float(s) for s in geometry["spacing"]])
    img.SetOrigin([float(o) for o in geometry["origin"]])
    img.SetDirection([float(d) for d in np.asarray(geometry["direction"], float).ravel()])
    suffix = ".nii.gz" if p.name.lower().endswith(".nii.gz") else p.suffix
    from ..io.atomic import atomic_path
    try:
        with atomic_path(p, force=force, suffix=suffix) as tmp:
            sitk.WriteImage(img, str(tmp), True)
    except RuntimeError as exc:
        raise OutputError(f"{p}: cannot write image ({str(exc).strip().splitlines()[-1]})") from None
    return p
