"""Voxel images of a unit cell: from a periodic field (a TPMS box of whole cells) or from a closed mesh.

A TPMS box of whole cells is periodic: its material field is
sampled at voxel centres ``lo + (i + ½) h`` and a voxel is solid where the
field is ≤ 0 (porecad's sign convention: negative inside material). A mesh is
voxelised over its bounding box by winding number (inside where the
generalised winding number is positive; :class:`porecad.bodies.mesh.MeshBody`).
Arrays are ordered ``[z, y, x]``.
"""

from __future__ import annotations

import numpy as np

from porecad.errors import InputError, ResourceError

__all__ = ["field_cell_voxels", "mesh_voxels", "MAX_CELL_VOXELS"]

#: Largest voxel image built here.
MAX_CELL_VOXELS = 512 ** 3


def _counts(ext, n: int):
    n = int(n)
    if n < 2:
        raise InputError(f"voxels per edge must be at least 2, got {n}")
    h = float(np.min(ext)) / n
    counts = np.maximum(np.round(ext / h).astype(np.int64), 1)
    if float(np.prod(counts.astype(float))) > MAX_CELL_VOXELS:
        raise ResourceError(f"a {counts[0]}x{counts[1]}x{counts[2]} voxel image is too large "
                            f"(at most {MAX_CELL_VOXELS:,} voxels): use fewer voxels")
    return h, counts


def field_cell_voxels(field, lo, hi, voxels: int):
    """Solid mask of a periodic field over the box ``[lo, hi]`` (whole cells): voxel centres, solid where ≤ 0.

    Parameters
    ----------
    field : Field
        Negative inside material (a TPMS design's field).
    lo, hi : (3,) float
        The box of whole cells (exactly periodic).
    voxels : int
        Voxels along the shortest box edge (cubic voxels, up to rounding of the counts).

    Returns
    -------
    solid : (nz, ny, nx) bool
    voxel : float
        Edge length (mm).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    h, n = _counts(hi - lo, voxels)
    hs = (hi - lo) / n  # exact fit of the box (cubic up to rounding of the cell counts)
    axes = [lo[a] + (np.arange(n[a]) + 0.5) * hs[a] for a in range(3)]
    solid = np.empty((n[2], n[1], n[0]), dtype=bool)
    step = max(1, int(4e6 // max(n[0] * n[1], 1)))
    for z0 in range(0, n[2], step):
        solid[z0:z0 + step] = field.sample_grid(axes[0], axes[1], axes[2][z0:z0 + step]) <= 0
    return solid, float(hs.mean())


def mesh_voxels(vertices, faces, voxels: int, box=None):
    """Solid mask of a closed mesh over its bounding box (or ``box``), by winding number.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        Closed and outward oriented.
    voxels : int
        Voxels along the shortest box edge.
    box : ((3,), (3,)), optional
        ``(lo, hi)``; default the mesh's bounding box.

    Returns
    -------
    solid : (nz, ny, nx) bool
    voxel : float
    origin : (3,) float
        Centre of voxel (0, 0, 0).
    """
    from porecad.bodies.mesh import MeshBody

    v = np.asarray(vertices, dtype=np.float64)
    lo, hi = (v.min(axis=0), v.max(axis=0)) if box is None else (np.asarray(box[0], float), np.asarray(box[1], float))
    h, n = _counts(hi - lo, voxels)
    hs = (hi - lo) / n
    axes = [lo[a] + (np.arange(n[a]) + 0.5) * hs[a] for a in range(3)]
    body = MeshBody(v, faces, band=float(hs.max()))
    solid = np.empty((n[2], n[1], n[0]), dtype=bool)
    step = max(1, int(2e6 // max(n[0] * n[1], 1)))
    for z0 in range(0, n[2], step):
        solid[z0:z0 + step] = body.sample_grid(axes[0], axes[1], axes[2][z0:z0 + step]) < 0
    return solid, float(hs.mean()), lo + 0.5 * hs
