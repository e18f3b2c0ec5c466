"""The conformal sphere of a genus-0 body and cube corners on it (for the hexahedral parameterisation).

Conformalized mean-curvature flow (Kazhdan, Solomon & Ben-Chen, "Can
mean-curvature flow be modified to be non-singular?", Computer Graphics
Forum 31(5), 2012, §4): backward-Euler steps

``(M_t − δ L₀) x_{t+1} = M_t x_t``

with the cotangent Laplacian ``L₀`` of the *input* surface and the lumped
mass ``M_t`` of the current one (:mod:`porecad.mesh.operators`), the surface
re-centred and scaled to unit area after each step. Unlike mean-curvature
flow it does not pinch: a closed genus-0 surface flows to a round sphere,
conformally (angles kept), so thin protrusions (a bunny's ears, limbs)
shrink to small spots while the body's bulk spreads evenly over the sphere.

Used by :func:`porecad.param.hexcube.hex_parameterisation` as the
"sphere" corner choice: the eight corners are the vertices closest to the
diagonal directions ``(±1, ±1, ±1)`` of the body's principal frame on the
sphere (a cube inscribed in it), and the twelve cube edges are the heat
geodesics between them on the sphere (a cubed sphere), which, as vertex
paths of the same triangulation, are edges on the body too. The face maps
are then computed on the body itself (conformal maps from the sphere would
crowd the nodes where the flow shrank a protrusion). Where the box corners
of a body land on a protrusion and fold the cube's faces (the bunny's ear),
these do not.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import InputError
from ..mesh.operators import cotangent_laplacian, face_areas, mass_matrix
from .cube import CUBE, check_corners

__all__ = ["conformal_sphere", "sphere_corners"]

#: flow steps and step size (unit-area surface) of :func:`conformal_sphere`
FLOW_STEPS = 12
FLOW_DT = 0.1


def conformal_sphere(vertices, faces, steps: int = FLOW_STEPS, dt: float = FLOW_DT):
    """Vertices of the body flowed to (nearly) a unit-area sphere by conformalized MCF, (V, 3).

    Returns ``(x, info)``: the flowed vertices centred at the origin, and
    ``{"radius_cv"`` (std / mean of the vertex radii: 0 for a round sphere),
    ``"inverted"`` (triangles facing the centre: the map from the sphere's
    centre is not one-to-one where > 0)``}``.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    if not (isinstance(steps, (int, np.integer)) and 1 <= steps <= 1000) or not 0 < dt <= 10:
        raise InputError(f"flow steps must lie in 1..1000 and the step size in (0, 10]; got {steps!r}, {dt!r}")
    x = v - v.mean(axis=0)
    x /= np.sqrt(face_areas(x, f).sum())
    L = cotangent_laplacian(x, f).tocsc()
    for _ in range(steps):
        m = mass_matrix(x, f)
        x = splu((sp.diags(m) - dt * L).tocsc()).solve(m[:, None] * x)
        m = mass_matrix(x, f)
        x -= (m[:, None] * x).sum(axis=0) / m.sum()
        x /= np.sqrt(face_areas(x, f).sum())
    r = np.linalg.norm(x, axis=1)
    n = np.cross(x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]])
    inverted = int(np.sum(np.einsum("ij,ij->i", n, x[f].mean(axis=1)) <= 0))
    return x, {"radius_cv": float(r.std() / max(r.mean(), 1e-300)), "inverted": inverted}


def sphere_corners(sphere, faces, frame) -> np.ndarray:
    """The eight cube corners on the sphere: the vertices closest to ``R (2 CUBE[k] − 1) / √3``.

    ``frame = (centre, R)`` is the body's principal frame
    (:func:`porecad.param.cube.pca_frame`; columns ``u, v, w``), so corner
    ``k`` lies in the octant of ``CUBE[k]`` (000 Fig. 3.2 order, right-handed).
    """
    x = np.asarray(sphere, np.float64)
    used = np.unique(np.asarray(faces, np.int64))
    d = x[used] / np.maximum(np.linalg.norm(x[used], axis=1, keepdims=True), 1e-300)
    _, R = frame
    dirs = ((2.0 * CUBE - 1.0) / np.sqrt(3.0)) @ R.T
    corners = used[np.argmax(d @ dirs.T, axis=0)]
    return check_corners(corners, len(x))
