"""Darcy permeability of a periodic voxel pore space by a Stokes solve (MAC finite volumes).

Steady Stokes flow ``μ Δu = ∇p - g``, ``∇·u = 0`` is solved in the pore
voxels of a periodic cell on the staggered marker-and-cell (MAC) grid
(Harlow & Welch, *Phys. Fluids* 8 (1965) 2182): pressures at voxel centres,
each velocity component on the voxel faces normal to it. A face between a
pore voxel and a solid one has zero normal velocity; a tangential velocity
next to a solid face sees the no-slip wall half a voxel away (ghost value
``-u``), so walls lie exactly on the voxel faces. The driving force ``g`` is
a unit mean pressure gradient along one axis; Darcy's law
``⟨u⟩ = -(k/μ) ∇p`` gives column ``d`` of the permeability tensor as the
superficial velocity ``⟨u⟩`` (averaged over the whole cell, solid included)
for ``g = e_d`` (Whitaker, *Transp. Porous Media* 1 (1986) 3).

The symmetric saddle-point system is solved by MINRES with the
block-diagonal preconditioner ``diag(A⁻¹, I)``: one algebraic-multigrid
V-cycle (pyamg, smoothed aggregation) for the viscous block and the
identity for the pressure (the pressure Schur complement of the MAC
discretisation is spectrally equivalent to the identity in voxel units;
Elman, Silvester & Wathen, *Finite Elements and Fast Iterative Solvers*, 2nd
ed., OUP 2014, §4.2 and §9.2). Why this method: it is exact for the
voxelised geometry (no compressibility or relaxation parameter, unlike the
lattice Boltzmann method whose wall location and permeability depend on the
relaxation time), the solver is a well-kept library (scipy MINRES, pyamg),
and the cost grows about linearly with the pore voxels.

Hydraulic tortuosity is ``T = ⟨|u|⟩ / ⟨u_d⟩`` over the pore space (Duda,
Koza & Matyka, *Phys. Rev. E* 84 (2011) 036319, eq. 2), with voxel-centred
velocities.

Pore voxels that belong to no component spanning the cell (closed pores)
carry no flow and are removed first; a pore space in which no component
spans the cell gives permeability zero, said so in the result.
"""

from __future__ import annotations

import time

import numpy as np

from porecad.errors import InputError, ResourceError
from porecad.resources import memory_budget
from porecad.simulate.periodic_components import periodic_components

__all__ = ["DARCY_MM2", "estimate_stokes_memory", "stokes_permeability", "MAX_STOKES_VOXELS"]

#: One darcy in mm² (9.869233e-13 m²).
DARCY_MM2 = 9.869233e-7
#: Largest cell solved.
MAX_STOKES_VOXELS = 256 ** 3


def estimate_stokes_memory(shape, porosity: float = 1.0) -> int:
    """Peak bytes of :func:`stokes_permeability` for a cell of ``shape`` voxels and this porosity.

    About 4 velocity unknowns per pore voxel (3 faces + pressure), 7 stored
    matrix entries per velocity (12 bytes each, assembled twice while
    building the saddle matrix), the AMG hierarchy (about 1.5 times the
    viscous matrix) and 10 MINRES work vectors, plus the voxel maps and 150
    MB for the interpreter.
    """
    n = float(np.prod(np.asarray(shape, dtype=np.float64)))
    pores = n * max(float(porosity), 0.01)
    nnz = 3 * pores * 7 + 2 * 3 * pores * 2
    return int(nnz * 12 * 2 + 1.5 * 3 * pores * 7 * 12 + 10 * 4 * pores * 8 + n * 40 + 150e6)


def _faces(fluid):
    """Index of each active face per array axis (``-1`` inactive) and the count."""
    fid = []
    start = 0
    for ax in range(3):
        act = fluid & np.roll(fluid, 1, axis=ax)
        idx = np.full(fluid.shape, -1, dtype=np.int64)
        n = int(act.sum())
        idx[act] = start + np.arange(n)
        start += n
        fid.append(idx)
    return fid, start


