"""Homogenised elasticity of a periodic voxel cell: six unit macro strains, multigrid-preconditioned CG.

The cell is a grid of cubic voxels, each void or made of an isotropic phase
``(E, ν)``. With periodic boundary conditions the displacement is
``u = ε̄ x + ũ`` with a periodic fluctuation ``ũ`` (Suquet 1987; Michel,
Moulinec & Suquet 1999, §2); for each of the six unit macro strains
``ε̄ = e_I`` the fluctuation solves ``K ũ = -K (ε̄ x)`` and the effective
stiffness is the mean strain energy (Hill–Mandel)

.. math:: C^*_{IJ} = \\frac{1}{V} \\sum_e (u^I_e)^T K_e\\, u^J_e,
   \\qquad u^I = ε̄^I x + ũ^I .

Voxels are 8-node hexes (:mod:`porecad.simulate.hex8`); the operator is
matrix free and the six systems are solved together by conjugate gradients
preconditioned with one geometric-multigrid V-cycle with Galerkin coarse
operators (:mod:`porecad.simulate.voxel_fe`). Void voxels carry no degrees
of freedom. Solid that is not face-connected to a component spanning the
cell in all three directions carries no load and is removed first (reported);
a cell without such a component is refused (no load path).

References
----------
P. Suquet, "Elements of homogenization for inelastic solid mechanics", in
*Homogenization Techniques for Composite Media*, LNP 272, Springer 1987.
J. C. Michel, H. Moulinec, P. Suquet, "Effective properties of composite
materials with periodic microstructure: a computational approach",
*Comput. Methods Appl. Mech. Engrg.* 172 (1999) 109–143.
E. Andreassen, C. S. Andreasen, "How to determine composite material
properties using numerical homogenization", *Comput. Mater. Sci.* 83 (2014)
488–495 (the voxel form with 8-node hexes used here).
"""

from __future__ import annotations

import time

import numpy as np

from porecad.errors import InputError, ResourceError
from porecad.resources import memory_budget
from porecad.simulate.hex8 import hex8_stiffness, isotropic_stiffness, macro_strain_displacements
from porecad.simulate.periodic_components import periodic_components
from porecad.simulate.voxel_fe import (
    apply_operator,
    axpy,
    coarse_element_matrices,
    coldot,
    element_energy,
    operator_diagonal,
    prolong,
    restrict,
    scatter_element_loads,
    xpby,
)

__all__ = ["check_moduli", "estimate_stiffness_memory", "load_bearing_solid", "homogenise_stiffness",
           "MAX_VOXELS"]

#: Largest cell solved (voxels); beyond it the job is refused before any work.
MAX_VOXELS = 512 ** 3
#: Coarsest multigrid grid: at most this many voxels per axis (solved directly).
_COARSEST = 8
_DENSE_DOFS = 6000


#: Young's moduli accepted (MPa): from soft gels to well past diamond (1.2e6), far from float64's overflow
MODULUS_RANGE = (1e-9, 1e9)


def check_moduli(E, nu, name: str = "solid"):
    """Refuse non-physical isotropic moduli (one-line :class:`InputError`).

    Parameters
    ----------
    E : float
        Young's modulus in :data:`MODULUS_RANGE` (MPa).
    nu : float
        Poisson's ratio, in the open interval (-1, 0.5) where the isotropic
        stiffness is positive definite.
    name : str
        What the moduli belong to, for the message.

    Returns
    -------
    (float, float)
    """
    try:
        E = float(E)
        nu = float(nu)
    except (TypeError, ValueError):
        raise InputError(f"{name} Young's modulus and Poisson ratio must be numbers, got {E!r}, {nu!r}") from None
    if not MODULUS_RANGE[0] <= E <= MODULUS_RANGE[1]:  # NaN too; 1e300 would overflow the solve
        raise InputError(f"{name} Young's modulus must lie in [{MODULUS_RANGE[0]:g}, {MODULUS_RANGE[1]:g}] MPa, "
                         f"got {E:g}")
    if not np.isfinite(nu) or not -1.0 < nu < 0.5:
        raise InputError(f"{name} Poisson ratio must lie in (-1, 0.5) for a stable isotropic solid, got {nu:g}")
    return E, nu


