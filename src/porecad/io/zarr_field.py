"""Sampled fields in a zarr store: written by the chunk workers, read back for reuse.

The store is one float32 array of shape ``(nz, ny, nx)`` (z slowest, like the
slabs), chunked by slab: chunk ``k`` holds the planes ``a_k .. a_{k+1} - 1``
of slab ``k`` (the shared last plane belongs to the next slab's chunk), so
every worker writes whole chunks of its own and no two workers touch one
chunk. Attributes: ``origin``, ``spacing`` (x, y, z, mm), ``axes = "zyx"``,
``porecad_version``.

The store is built in a hidden temporary directory next to the target and
renamed onto it only when the run succeeded (:func:`commit_store`);
:func:`discard_store` removes it otherwise. For a remote cluster give a path
that every worker can write (a shared file system).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from porecad.errors import InputError, OutputError

DASK_HINT = 'pip install "porecad[dask]"'


def _zarr():
    try:
        import zarr
    except ImportError:
        raise InputError(f"zarr output needs zarr: {DASK_HINT}") from None
    return zarr


def check_store_path(path, force: bool = False) -> Path:
    """Refuse an existing store (without ``force``) or a missing parent directory, before any work."""
    p = Path(os.fspath(path))
    if p.exists() and not force:
        raise OutputError(f"{p}: already exists (`force` overwrites it)")
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: exists and is not a zarr directory")
    if not p.parent.is_dir():
        raise OutputError(f"{p}: directory {p.parent} does not exist")
    return p


def create_store(path, grid, planes_per_slab: int, force: bool = False) -> str:
    """Create the (temporary) store for ``grid``; return its path for the workers."""
    from porecad.version import __version__
    zarr = _zarr()
    p = check_store_path(path, force)
    from porecad.io.atomic import temp_dir
    try:
        tmp = temp_dir(p, "tmp")
    except OSError as exc:
        raise OutputError(f"{p}: cannot create zarr store: {exc.strerror or exc}") from None
    nx, ny, nz = grid.shape
    step = max(1, int(planes_per_slab) - 1)
    try:
        arr = zarr.open_array(str(tmp), mode="w", shape=(nz, ny, nx), chunks=(min(step, nz), ny, nx),
                              dtype="float32")
        arr.attrs.update({"origin": list(grid.origin), "spacing": list(grid.spacing), "axes": "zyx",
                          "porecad_version": __version__})
    except OSError as exc:
        discard_store(tmp)
        raise OutputError(f"{p}: cannot create zarr store: {exc.strerror or exc}") from None
    return str(tmp)


def store_slab(store: str, F: np.ndarray, a: int, b: int, nz: int) -> None:
    """Write the samples ``F`` of planes ``a .. b``: planes ``a .. b - 1`` (and ``b`` if it is the last)."""
    zarr = _zarr()
    stop = b + 1 if b == nz - 1 else b
    arr = zarr.open_array(store, mode="r+")
    arr[a:stop] = F[: stop - a]


def commit_store(tmp: str, path, force: bool = False) -> None:
    """Rename the finished temporary store onto ``path`` (replacing an old store with ``force``)."""
    p = Path(os.fspath(path))
    if p.exists():
        if not force:
            raise OutputError(f"{p}: already exists (`force` overwrites it)")
        shutil.rmtree(p)
    from porecad.io.atomic import forget_temp
    os.replace(tmp, p)
    forget_temp(tmp)


def discard_store(tmp) -> None:
    """Remove a temporary store (best effort)."""
    from porecad.io.atomic import forget_temp
    forget_temp(tmp, remove=True)


def read_field(path):
    """Read a stored field: ``(values (nz, ny, nx) float32, grid)``."""
    from porecad.mesh.grid import Grid
    zarr = _zarr()
    p = Path(os.fspath(path))
    if not p.is_dir():
        raise InputError(f"{p}: no such zarr store")
    arr = zarr.open_array(str(p), mode="r")
    nz, ny, nx = arr.shape
    grid = Grid(tuple(arr.attrs["origin"]), tuple(arr.attrs["spacing"]), (nx, ny, nz))
    return np.asarray(arr[...]), grid
