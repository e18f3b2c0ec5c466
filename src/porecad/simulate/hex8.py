"""The trilinear 8-node hexahedron (C3D8) of a cubic voxel: stiffness and macro-strain loads.

Local node ``a = dx + 2 dy + 4 dz`` sits at ``(dx, dy, dz) h`` with
``dx, dy, dz`` in ``{0, 1}``; the 24 degrees of freedom are ordered
``3 a + c`` (component ``c`` = x, y, z). Strains use Voigt order
``(11, 22, 33, 23, 13, 12)`` with engineering shears ``γ = 2 ε``.

The element stiffness ``K = ∫ Bᵀ D B dV`` is integrated exactly for the
trilinear element by 2 × 2 × 2 Gauss points (Hughes, *The Finite Element
Method*, 1987, §3.5 and Table 3.I.1); ``D`` is the isotropic elasticity
matrix (Hughes eq. 2.7.35, here in the order above).
"""

from __future__ import annotations

import numpy as np

__all__ = ["isotropic_stiffness", "hex8_stiffness", "hex8_node_offsets", "macro_strain_displacements",
           "voigt_strain_tensor"]


def hex8_node_offsets() -> np.ndarray:
    """(8, 3) int: the ``(dx, dy, dz)`` offset of each local node ``a = dx + 2 dy + 4 dz``."""
    a = np.arange(8)
    return np.stack([a & 1, (a >> 1) & 1, (a >> 2) & 1], axis=1)


def isotropic_stiffness(E: float, nu: float) -> np.ndarray:
    """6 × 6 Voigt stiffness of an isotropic material (engineering shear strains).

    Parameters
    ----------
    E : float
        Young's modulus.
    nu : float
        Poisson's ratio, in (-1, 0.5).

    Returns
    -------
    (6, 6) float64
        ``λ`` off-diagonal in the normal block, ``λ + 2μ`` on its diagonal,
        ``μ`` on the shear diagonal, with ``λ = E ν / ((1 + ν)(1 - 2ν))`` and
        ``μ = E / (2 (1 + ν))``.

    Examples
    --------
    >>> C = isotropic_stiffness(1.0, 0.25)
    >>> float(round(C[0, 0], 6)), float(round(C[3, 3], 6))
    (1.2, 0.4)
    """
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[np.arange(3), np.arange(3)] = lam + 2 * mu
    C[np.arange(3, 6), np.arange(3, 6)] = mu
    return C


def _b_matrix(xi: np.ndarray, h: float) -> np.ndarray:
    """Strain-displacement matrix (6, 24) at reference point ``xi`` in [0, 1]^3 of a cube of side h."""
    off = hex8_node_offsets()
    B = np.zeros((6, 24))
    for a in range(8):
        g = np.empty(3)
        for d in range(3):
            f = [(xi[e] if off[a, e] else 1.0 - xi[e]) for e in range(3)]
            f[d] = 1.0 if off[a, d] else -1.0
            g[d] = f[0] * f[1] * f[2] / h
        c = 3 * a
        B[0, c] = g[0]
        B[1, c + 1] = g[1]
        B[2, c + 2] = g[2]
        B[3, c + 1], B[3, c + 2] = g[2], g[1]
        B[4, c], B[4, c + 2] = g[2], g[0]
        B[5, c], B[5, c + 1] = g[1], g[0]
    return B


def hex8_stiffness(C: np.ndarray, h: float = 1.0) -> np.ndarray:
    """24 × 24 stiffness of a cube of side ``h`` with 6 × 6 Voigt stiffness ``C``.

    Parameters
    ----------
    C : (6, 6) array
        Material stiffness (Voigt, engineering shears), e.g. from
        :func:`isotropic_stiffness`.
    h : float
        Edge length of the voxel.

    Returns
    -------
    (24, 24) float64, symmetric positive semi-definite with the six rigid
    modes as its null space. It scales as ``h``.

    References
    ----------
    T. J. R. Hughes, *The Finite Element Method*, Prentice-Hall 1987, §3.5
    (isoparametric hexahedra) and Table 3.I.1 (Gauss rules).
    """
    g = 0.5 + np.array([-1.0, 1.0]) / (2 * np.sqrt(3.0))
    K = np.zeros((24, 24))
    for x in g:
        for y in g:
            for z in g:
                B = _b_matrix(np.array([x, y, z]), h)
                K += B.T @ C @ B * (h ** 3 / 8.0)
    return 0.5 * (K + K.T)


def voigt_strain_tensor(v) -> np.ndarray:
    """3 × 3 symmetric strain tensor of a Voigt strain vector (engineering shears halved)."""
    e = np.asarray(v, dtype=float)
    return np.array([[e[0], e[5] / 2, e[4] / 2], [e[5] / 2, e[1], e[3] / 2], [e[4] / 2, e[3] / 2, e[2]]])


def macro_strain_displacements(h: float = 1.0) -> np.ndarray:
    """(24, 6): nodal displacements ``ε̄ x`` of the element for the six unit Voigt strains.

    Column ``I`` is the affine displacement of unit strain ``I`` (engineering
    shear 1 for ``I >= 3``) at the element's nodes, relative to node 0.
    """
    off = hex8_node_offsets() * float(h)
    U = np.zeros((24, 6))
    for I in range(6):
        e = np.zeros(6)
        e[I] = 1.0
        U[:, I] = (off @ voigt_strain_tensor(e).T).ravel()
    return U