def estimate_stiffness_memory(shape, solid_fraction: float = 1.0, rhs: int = 6) -> int:
    """Peak bytes of :func:`homogenise_stiffness` on a grid of ``shape`` voxels.

    Counts ten vectors of ``N × 3 × rhs`` float64 (the five CG vectors plus
    the temporaries of the fine-level smoothing, residual and prolongation;
    calibrated on a 128³ gyroid cell: 3.6 GB measured peak), the multigrid
    work vectors of the coarse levels (3/7 of a vector set), the float32
    coarse element matrices of the first coarse level (2304 bytes per active
    coarse voxel), the voxel maps, and 150 MB for the interpreter and kernels.
    """
    n = float(np.prod(np.asarray(shape, dtype=np.float64)))
    vec = n * 3 * rhs * 8
    coarse_active = min(1.0, 4.0 * max(solid_fraction, 0.05)) * n / 8
    return int(10 * vec + 0.45 * vec + 1.15 * coarse_active * 2304 + n * 24 + 150e6)


def load_bearing_solid(phase):
    """The voxels of the load-bearing solid (spanning all three axes), and what was removed.

    Parameters
    ----------
    phase : (nz, ny, nx) int array
        ``-1`` void, else the phase index.

    Returns
    -------
    keep : (nz, ny, nx) bool
    info : dict
        ``solid_voxels``, ``removed_voxels`` (floating or partially
        spanning pieces), ``components``.

    Raises
    ------
    InputError
        No component spans the cell in every direction (no load path).
    """
    labels, spans, sizes = periodic_components(phase >= 0)
    full = np.where(spans.all(axis=1))[0]
    solid = int(sizes.sum())
    if solid == 0:
        raise InputError("the cell has no solid: its stiffness is zero")
    if len(full) == 0:
        dirs = [a for a, s in zip("xyz", spans[1:].any(axis=0)) if not s]
        what = f"along {', '.join(dirs)}" if dirs else "in all three directions at once"
        raise InputError(f"the solid has no load path across the cell {what} "
                         f"({len(sizes) - 1} disconnected pieces): its stiffness is zero there")
    keep = np.isin(labels, full)
    kept = int(sizes[full].sum())
    return keep, {"solid_voxels": solid, "removed_voxels": solid - kept, "components": int(len(sizes) - 1)}


class _Level:
    def __init__(self, eidx, emat):
        self.eidx = eidx
        self.emat = emat
        d = operator_diagonal(eidx, emat)
        self.active = d > 0
        self.dinv = np.where(self.active, 1.0 / np.where(self.active, d, 1.0), 0.0)
        self.nodes = self.active.any(axis=3)
        self.lam = self._max_eigenvalue()

    def _max_eigenvalue(self, iterations: int = 8) -> float:
        """Largest eigenvalue of ``D⁻¹ K`` by power iteration (for the Jacobi damping)."""
        x = np.random.default_rng(7).standard_normal(self.active.shape + (1,)) * self.active[..., None]
        lam = 1.0
        for _ in range(iterations):
            nx = np.linalg.norm(x)
            if nx == 0:
                return 1.0
            x /= nx
            y = apply_operator(x, self.eidx, self.emat) * self.dinv[..., None]
            lam = float(np.linalg.norm(y))
            x = y
        return 1.1 * lam