def _assemble(fluid):
    from scipy import sparse

    fid, nu = _faces(fluid)
    pid = np.full(fluid.shape, -1, dtype=np.int64)
    npres = int(fluid.sum())
    pid[fluid] = np.arange(npres)
    rows, cols, vals = [], [], []
    diag = np.zeros(nu)
    for ax in range(3):
        f = fid[ax]
        act = f >= 0
        fa = f[act]
        for b in range(3):
            for s in (1, -1):
                nb = np.roll(f, -s, axis=b)[act]
                has = nb >= 0
                rows.append(fa[has])
                cols.append(nb[has])
                vals.append(-np.ones(int(has.sum())))
                diag[fa[has]] += 1.0
                diag[fa[~has]] += 1.0 if b == ax else 2.0  # wall: u = 0 at the face, or ghost -u
    rows.append(np.arange(nu))
    cols.append(np.arange(nu))
    vals.append(diag)
    A = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nu, nu))
    # divergence: face at cell c (lower face of c) is -1 in c and +1 in c - e_ax
    br, bc, bv = [], [], []
    for ax in range(3):
        f = fid[ax]
        act = f >= 0
        br += [pid[act], np.roll(pid, 1, axis=ax)[act]]
        bc += [f[act], f[act]]
        bv += [-np.ones(int(act.sum())), np.ones(int(act.sum()))]
    B = sparse.csr_matrix((np.concatenate(bv), (np.concatenate(br), np.concatenate(bc))), shape=(npres, nu))
    return A, B, fid, pid


def stokes_permeability(pore, voxel: float, directions=(0, 1, 2), tol: float = 1e-8, max_iter: int = 3000,
                        progress=None, memory_limit: int | None = None) -> dict:
    """Darcy permeability tensor of a periodic voxel pore space.

    Parameters
    ----------
    pore : (nz, ny, nx) bool array
        ``True`` in the pore space (fluid); axes z, y, x. Periodic.
    voxel : float
        Voxel edge (mm).
    directions : sequence of int
        Flow directions to solve (0 = x, 1 = y, 2 = z); the tensor columns
        of the others are left as NaN. Give all three for the full tensor.
    tol : float
        MINRES relative residual (preconditioned norm).
    max_iter : int
        MINRES iteration limit per direction.
    progress : callable(stage, done, total), optional
        Called every 10 MINRES iterations with stage ``"stokes x"`` etc.
    memory_limit : int, optional
        Bytes available (default: the machine's available memory).

    Returns
    -------
    dict
        ``permeability_mm2`` (3 × 3 list, x y z order; columns not solved are
        NaN), ``permeability_darcy``, ``principal_mm2`` (eigenvalues of the
        symmetric part), ``tortuosity`` {x, y, z}, ``porosity`` (all pore
        voxels), ``effective_porosity`` (spanning pore space),
        ``percolates`` {x, y, z}, ``closed_pore_voxels``, ``iterations``,
        ``note`` and ``time_s``. A pore space spanning no direction returns
        zeros with ``percolates`` all false and a note saying so.

    References
    ----------
    See the module docstring (Harlow & Welch 1965; Whitaker 1986; Elman,
    Silvester & Wathen 2014; Duda, Koza & Matyka 2011).

    Examples
    --------
    A straight square duct along z (side ``a`` = 20 voxels in a 24-voxel
    cell) has the exact duct permeability (White, *Viscous Fluid Flow*,
    eq. 3-48) ``a²/12 (1 - 192/π⁵ Σ tanh(nπ/2)/n⁵)`` times its area
    fraction, up to the grid error:

    >>> p = np.zeros((2, 24, 24), bool); p[:, 2:22, 2:22] = True
    >>> k = stokes_permeability(p, 1.0, directions=[2])["permeability_mm2"][2][2]
    >>> n = np.arange(1, 200, 2)
    >>> exact = 20**2 / 12 * (1 - 192 / np.pi**5 * np.sum(np.tanh(n * np.pi / 2) / n**5)) * 400 / 576
    >>> bool(abs(k / exact - 1) < 0.02)
    True
    """
    t0 = time.perf_counter()
    pore, h, dirs, porosity, est = _checked_input(pore, voxel, directions, memory_limit)
    labels, keep_c, percolates = _spanning_components(pore)
    base = {"porosity": porosity, "percolates": percolates, "voxel": h, "grid": list(pore.shape[::-1]),
            "estimate_bytes": est}
    if not len(keep_c):
        return _no_flow_result(base, pore, t0)
    fluid = np.isin(labels, keep_c)
    system = _saddle_system(fluid)
    k = np.full((3, 3), float("nan"))
    tort = {a: None for a in "xyz"}
    iters = {}
    for d in dirs:
        _solve_direction(system, fluid, d, percolates, k, tort, iters, tol, max_iter, progress)
    return _flow_result(base, pore, fluid, system, k * h * h, tort, iters, percolates, t0)


