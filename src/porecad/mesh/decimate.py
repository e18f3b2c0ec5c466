"""Decimation of closed manifold meshes that keeps them closed and manifold.

Thin wrapper around the edge-collapse simplification of manifold3d
(``Manifold.simplify``), which only removes an edge when the surface moves by
less than the tolerance and the result stays an oriented 2-manifold.  The mesh
is passed as ``Mesh64`` so coordinates stay float64.

References
----------
.. [1] E. Lalish et al., manifold3d (https://github.com/elalish/manifold),
   ``Manifold::Simplify``.
"""

from __future__ import annotations

import math

import manifold3d
import numpy as np

from porecad.errors import InputError, MeshError
from porecad.mesh.validate import as_mesh

__all__ = ["decimate"]


def to_manifold(v, f):
    mesh = manifold3d.Mesh64(
        vert_properties=np.ascontiguousarray(v, dtype=np.float64),
        tri_verts=np.ascontiguousarray(f, dtype=np.uint64),
    )
    m = manifold3d.Manifold(mesh)
    status = m.status()
    if status != manifold3d.Error.NoError:
        raise MeshError(f"mesh is not a valid closed manifold for decimation: {status.name}")
    return m


def from_manifold(m):
    out = m.to_mesh64()
    v = np.asarray(out.vert_properties, dtype=np.float64)[:, :3].copy()
    f = np.asarray(out.tri_verts).astype(np.int64)
    return v, f


def decimate(vertices, faces, tolerance=None, *, target_faces=None, max_rounds=24):
    """Simplify a closed manifold mesh, keeping it closed and manifold.

    Edges are collapsed while every point of the surface moves by less than
    ``tolerance`` (manifold3d ``Manifold.simplify``).  With ``target_faces``
    the tolerance is found by geometric bisection between ``1e-9 x d`` and
    ``tolerance`` (default: the bounding-box diagonal ``d``): the smallest
    tolerance tried whose result has at most ``target_faces`` faces, to within
    a factor 1.05 or ``max_rounds`` simplifications of the full mesh.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array
        A closed, oriented 2-manifold.
    tolerance : float, optional
        Largest allowed surface deviation (mesh units).  Required unless
        ``target_faces`` is given, in which case it caps the search.
    target_faces : int, optional
        Aim for at most this many faces.  If even the largest tolerance
        allowed leaves more, that result is returned.
    max_rounds : int
        Bisection steps for ``target_faces``.

    Returns
    -------
    vertices : (V', 3) float64 array
    faces : (F', 3) int64 array
        Vertices are a subset of the input's, renumbered; faces keep the
        input's orientation.

    Raises
    ------
    MeshError
        If manifold3d rejects the input (not closed, not manifold, ...).
    InputError
        On bad arguments.
    """
    v, f = as_mesh(vertices, faces)
    if len(f) == 0:
        raise MeshError("mesh is empty: no faces")
    if tolerance is None and target_faces is None:
        raise InputError("give tolerance, target_faces or both")
    if tolerance is not None and not (tolerance >= 0 and math.isfinite(tolerance)):
        raise InputError(f"tolerance must be a finite number >= 0, got {tolerance}")
    m = to_manifold(v, f)
    if target_faces is None:
        return from_manifold(m.simplify(float(tolerance)))
    target_faces = int(target_faces)
    if target_faces < 4:
        raise InputError(f"target_faces must be >= 4, got {target_faces}")
    if m.num_tri() <= target_faces:
        return from_manifold(m)
    diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    hi = float(tolerance) if tolerance is not None else diag
    best = m.simplify(hi)
    if best.num_tri() > target_faces or hi <= 0:
        return from_manifold(best)
    lo = min(1e-9 * diag, hi / 2)
    for _ in range(int(max_rounds)):
        if hi <= 1.05 * lo:
            break
        mid = math.sqrt(lo * hi)
        s = m.simplify(mid)
        if s.num_tri() <= target_faces:
            hi, best = mid, s
        else:
            lo = mid
    return from_manifold(best)