class _Coarsest:
    """Direct solve of the coarsest level (dense Cholesky, or a sparse factorisation)."""

    def __init__(self, level: _Level):
        eidx, emat = level.eidx, level.emat
        nz, ny, nx = eidx.shape
        act = level.active.reshape(-1)
        dof_of = np.full(act.size, -1, dtype=np.int64)
        dof_of[act] = np.arange(int(act.sum()))
        self.dof_of = dof_of
        self.shape = (nz, ny, nx)
        ks, js, is_ = np.nonzero(eidx >= 0)
        off = np.array([[a & 1, (a >> 1) & 1, a >> 2] for a in range(8)])
        nodes = (((ks[:, None] + off[None, :, 2]) % nz) * ny + (js[:, None] + off[None, :, 1]) % ny) * nx \
            + (is_[:, None] + off[None, :, 0]) % nx
        dofs = (3 * nodes[:, :, None] + np.arange(3)[None, None, :]).reshape(len(ks), 24)
        dofs = dof_of[dofs]
        mats = emat[eidx[ks, js, is_]].astype(np.float64)
        n = int(act.sum())
        rows = np.repeat(dofs, 24, axis=1).ravel()
        cols = np.tile(dofs, (1, 24)).ravel()
        from scipy import sparse
        A = sparse.csr_matrix((mats.ravel(), (rows, cols)), shape=(n, n))
        self.n = n
        if n <= _DENSE_DOFS:
            # the periodic operator is singular (rigid translations): add α T Tᵀ over the
            # normalised translations T, which leaves the solution orthogonal to T unchanged
            D = A.toarray()
            comp = np.flatnonzero(act) % 3
            T = np.zeros((n, 3))
            T[np.arange(n), comp] = 1.0
            T /= np.sqrt(np.maximum(T.sum(axis=0), 1.0))
            D += float(np.mean(np.diag(D))) * (T @ T.T)
            from scipy.linalg import cho_factor
            from scipy.linalg import LinAlgError
            try:
                self.kind = "cholesky"
                self.factor = cho_factor(D)
            except LinAlgError:  # near-mechanisms from float32 rounding: pseudo-inverse instead
                w, V = np.linalg.eigh(D)
                keep = w > 1e-9 * w.max()
                self.kind = "dense"
                self.factor = (V[:, keep], 1.0 / w[keep])
        else:
            shift = 1e-7 * float(A.diagonal().mean())
            A = A + shift * sparse.identity(n, format="csr")
            from scipy.sparse.linalg import splu
            self.kind = "splu"
            self.factor = splu(A.tocsc())

    def solve(self, b):
        m = b.shape[-1]
        flat = b.reshape(-1, m)
        act = self.dof_of >= 0
        rhs = flat[act]
        if self.kind == "cholesky":
            from scipy.linalg import cho_solve
            sol = cho_solve(self.factor, rhs)
        elif self.kind == "dense":
            V, winv = self.factor
            sol = V @ (winv[:, None] * (V.T @ rhs))
        else:
            sol = self.factor.solve(np.ascontiguousarray(rhs))
        out = np.zeros_like(flat)
        out[act] = sol
        return out.reshape(b.shape)


class _Hierarchy:
    def __init__(self, eidx, emat, sweeps=2):
        self.levels = [_Level(eidx, emat)]
        self.sweeps = sweeps
        while True:
            e = self.levels[-1].eidx
            shape = np.array(e.shape)
            if np.any(shape % 2) or shape.max() <= _COARSEST or shape.min() < 4:
                break
            cidx, cmat = coarse_element_matrices(e, self.levels[-1].emat)
            self.levels.append(_Level(cidx, cmat))
        last = self.levels[-1]
        ndof = int(last.active.sum())
        if ndof > 400_000:
            raise ResourceError(f"a {'x'.join(map(str, last.eidx.shape[::-1]))} voxel grid cannot be coarsened "
                                "by multigrid (odd size) and is too large to factorise: use an even number "
                                "of voxels per axis (a multiple of 8)")
        self.coarsest = _Coarsest(last)

    def vcycle(self, b, lev=0):
        L = self.levels[lev]
        if lev == len(self.levels) - 1:
            return self.coarsest.solve(b)
        d = (4.0 / (3.0 * L.lam)) * L.dinv[..., None]  # damped Jacobi, Briggs et al. ch. 2
        x = d * b
        for _ in range(self.sweeps - 1):
            x += d * (b - apply_operator(x, L.eidx, L.emat))
        r = b - apply_operator(x, L.eidx, L.emat)
        ec = self.vcycle(restrict(r), lev + 1)
        x += prolong(ec) * L.active[..., None]
        for _ in range(self.sweeps):
            x += d * (b - apply_operator(x, L.eidx, L.emat))
        return x


def _remove_translation(x, nodes):
    """Subtract the mean displacement of the active nodes (the rigid translation) per component."""
    cnt = max(int(nodes.sum()), 1)
    mean = x[nodes].sum(axis=0) / cnt  # (3, m)
    x -= mean[None, None, None] * nodes[..., None, None]