def _checked_input(pore, voxel, directions, memory_limit):
    """Check the inputs of :func:`stokes_permeability` and the job size.

    Takes the raw ``pore``, ``voxel``, ``directions`` and ``memory_limit``;
    returns ``(pore, h, dirs, porosity, est)``: the pore space as a bool
    array, the voxel edge as a float, the sorted distinct directions, the
    pore fraction and the estimated peak bytes. Raises :class:`InputError`
    on a bad input or a cell without solid, :class:`ResourceError` on a cell
    too large for the voxel limit or the memory.
    """
    pore = np.asarray(pore, dtype=bool)
    if pore.ndim != 3 or min(pore.shape) < 2:
        raise InputError(f"the pore space must be a 3-D array with at least 2 voxels per axis, got {pore.shape}")
    h = float(voxel)
    if not np.isfinite(h) or h <= 0:
        raise InputError(f"voxel size must be positive, got {voxel}")
    dirs = sorted({int(d) for d in directions})
    if not dirs or any(d not in (0, 1, 2) for d in dirs):
        raise InputError("flow directions must be among 0 (x), 1 (y), 2 (z)")
    n_vox = int(pore.size)
    if n_vox > MAX_STOKES_VOXELS:
        raise ResourceError(f"a {'x'.join(map(str, pore.shape[::-1]))} cell has {n_vox:,} voxels, more than the "
                            f"limit {MAX_STOKES_VOXELS:,} for a Stokes solve: use fewer voxels")
    porosity = float(pore.mean())
    est = estimate_stokes_memory(pore.shape, porosity)
    limit = memory_budget(memory_limit)
    if est > 0.8 * limit:
        raise ResourceError(f"permeability job too large for this machine: a {'x'.join(map(str, pore.shape[::-1]))} "
                            f"cell needs about {est / 2**30:.1f} GiB, {limit / 2**30:.1f} GiB available; "
                            "use fewer voxels")
    if porosity == 1.0:
        raise InputError("the cell has no solid: its permeability is unbounded")
    return pore, h, dirs, porosity, est


def _spanning_components(pore):
    """Periodic pore components that span the cell.

    Takes the bool pore space; returns ``(labels, keep_c, percolates)``: the
    component label per voxel, the labels of the components spanning the
    cell along some axis, and ``{x, y, z}`` → whether any of them spans
    that axis.
    """
    labels, spans, sizes = periodic_components(pore)
    keep_c = np.where(spans.any(axis=1))[0]
    perc = spans[keep_c].any(axis=0) if len(keep_c) else np.zeros(3, bool)
    percolates = {a: bool(perc[i]) for i, a in enumerate("xyz")}
    return labels, keep_c, percolates


def _no_flow_result(base, pore, t0):
    """Result of a pore space spanning no direction.

    Takes the ``base`` report entries, the pore space and the start time;
    returns the report with zero permeability and a note saying why.
    """
    zero = [[0.0] * 3 for _ in range(3)]
    return {**base, "permeability_mm2": zero, "permeability_darcy": zero, "principal_mm2": [0.0] * 3,
            "tortuosity": {a: None for a in "xyz"}, "effective_porosity": 0.0,
            "closed_pore_voxels": int(pore.sum()), "iterations": {},
            "note": "the pore space does not percolate in any direction (no pore path across the cell): "
                    "permeability is zero", "time_s": time.perf_counter() - t0}


def _saddle_system(fluid):
    """Saddle-point matrix and its preconditioner for the fluid voxels.

    Takes the bool mask of the flowing voxels; returns a dict with ``K``
    (the symmetric saddle matrix ``[[A, -Bᵀ], [-B, 0]]``), ``M`` (the
    preconditioner ``diag(AMG V-cycle on A, I)`` as a LinearOperator),
    ``nu`` and ``npres`` (velocity and pressure unknowns), ``fid`` (face
    index per array axis) and ``face_ranges`` (the unknown range of each
    array axis's faces). Raises :class:`InputError` without pyamg.
    """
    from scipy import sparse
    from scipy.sparse.linalg import LinearOperator

    A, B, fid, pid = _assemble(fluid)
    nu, npres = A.shape[0], B.shape[0]
    K = sparse.bmat([[A, -B.T], [-B, None]], format="csr")
    try:
        import pyamg
    except ImportError:
        raise InputError('the permeability solve needs pyamg: pip install "porecad[simulate]"') from None
    ml = pyamg.smoothed_aggregation_solver(A, symmetry="symmetric", max_coarse=500,
                                           smooth=("jacobi", {"weighting": "local"}))
    amg = ml.aspreconditioner(cycle="V")

    def prec(v):
        out = np.empty_like(v)
        out[:nu] = amg @ v[:nu]
        out[nu:] = v[nu:]
        return out

    M = LinearOperator(K.shape, matvec=prec, dtype=np.float64)
    # array axis of physical axis d is 2 - d; face velocities of array axis ax are physical component 2 - ax
    face_ranges = []
    s = 0
    for ax in range(3):
        n = int((fid[ax] >= 0).sum())
        face_ranges.append((s, s + n))
        s += n
    return {"K": K, "M": M, "nu": nu, "npres": npres, "fid": fid, "face_ranges": face_ranges}


