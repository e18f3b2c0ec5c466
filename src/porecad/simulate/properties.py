"""Mechanics and flow of a voxel cell: stiffness and permeability, and what follows from them.

Arrays in, dicts out: a solid mask ``[z, y, x]`` and its voxel size (a
design, recipe or mesh, becomes one in :mod:`porecad.jobs.design_source`,
which runs ``porecad properties``). The cell is periodic (stiffness), or a
sample block for the permeability with ``block`` (each direction is solved
on the block mirrored along the flow, a periodic stand-in for a permeameter).

Reported: the homogenised stiffness tensor and what follows from it
(:mod:`porecad.simulate.elastic_tensors`), the Hashin–Shtrikman upper bounds
at the same solid fraction, the permeability tensor with tortuosity
(:mod:`porecad.simulate.stokes`) beside the Kozeny–Carman estimate
(:func:`porecad.analysis.pores.kozeny_carman_permeability`).
"""

from __future__ import annotations

import numpy as np

from porecad.simulate.elastic_tensors import (
    directional_modulus_extremes,
    engineering_constants,
    hashin_shtrikman_upper,
)
from porecad.simulate.homogenise import check_moduli, homogenise_stiffness
from porecad.simulate.stokes import DARCY_MM2, stokes_permeability

__all__ = ["stiffness_properties", "permeability_properties"]


def stiffness_properties(solid, voxel: float, E: float, nu: float, progress=None, directions: int = 2000) -> dict:
    """Homogenised stiffness of a voxel cell and everything derived from it.

    Parameters
    ----------
    solid : (nz, ny, nx) bool
    voxel : float
    E, nu : float
        The solid's isotropic moduli (E in MPa gives moduli in MPa).
    progress : callable, optional
    directions : int
        Directions searched for the extremes of the directional modulus.

    Returns
    -------
    dict
        ``C_MPa`` (6 × 6), ``engineering`` (E1.., G.., ν.., bulk, Zener),
        ``directional_modulus`` (extremes and a θ–φ grid for a plot),
        ``relative_density``, ``relative_modulus`` (mean of E1–E3 over E),
        ``hashin_shtrikman`` (upper bounds at this solid fraction and whether
        the bulk and shear moduli respect them), solver statistics.
    """
    E, nu = check_moduli(E, nu)
    res = homogenise_stiffness(np.where(solid, 0, -1).astype(np.int32), voxel, [(E, nu)], progress=progress)
    C = np.array(res["C"])
    eng = engineering_constants(C)
    rho = float(np.mean(solid))
    hs = hashin_shtrikman_upper(E, nu, rho)
    g_voigt = (C[0, 0] + C[1, 1] + C[2, 2] - C[0, 1] - C[0, 2] - C[1, 2] + 3 * (C[3, 3] + C[4, 4] + C[5, 5])) / 15
    hs.update({"bulk": eng["bulk_modulus"], "shear_voigt": float(g_voigt),
               "within": bool(eng["bulk_modulus"] <= hs["bulk_upper"] * (1 + 1e-9)
                              and g_voigt <= hs["shear_upper"] * (1 + 1e-9))})
    return {"C_MPa": C.tolist(), "engineering": eng,
            "directional_modulus": directional_modulus_extremes(C, refine=directions),
            "relative_density": rho, "load_bearing_fraction": res["solid_fraction"],
            "relative_modulus": float(np.mean([eng["E1"], eng["E2"], eng["E3"]]) / E),
            "hashin_shtrikman": hs, "solid": {"E": E, "nu": nu},
            "solver": {k: res[k] for k in ("iterations", "residual", "levels", "grid", "voxel", "removed_voxels",
                                           "estimate_bytes", "time_s")}}


def permeability_properties(solid, voxel: float, block: bool = False, progress=None, mesh_area=None,
                            mesh_volume=None) -> dict:
    """Permeability of the pore space of a voxel cell, with the Kozeny–Carman estimate beside it.

    Parameters
    ----------
    solid : (nz, ny, nx) bool
    voxel : float
    block : bool
        The cell is a non-periodic sample block: solve each direction on the
        block mirrored along the flow and report the diagonal only.
    mesh_area, mesh_volume : float, optional
        Surface area and solid volume of the mesh, for the Kozeny–Carman estimate.

    Returns
    -------
    dict
        The result of :func:`~porecad.simulate.stokes.stokes_permeability`
        (``permeability_mm2``, ``permeability_darcy``, ``tortuosity``, ...),
        ``method`` (periodic cell or mirrored block) and
        ``kozeny_carman_mm2`` (estimate) when the mesh statistics are given.
    """
    from porecad.analysis.pores import kozeny_carman_permeability

    pore = ~np.asarray(solid, bool)
    if not block:
        out = stokes_permeability(pore, voxel, progress=progress)
        out["method"] = "periodic cell: Stokes flow (MAC finite volumes) under a unit mean pressure gradient"
    else:
        k = np.full((3, 3), np.nan)
        tort, iters, perc, notes = {}, {}, {}, []
        for d in range(3):
            arr_ax = 2 - d
            mirrored = np.concatenate([pore, np.flip(pore, axis=arr_ax)], axis=arr_ax)
            r = stokes_permeability(mirrored, voxel, directions=[d], progress=progress)
            k[:, d] = 0.0
            k[d, d] = r["permeability_mm2"][d][d]
            tort["xyz"[d]] = r["tortuosity"]["xyz"[d]]
            iters.update(r["iterations"])
            perc["xyz"[d]] = r["percolates"]["xyz"[d]]
            notes.append(r["note"])
        out = {"permeability_mm2": k.tolist(), "permeability_darcy": (k / DARCY_MM2).tolist(),
               "principal_mm2": None, "tortuosity": tort, "percolates": perc, "iterations": iters,
               "porosity": float(pore.mean()), "note": "; ".join(sorted(set(notes))),
               "method": "sample block: diagonal only, each direction on the block mirrored along the flow"}
    eps = float(pore.mean())
    if mesh_area and mesh_volume and 0 < eps < 1:
        out["kozeny_carman_mm2"] = kozeny_carman_permeability(eps, mesh_area / mesh_volume)
        out["kozeny_carman_note"] = ("estimate from porosity and the mesh's area per solid volume "
                                     "(as porecad analyze --pores)")
    return out