def homogenise_stiffness(phase, voxel: float, materials, tol: float = 1e-6, max_iter: int = 500,
                         progress=None, memory_limit: int | None = None) -> dict:
    """Homogenised 6 × 6 stiffness of a periodic voxel cell.

    Parameters
    ----------
    phase : (nz, ny, nx) int array
        ``-1`` for void, else an index into ``materials``; axes z, y, x.
        Every dimension should be a multiple of 8 for the multigrid.
    voxel : float
        Voxel edge length (mm); the tensor does not depend on it.
    materials : sequence of (E, nu)
        Isotropic phases (E in MPa gives the tensor in MPa).
    tol : float
        Relative residual at which each of the six CG solves stops; the
        tensor's error is of order ``tol²`` (energy norm).
    max_iter : int
        CG iteration limit (a solve that does not converge raises).
    progress : callable(stage, done, total), optional
        Called after every CG iteration with the stage ``"stiffness"``.
    memory_limit : int, optional
        Bytes available (default: the machine's available memory).

    Returns
    -------
    dict
        ``C`` ((6, 6) list, Voigt order 11, 22, 33, 23, 13, 12, engineering
        shears), ``iterations``, ``residual``, ``solid_fraction`` (load-bearing
        solid per cell volume), ``removed_voxels``, ``grid``, ``levels``,
        ``estimate_bytes``, ``time_s``.

    Raises
    ------
    InputError
        Non-physical moduli, a bad phase map, no load path.
    ResourceError
        The job would not fit in memory (refused before the solve, with the estimate).

    References
    ----------
    See the module docstring (Suquet 1987; Michel, Moulinec & Suquet 1999;
    Andreassen & Andreasen 2014; Amir, Aage & Lazarov 2014).

    Examples
    --------
    A two-phase laminate reproduces the exact laminate tensor:

    >>> ph = np.zeros((8, 8, 8), np.int32); ph[4:] = 1
    >>> out = homogenise_stiffness(ph, 0.1, [(1.0, 0.3), (10.0, 0.3)])
    >>> round(float(out["C"][2][2]), 4)   # harmonic mean of the constrained moduli, 2 / (1/M1 + 1/M2)
    2.4476
    """
    t0 = time.perf_counter()
    phase, h, mats, n_vox, est = _checked_cell(phase, voxel, materials, memory_limit)
    keep, info = load_bearing_solid(phase)
    eidx = np.where(keep, phase, -1).astype(np.int32)
    emat = np.stack([hex8_stiffness(isotropic_stiffness(E, nu), h) for E, nu in mats])
    U = macro_strain_displacements(h)
    loads = -np.einsum("pij,jq->piq", emat, U)
    b = scatter_element_loads(eidx, np.ascontiguousarray(loads), 6)
    mg = _Hierarchy(eidx, emat)
    x, it, res = _solve_cg(mg, eidx, emat, loads, b, tol, max_iter, progress)
    energy = element_energy(x, eidx, emat, U)
    V = n_vox * h ** 3
    C = 0.5 * (energy + energy.T) / V
    return {"C": C.tolist(), "iterations": it, "residual": float(res.max()),
            "solid_fraction": float(keep.mean()), "removed_voxels": info["removed_voxels"],
            "grid": list(phase.shape[::-1]), "voxel": h, "levels": len(mg.levels),
            "estimate_bytes": est, "time_s": time.perf_counter() - t0}