def _solve_direction(system, fluid, d, percolates, k, tort, iters, tol, max_iter, progress):
    """Solve the flow driven along physical axis ``d`` and record it.

    Takes the :func:`_saddle_system` dict, the fluid mask, the direction,
    the percolation flags and the solver settings; fills column ``d`` of
    the voxel-unit permeability ``k`` (zero where the pore space does not
    percolate along ``d``), ``tort[axis]`` and ``iters[axis]`` in place and
    returns nothing. Raises :class:`InputError` if MINRES does not converge.
    """
    from scipy.sparse.linalg import minres

    nu, fid, face_ranges = system["nu"], system["fid"], system["face_ranges"]
    ax = 2 - d
    rhs = np.zeros(nu + system["npres"])
    a, b_ = face_ranges[ax]
    rhs[a:b_] = 1.0
    count = [0]

    def cb(_x, name="xyz"[d]):
        count[0] += 1
        if progress is not None and count[0] % 10 == 0:
            progress(f"stokes {name}", count[0], max_iter)

    sol, info = minres(system["K"], rhs, M=system["M"], rtol=tol, maxiter=max_iter, callback=cb)
    if info > 0:
        raise InputError(f"the Stokes solve along {'xyz'[d]} did not converge in {max_iter} iterations; "
                         "use more voxels across the narrowest pores")
    iters["xyz"[d]] = count[0]
    u = sol[:nu]
    n_vox = int(fluid.size)
    for ax2 in range(3):
        a2, b2 = face_ranges[ax2]
        k[2 - ax2, d] = u[a2:b2].sum() / n_vox
    # voxel-centred velocities for the tortuosity
    vel = np.zeros((3,) + fluid.shape)
    for ax2 in range(3):
        f = fid[ax2]
        uf = np.zeros(fluid.shape)
        uf[f >= 0] = u[f[f >= 0]]
        vel[ax2] = 0.5 * (uf + np.roll(uf, -1, axis=ax2))
    speed = np.sqrt((vel ** 2).sum(axis=0))[fluid]
    along = vel[ax][fluid].mean()
    tort["xyz"[d]] = float(speed.mean() / along) if along > 0 and percolates["xyz"[d]] else None
    if not percolates["xyz"[d]]:
        k[:, d] = 0.0


def _flow_result(base, pore, fluid, system, k_mm2, tort, iters, percolates, t0):
    """Report of a solved permeability.

    Takes the ``base`` report entries, the pore space, the fluid mask, the
    :func:`_saddle_system` dict, the permeability in mm², the tortuosity and
    iteration dicts, the percolation flags and the start time; returns the
    full report of :func:`stokes_permeability` (principal values only when
    every column was solved, a note on closed pores and blocked axes).
    """
    solved = np.all(np.isfinite(k_mm2))
    principal = np.linalg.eigvalsh(0.5 * (k_mm2 + k_mm2.T)).tolist() if solved else None
    note = "Stokes flow on the voxelised pore space (MAC finite volumes)"
    closed = int(pore.sum() - fluid.sum())
    if closed:
        note += f"; {closed} voxels of closed pores carry no flow"
    blocked = [a for a in "xyz" if not percolates[a]]
    if blocked:
        note += f"; the pore space does not percolate along {', '.join(blocked)}: permeability zero there"
    return {**base, "permeability_mm2": k_mm2.tolist(), "permeability_darcy": (k_mm2 / DARCY_MM2).tolist(),
            "principal_mm2": principal, "tortuosity": tort, "effective_porosity": float(fluid.mean()),
            "closed_pore_voxels": closed, "iterations": iters, "unknowns": int(system["nu"] + system["npres"]),
            "note": note, "time_s": time.perf_counter() - t0}
