"""Independent check of the voxel homogenisation: periodic FE on a tetrahedral mesh with scikit-fem.

scikit-fem (BSD-3; Gustafsson & McBain, *J. Open Source Softw.* 5 (2020)
2369) assembles the linear-elasticity stiffness on a periodic tet mesh from
:func:`porecad.simulate.tetmesh_solid.periodic_volume_mesh` with linear (P1)
or quadratic (P2) Lagrange elements. Periodicity is imposed by identifying
every degree of freedom on an upper face with its image on the lower face
(``K_r = Pᵀ K P``; Michel, Moulinec & Suquet 1999, §2.3), one node is pinned
against rigid translation, and for each unit macro strain ``ε̄`` the
fluctuation solves ``K_r ũ = -Pᵀ K u_aff`` with ``u_aff = ε̄ x`` interpolated
exactly at the degrees of freedom. The tensor is the mean energy, as in
:mod:`porecad.simulate.homogenise`. Nothing here shares code with the voxel
solver: geometry (a smooth tet mesh instead of voxels), elements,
assembly and solver are all different.
"""

from __future__ import annotations

import time

import numpy as np

from porecad.errors import InputError
from porecad.simulate.homogenise import check_moduli

__all__ = ["tet_homogenise_stiffness"]


def _periodic_map(locs, comp, lo, hi):
    """For each scalar dof, the index of its master: same component, location wrapped onto the lower faces."""
    L = hi - lo
    tol = 1e-7 * float(L.max())
    w = locs - lo
    for a in range(3):
        w[:, a] = np.where(np.abs(w[:, a] - L[a]) <= tol, 0.0, w[:, a])
    key = np.concatenate([np.round(w / tol).astype(np.int64), comp[:, None]], axis=1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return first[inv.ravel()]


def tet_homogenise_stiffness(points, tets, lo, hi, E: float, nu: float, order: int = 2,
                             direct_limit: int = 30_000) -> dict:
    """Homogenised 6 × 6 stiffness of a periodic tet mesh of a cell by scikit-fem.

    Parameters
    ----------
    points : (N, 3) float array
    tets : (T, 4) int array
        Linear tets of a periodic mesh (opposite faces matching).
    lo, hi : (3,) float
        The cell box.
    E, nu : float
        Isotropic solid.
    order : {1, 2}
        Lagrange element order (P2 = quadratic tets, C3D10).
    direct_limit : int
        Up to this many unknowns a sparse direct solve, beyond it CG with
        pyamg smoothed aggregation (rigid-body near-null space).

    Returns
    -------
    dict
        ``C`` (6 × 6 list, Voigt 11, 22, 33, 23, 13, 12), ``dofs``,
        ``solid_fraction`` (mesh volume / cell volume), ``time_s``.
    """
    E, nu = check_moduli(E, nu)
    t0 = time.perf_counter()
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    fe = _periodic_system(points, tets, lo, hi, E, nu, order)
    K, P, free = fe["K"], fe["P"], fe["free"]
    U = _affine_displacements(fe["locs"], fe["comp"], lo)
    B = -(P.T @ (K @ U))[free]
    sol, iters = _solve_fluctuations(fe, B, direct_limit)
    ur = np.zeros((len(fe["masters"]), 6))
    ur[free] = sol
    Ut = U + P @ ur
    V = float(np.prod(hi - lo))
    C = Ut.T @ (K @ Ut) / V
    q = np.asarray(points, float)[np.asarray(tets, np.int64)]
    vol = float(np.einsum("ij,ij->i", q[:, 1] - q[:, 0], np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 0])).sum() / 6)
    return {"C": (0.5 * (C + C.T)).tolist(), "dofs": int(len(free)), "order": int(order),
            "solver": "splu" if len(free) <= direct_limit else f"cg+amg {iters}",
            "solid_fraction": vol / V, "time_s": time.perf_counter() - t0}


