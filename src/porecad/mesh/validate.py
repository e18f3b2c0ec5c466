"""Validation of triangle meshes as printable solids.

A triangle mesh bounds a solid only if it is *closed* (no boundary edges),
*manifold* (every edge is shared by exactly two faces and the faces around
every vertex form one fan), *consistently oriented* (each edge is traversed
once in each direction by its two faces), *outward* (positive signed volume)
and free of *self-intersections*.  This module checks each property on plain
arrays, libigl style: ``vertices`` is an ``(V, 3)`` float array and ``faces``
an ``(F, 3)`` integer array of counter-clockwise (seen from outside) vertex
indices.

The combinatorial checks work on vertex *indices*: coincident but unmerged
vertices are different vertices.

Public functions
----------------
edge_topology (in :mod:`porecad.mesh.topology`)
    Edge and vertex incidence counts, and the ``closed`` / ``manifold`` /
    ``oriented`` verdicts derived from them.
signed_volume, surface_area
    Scalar measures.
self_intersections (in :mod:`porecad.mesh.intersections`, re-exported here)
    Pairs of faces that intersect other than along shared edges and vertices.
check_solid
    All of the above as a report.
stored_coordinates, stored_with
    Vertices rounded as the mesh files store them (float32), so that a
    solid is checked exactly as it will be read back.

References
----------
.. [1] T. Möller, "A fast triangle-triangle intersection test", Journal of
   Graphics Tools 2(2):25-30, 1997.
.. [2] P. Guigue, O. Devillers, "Fast and robust triangle-triangle overlap test
   using orientation predicates", Journal of Graphics Tools 8(1):25-32, 2003.
.. [3] C. Zhang, T. Chen, "Efficient feature extraction for 2D/3D objects in
   mesh representation", ICIP 2001 (signed volume by the divergence theorem).
.. [4] M. Teschner et al., "Optimized spatial hashing for collision detection
   of deformable objects", VMV 2003 (uniform grid hashed into a table).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from porecad.errors import InputError
from porecad.mesh.arrays import as_mesh, as_vertices, narrow_faces  # noqa: F401 - as_mesh re-exported
from porecad.mesh.intersections import self_intersections  # noqa: F401 - re-exported
from porecad.mesh.topology import edge_topology, topology_of_checked  # noqa: F401 - edge_topology re-exported

__all__ = [
    "signed_volume",
    "surface_area",
    "bounds",
    "self_intersections",
    "check_solid",
]


# ---------------------------------------------------------------------------
# measures
# ---------------------------------------------------------------------------


_SUM_BLOCK = 4096


@njit(cache=True, nogil=True)
def _block_volume_area(vertices, faces, c, vol, area, first, step):
    """Per-block sums of ``det[p0-c, p1-c, p2-c] / 6`` and ``|(p1-p0) x (p2-p0)| / 2`` into ``vol``, ``area``.

    Blocks of ``_SUM_BLOCK`` faces ``first, first + step, ...`` (one run per
    thread: :func:`porecad.kernel_threads.run_interleaved`); the caller adds
    the block sums with numpy's pairwise summation, so the result does not
    depend on the number of threads.
    """
    nf = faces.shape[0]
    nb = vol.shape[0]
    for blk in range(first, nb, step):
        sv = 0.0
        sa = 0.0
        for f in range(blk * _SUM_BLOCK, min(nf, (blk + 1) * _SUM_BLOCK)):
            i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
            ax = vertices[i, 0] - c[0]
            ay = vertices[i, 1] - c[1]
            az = vertices[i, 2] - c[2]
            bx = vertices[j, 0] - c[0]
            by = vertices[j, 1] - c[1]
            bz = vertices[j, 2] - c[2]
            cx = vertices[k, 0] - c[0]
            cy = vertices[k, 1] - c[1]
            cz = vertices[k, 2] - c[2]
            sv += (ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)) / 6.0
            ux, uy, uz = bx - ax, by - ay, bz - az
            wx, wy, wz = cx - ax, cy - ay, cz - az
            nx = uy * wz - uz * wy
            ny = uz * wx - ux * wz
            nz = ux * wy - uy * wx
            sa += 0.5 * math.sqrt(nx * nx + ny * ny + nz * nz)
        vol[blk] = sv
        area[blk] = sa


def _column_bounds(v):
    """``(lo, hi)`` of the columns of a finite ``(V, 3)`` array, ``V > 0``, column by column (numpy's
    ``min(axis=0)`` over three-wide rows took 15 times as long)."""
    return (np.array([v[:, c].min() for c in range(3)]), np.array([v[:, c].max() for c in range(3)]))


def bounds(vertices):
    """Axis-aligned bounding box ``(lo, hi)`` of the vertices, as two ``(3,)`` arrays."""
    v = as_vertices(vertices)
    if len(v) == 0:
        raise InputError("no vertices: the bounding box is undefined")
    return _column_bounds(v)


def _volume_area(vertices, faces):
    v, f = as_mesh(vertices, faces)
    return _volume_area_of(v, f)


def _volume_area_of(v, f):
    """:func:`_volume_area` of arrays already checked (:func:`~porecad.mesh.arrays.as_mesh`)."""
    if len(f) == 0:
        return 0.0, 0.0
    from ..kernel_threads import run_interleaved

    c = v[f[:: max(1, len(f) // 4096), 0]].mean(axis=0)  # a point amid the referenced vertices
    nb = (len(f) + _SUM_BLOCK - 1) // _SUM_BLOCK
    vol, area = np.zeros(nb), np.zeros(nb)
    run_interleaved(_block_volume_area, nb, v, narrow_faces(f), c, vol, area, min_per_thread=32)
    return float(np.sum(vol)), float(np.sum(area))


def signed_volume(vertices, faces):
    """Signed volume enclosed by a closed triangle mesh.

    By the divergence theorem ([3]_),

    .. math:: V = \\frac{1}{6} \\sum_f (p_0 - c) \\cdot \\big((p_1 - c) \\times (p_2 - c)\\big),

    the sum of signed tetrahedra from a reference point ``c`` to every face.
    ``c`` is the mean of sampled face corners; for a closed mesh the result does not depend
    on ``c``, and a nearby ``c`` avoids cancellation far from the origin.
    Positive for outward (counter-clockwise seen from outside) faces.
    Accumulated in float64: blocks of faces in parallel, the block sums
    with numpy's pairwise summation.

    For an open mesh the value depends on ``c`` and is not a volume.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array

    Returns
    -------
    float
    """
    return _volume_area(vertices, faces)[0]


def surface_area(vertices, faces):
    """Total area ``sum_f |(p1 - p0) x (p2 - p0)| / 2`` of a triangle mesh.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array

    Returns
    -------
    float
    """
    return _volume_area(vertices, faces)[1]


def stored_coordinates(vertices) -> np.ndarray:
    """``vertices`` rounded to float32, as STL and PLY files store them (a float64 array).

    Rounding can move a vertex by up to 6e-8 of its coordinate, enough to make
    two nearly touching slivers of a strongly stretched map cross: a solid is
    checked for self-intersections on these coordinates, and the jobs write
    exactly them (OBJ and 3MF store them exactly too), so that the file read
    back passes the same check. A float32 array is already as stored and is
    returned as it is (no float64 copy of a large marching-cubes mesh).
    """
    v = np.asarray(vertices)
    if v.dtype == np.float32:
        return v
    return np.asarray(v, dtype=np.float64).astype(np.float32).astype(np.float64)


def stored_with(vertices, known):
    """``(stored_coordinates(vertices), known)``, ``known`` (e.g. crossing pairs counted on ``vertices``)
    replaced by None when the rounding moved a vertex: it was measured on other coordinates."""
    v = stored_coordinates(vertices)
    if known is not None and not np.array_equal(v, np.asarray(vertices)):
        known = None
    return v, known


# ---------------------------------------------------------------------------
# reports
# ---------------------------------------------------------------------------


def check_solid(vertices, faces, check_self_intersections=True):
    """Whether the mesh bounds a solid, as a report: faces present, no degenerate face, closed, manifold
    edges and vertices, consistent and outward orientation, optionally no self-intersections.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
    check_self_intersections : bool
        Run :func:`self_intersections` (the expensive part).

    Returns
    -------
    dict
        ``closed``, ``manifold``, ``oriented`` (see :func:`~porecad.mesh.topology.edge_topology`),
        ``outward`` (signed volume > 0), ``self_intersections`` (number of
        intersecting face pairs, None when not checked), ``volume`` (signed),
        ``area``, ``bounds`` (``[lo, hi]`` lists, None without vertices); plus
        the counts of :func:`~porecad.mesh.topology.edge_topology`.
    """
    v, f = as_mesh(vertices, faces)
    topo = topology_of_checked(f)
    volume, area = _volume_area_of(v, f)
    n_self = self_intersections(v, f, max_report=0)[1] if check_self_intersections else None
    report = dict(
        closed=topo["closed"],
        manifold=topo["manifold"],
        oriented=topo["oriented"],
        outward=volume > 0,
        self_intersections=n_self,
        volume=volume,
        area=area,
        bounds=[b.tolist() for b in _column_bounds(v)] if len(v) else None,
    )
    for k, val in topo.items():
        report.setdefault(k, val)
    return report
