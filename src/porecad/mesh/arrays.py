"""Checked mesh arrays: vertices as ``(V, 3)`` float64, faces as ``(F, 3)`` integer indices in range."""

from __future__ import annotations

import numpy as np

from porecad.errors import InputError



def as_faces(faces, n_vertices=None):
    """Return ``faces`` as a C-contiguous ``(F, 3)`` int64 array, checked."""
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must have shape (F, 3), got {f.shape}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise InputError(f"faces must be integers, got dtype {f.dtype}")
    # int32 stays int32 (the polygoniser's output; half the memory of int64)
    f = np.ascontiguousarray(f, dtype=np.int32 if f.dtype == np.int32 else np.int64)
    if f.size:
        lo, hi = int(f.min()), int(f.max())
        if lo < 0:
            raise InputError(f"faces contain a negative vertex index ({lo})")
        if n_vertices is not None and hi >= n_vertices:
            raise InputError(
                f"faces reference vertex {hi} but there are only {n_vertices} vertices"
            )
    return f


def as_vertices(vertices):
    """Return ``vertices`` as a C-contiguous ``(V, 3)`` float64 array, checked."""
    v = np.asarray(vertices)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"vertices must have shape (V, 3), got {v.shape}")
    v = np.ascontiguousarray(v, dtype=np.float64)
    if not np.isfinite(v).all():
        raise InputError("vertices contain NaN or infinite coordinates")
    return v


def as_mesh(vertices, faces):
    """Both arrays checked: ``(vertices float64 (V, 3), faces int (F, 3))`` with indices in range."""
    v = as_vertices(vertices)
    return v, as_faces(faces, len(v))


def narrow_faces(faces: np.ndarray) -> np.ndarray:
    """C-contiguous int32 faces where the indices fit (the polygoniser's type), else int64.

    Kernels then compile one specialisation (the first run's cost) and a large
    int32 build's faces are not copied.
    """
    f = faces
    if f.dtype != np.int32 and (f.size == 0 or int(f.max()) < np.iinfo(np.int32).max):
        f = f.astype(np.int32)
    return np.ascontiguousarray(f)


def scatter_sum(index, values, n: int) -> np.ndarray:
    """``out[index[m]] += values[m]``: ``(n,)`` for ``(M,)`` values, ``(n, k)`` for ``(M, k)``.

    The sums of ``np.add.at`` by ``np.bincount`` per column, several times
    faster on large meshes (per-vertex sums of face values: one call per
    corner, ``index = faces[:, c]``).
    """
    idx = np.asarray(index).reshape(-1)
    w = np.asarray(values, dtype=np.float64)
    if w.ndim == 1:
        return np.bincount(idx, w, minlength=n)
    return np.stack([np.bincount(idx, w[:, c], minlength=n) for c in range(w.shape[1])], axis=1)
