"""Discrete differential operators on triangle meshes: cotangent weights, Laplacian and lumped mass.

One implementation used by smoothing (:mod:`porecad.mesh.smooth`), the heat
method (:mod:`porecad.param.heat`) and the hexahedral parameterisation's
harmonic maps (:mod:`porecad.param.patch_maps`, :mod:`porecad.param.cube_edges`).

* corner cotangents ``cot θ_c`` of every triangle corner;
* edge weights ``w_ij = ½ (cot α_ij + cot β_ij)``, ``α_ij, β_ij`` the angles
  opposite edge ``ij`` (the standard cotangent weights, Pinkall & Polthier,
  "Computing discrete minimal surfaces and their conjugates", Exp. Math. 2(1),
  1993; 000 eq. 3.1.2 with the erratum of the notes: not normalised to 1);
* integrated cotangent Laplacian ``(L u)_i = Σ_j w_ij (u_j − u_i)``
  (negative semi-definite);
* lumped (barycentric) mass ``A_i = ⅓ Σ_{f∋i} |f|``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InputError

__all__ = ["corner_cotangents", "cotangent_laplacian", "edge_cotangent_weights", "edge_index", "face_areas", "mass_matrix",
           "triangle_mesh"]


def triangle_mesh(vertices, faces):
    """Checked ``(v (V, 3) float64, f (F, 3) int64)``; a one-line :class:`InputError` otherwise."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise InputError(f"a triangle mesh needs vertices (V, 3) and faces (F, 3); got {v.shape} and {f.shape}")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"face indices must lie in 0..{len(v) - 1}")
    return v, f


def corner_cotangents(vertices, faces) -> np.ndarray:
    """Cotangent of the angle at each corner of each face, (F, 3); the angle at corner c is opposite edge (c+1, c+2)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cots = np.empty((len(f), 3))
    for c, (a, b, o) in enumerate(((p0, p1, p2), (p1, p2, p0), (p2, p0, p1))):
        e1, e2 = b - a, o - a
        cr = np.linalg.norm(np.cross(e1, e2), axis=1)
        cots[:, c] = np.einsum("ij,ij->i", e1, e2) / np.maximum(cr, 1e-300)
    return cots


def face_areas(vertices, faces) -> np.ndarray:
    """Triangle areas ``|f| = ½ |(x₁ − x₀) × (x₂ − x₀)|``, (F,)."""
    v, f = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


def edge_cotangent_weights(vertices, faces, index=None):
    """Unique edges and their weights ``w_ij = ½ (cot α_ij + cot β_ij)``: ``(i (E,), j (E,), w (E,))``, ``i < j``.

    A boundary edge has one opposite angle and gets ``½ cot α``. Weights are
    not clipped (obtuse angles can make them negative). ``index``: the faces'
    :func:`edge_index`, when an iteration that moves vertices found it once.
    """
    f = np.asarray(faces, np.int64)
    i, j, inv = edge_index(f, len(vertices)) if index is None else index
    return i, j, np.bincount(inv, weights=0.5 * corner_cotangents(vertices, f).T.ravel(), minlength=len(i))


def edge_index(faces, n_vertices: int):
    """The unique edges of a triangle mesh and where each face corner's opposite edge is among them.

    Returns ``(i (E,), j (E,), inv (3F,))`` with ``i < j`` and ``inv[c F + k]``
    the edge opposite corner ``c`` of face ``k`` (the layout of
    ``corner_cotangents(...).T.ravel()``), so per-edge sums of corner values
    are one :func:`numpy.bincount` (the edges depend on the faces only: an
    iteration that moves vertices finds them once).
    """
    f = np.asarray(faces, np.int64)
    n = int(n_vertices)
    i = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    uk, inv = np.unique(np.minimum(i, j) * n + np.maximum(i, j), return_inverse=True)
    return uk // n, uk % n, inv.ravel()


def cotangent_laplacian(vertices, faces) -> sp.csr_matrix:
    """Integrated cotangent Laplacian ``L`` (V, V), negative semi-definite.

    ``L_ij = w_ij = ½ (cot α_ij + cot β_ij)`` for an edge ``ij`` and
    ``L_ii = −Σ_j L_ij`` (000 eq. 3.1.2 with the standard sign and weights).
    """
    v, f = triangle_mesh(vertices, faces)
    i, j, w = edge_cotangent_weights(v, f)
    n = len(v)
    W = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                      shape=(n, n)).tocsr()
    return (W - sp.diags(np.asarray(W.sum(axis=1)).ravel())).tocsr()


def mass_matrix(vertices, faces) -> np.ndarray:
    """Barycentric lumped vertex areas ``A_i = ⅓ Σ_{f∋i} |f|``, (V,)."""
    v, f = triangle_mesh(vertices, faces)
    a = face_areas(v, f) / 3.0
    return np.bincount(f.ravel(), weights=np.repeat(a, 3), minlength=len(v))