def _checked_cell(phase, voxel, materials, memory_limit):
    """Check the inputs of :func:`homogenise_stiffness` and the job size.

    Takes the raw phase map, voxel edge, materials and memory limit; returns
    ``(phase, h, mats, n_vox, est)``: the phase map as an array, the voxel
    edge as a float, the checked ``(E, nu)`` pairs, the voxel count and the
    estimated peak bytes. Raises :class:`InputError` on a bad input and
    :class:`ResourceError` on a cell over the voxel limit or the memory.
    """
    phase = np.asarray(phase)
    if phase.ndim != 3 or min(phase.shape) < 2:
        raise InputError(f"the voxel cell must be a 3-D array with at least 2 voxels per axis, got {phase.shape}")
    if not np.issubdtype(phase.dtype, np.integer):
        raise InputError("the phase map must be integers (-1 void, else a material index)")
    h = float(voxel)
    if not np.isfinite(h) or h <= 0:
        raise InputError(f"voxel size must be positive, got {voxel}")
    mats = [check_moduli(E, nu, f"material {i}") for i, (E, nu) in enumerate(materials)]
    if not mats:
        raise InputError("give at least one material (E, nu)")
    if phase.max() >= len(mats) or phase.min() < -1:
        raise InputError(f"phase indices must lie in -1..{len(mats) - 1}")
    n_vox = int(np.prod(phase.shape))
    if n_vox > MAX_VOXELS:
        raise ResourceError(f"a {'x'.join(map(str, phase.shape[::-1]))} cell has {n_vox:,} voxels, more than the "
                            f"limit {MAX_VOXELS:,}: use fewer voxels")
    est = estimate_stiffness_memory(phase.shape, float((phase >= 0).mean()))
    limit = memory_budget(memory_limit)
    if est > 0.8 * limit:
        raise ResourceError(f"stiffness job too large for this machine: a {'x'.join(map(str, phase.shape[::-1]))} "
                            f"cell needs about {est / 2**30:.1f} GiB, {limit / 2**30:.1f} GiB available; "
                            "use fewer voxels")
    return phase, h, mats, n_vox, est


def _solve_cg(mg, eidx, emat, loads, b, tol, max_iter, progress):
    """Solve the six fluctuation systems together by multigrid-preconditioned CG.

    Takes the :class:`_Hierarchy`, the element index and matrices, the
    element loads (for the residual reference), the assembled loads ``b``
    (six columns) and the solver settings; returns ``(x, it, res)``: the
    fluctuations, the iterations used and the relative residual per column.
    Each column stops once its residual is at most ``tol``. Raises
    :class:`InputError` if they do not all converge in ``max_iter``.
    """
    fine = mg.levels[0]
    m = 6
    x = np.zeros_like(b)
    r = b.copy()
    bnorm = np.sqrt(coldot(b.reshape(-1, m), b.reshape(-1, m)))
    # a load that cancels (e.g. in-plane shear of a laminate: the affine field is exact) is measured
    # against the element loads before assembly, not against its own round-off
    ref = np.sqrt(float((eidx >= 0).sum())) * np.linalg.norm(loads, axis=1).max(axis=0)
    bnorm = np.maximum(bnorm, 1e-6 * ref)
    z = mg.vcycle(r)
    _remove_translation(z, fine.nodes)
    p = z.copy()
    rz = coldot(r.reshape(-1, m), z.reshape(-1, m))
    q = np.empty_like(b)
    it = 0
    res = np.ones(m)
    for it in range(1, max_iter + 1):
        apply_operator(p, eidx, emat, out=q)
        pq = coldot(p.reshape(-1, m), q.reshape(-1, m))
        alpha = np.where(res > tol, rz / np.where(pq == 0, 1.0, pq), 0.0)
        axpy(x.reshape(-1, m), alpha, p.reshape(-1, m))
        axpy(r.reshape(-1, m), -alpha, q.reshape(-1, m))
        res = np.sqrt(coldot(r.reshape(-1, m), r.reshape(-1, m))) / bnorm
        if progress is not None:
            progress("stiffness", it, max_iter)
        if np.all(res <= tol):
            break
        if not np.all(np.isfinite(res)):
            raise InputError("the stiffness solve overflowed (a non-finite residual); check the moduli")
        z = mg.vcycle(r)
        _remove_translation(z, fine.nodes)
        rz_new = coldot(r.reshape(-1, m), z.reshape(-1, m))
        beta = np.where(res > tol, rz_new / np.where(rz == 0, 1.0, rz), 0.0)
        rz = rz_new
        xpby(z.reshape(-1, m), beta, p.reshape(-1, m))
    else:
        raise InputError(f"the stiffness solve did not converge in {max_iter} iterations "
                         f"(relative residual {res.max():.2e}); the cell may be nearly disconnected")
    if progress is not None:
        progress("stiffness", max_iter, max_iter)
    return x, it, res