def _periodic_system(points, tets, lo, hi, E, nu, order):
    """Assemble the periodic elasticity system of the tet mesh with scikit-fem.

    Takes the mesh, the cell box (float arrays), the moduli and the element
    order; returns a dict with ``K`` (the full stiffness), ``P`` (the
    periodic identification, dofs × masters), ``Kf`` (``Pᵀ K P`` on the
    free masters, CSC), ``locs`` and ``comp`` (location and component of
    each scalar dof), ``masters``, ``mc`` (component of each master) and
    ``free`` (masters left after pinning one node's three components).
    Raises :class:`InputError` on an order other than 1 or 2.
    """
    import skfem
    from scipy.sparse import csr_matrix
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    mesh = skfem.MeshTet(np.asarray(points, float).T.copy(), np.asarray(tets, np.int64).T.copy())
    el = skfem.ElementVector(skfem.ElementTetP2() if order == 2 else skfem.ElementTetP1())
    if order not in (1, 2):
        raise InputError(f"element order must be 1 or 2, got {order}")
    basis = skfem.Basis(mesh, el)
    lam, mu = lame_parameters(E, nu)
    K = linear_elasticity(lam, mu).assemble(basis).tocsr()
    locs = basis.doflocs.T  # (ndofs, 3): location of each scalar dof
    ndof = locs.shape[0]
    # dof component: skfem interleaves vector components per node/edge
    comp = np.zeros(ndof, dtype=np.int64)
    for c in range(3):
        comp[basis.nodal_dofs[c]] = c
        if basis.edge_dofs.size:
            comp[basis.edge_dofs[c]] = c
    master = _periodic_map(locs.copy(), comp, lo, hi)
    masters, col = np.unique(master, return_inverse=True)
    P = csr_matrix((np.ones(ndof), (np.arange(ndof), col)), shape=(ndof, len(masters)))
    Kr = (P.T @ K @ P).tocsr()
    # pin the three components of one master node against translation
    mc = comp[masters]
    pin = [int(np.flatnonzero(mc == c)[0]) for c in range(3)]
    free = np.setdiff1d(np.arange(len(masters)), pin)
    Kf = Kr[free][:, free].tocsc()
    return {"K": K, "P": P, "Kf": Kf, "locs": locs, "comp": comp, "masters": masters, "mc": mc, "free": free}


def _affine_displacements(locs, comp, lo):
    """Affine fields ``ε̄ (x - lo)`` of the six unit macro strains at the dofs.

    Takes the dof locations, their components and the lower cell corner;
    returns the ``(ndof, 6)`` array, one column per Voigt strain.
    """
    from porecad.simulate.hex8 import voigt_strain_tensor

    ndof = locs.shape[0]
    x = locs
    U = np.zeros((ndof, 6))
    for I in range(6):
        e = np.zeros(6)
        e[I] = 1.0
        eps = voigt_strain_tensor(e)
        U[:, I] = np.einsum("ij,nj->ni", eps, x - lo)[np.arange(ndof), comp]
    return U


def _solve_fluctuations(fe, B, direct_limit):
    """Solve ``Kf ũ = B`` for the six right-hand sides.

    Takes the :func:`_periodic_system` dict, the ``(free, 6)`` loads and the
    direct-solve limit; returns ``(sol, iters)``: the free-dof fluctuations
    and the CG iterations per column (``None`` after a sparse direct solve,
    used up to ``direct_limit`` unknowns). Beyond it, CG with pyamg smoothed
    aggregation on the rigid-body near-null space; raises
    :class:`InputError` if a CG solve does not converge.
    """
    from scipy.sparse.linalg import splu

    Kf, free = fe["Kf"], fe["free"]
    if len(free) <= direct_limit:
        return splu(Kf).solve(np.ascontiguousarray(B)), None
    import pyamg
    from scipy.sparse.linalg import cg
    # rigid-body modes of the free dofs as the near-null space (translations and rotations)
    xf = fe["locs"][fe["masters"][free]]
    cf = fe["mc"][free]
    Bns = np.zeros((len(free), 6))
    for c in range(3):
        Bns[cf == c, c] = 1.0
    for r, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):  # rotation about axis r: u_a = -x_b, u_b = x_a
        Bns[cf == a, 3 + r] = -xf[cf == a, b]
        Bns[cf == b, 3 + r] = xf[cf == b, a]
    ml = pyamg.smoothed_aggregation_solver(Kf.tocsr(), B=Bns, symmetry="symmetric",
                                           smooth=("jacobi", {"weighting": "local"}))
    M = ml.aspreconditioner()
    sol = np.zeros_like(B)
    iters = []
    for I in range(6):
        n_it = [0]
        sol[:, I], info = cg(Kf, B[:, I], M=M, rtol=1e-8, maxiter=2000,
                             callback=lambda _x, n=n_it: n.__setitem__(0, n[0] + 1))
        iters.append(n_it[0])
        if info:
            raise InputError("the scikit-fem reference solve did not converge")
    return sol, iters
