"""Homogenised stiffness by periodic voxel FE against references nobody here wrote (issue 23)."""

import numpy as np
import pytest

from porecad.errors import InputError, ResourceError
from porecad.simulate import (
    directional_modulus,
    engineering_constants,
    gibson_ashby_fit,
    hashin_shtrikman_upper,
    homogenise_stiffness,
    laminate_stiffness,
)
from porecad.jobs.design_source import recipe_cell_voxels
from porecad.simulate.hex8 import isotropic_stiffness
from porecad.simulate.properties import stiffness_properties


def test_two_phase_laminate_matches_the_exact_laminate_tensor():
    """Backus (1962) / Milton (2002) §9.5: exact for layers; voxel FE is exact for flat layers too."""
    ph = np.zeros((16, 8, 8), np.int32)  # [z, y, x]: layers normal to z
    ph[10:] = 1
    mats = [(1.0, 0.3), (12.0, 0.2)]
    out = homogenise_stiffness(ph, 0.05, mats)
    exact = laminate_stiffness(mats, [10 / 16, 6 / 16])
    C = np.array(out["C"])
    nz = np.abs(exact) > 1e-12
    assert np.max(np.abs(C[nz] / exact[nz] - 1)) < 0.01
    assert np.max(np.abs(C[~nz])) < 1e-6 * exact.max()
    # the laminate really is anisotropic: in-plane and through-thickness moduli differ by > 2x
    assert exact[0, 0] > 2 * exact[2, 2]


def test_homogeneous_cell_returns_the_solid():
    out = homogenise_stiffness(np.zeros((8, 8, 8), np.int32), 0.1, [(200.0, 0.25)])
    np.testing.assert_allclose(out["C"], isotropic_stiffness(200.0, 0.25), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("kind", ["spherical voids", "gyroid sheet"])
def test_porous_cells_lie_within_hashin_shtrikman_bounds(kind):
    """Hashin & Shtrikman (1963): porous bulk and shear moduli below the upper bounds, above zero."""
    n = 16
    if kind == "spherical voids":
        z, y, x = np.mgrid[0:n, 0:n, 0:n] + 0.5 - n / 2
        solid = x * x + y * y + z * z > (0.42 * n) ** 2
        h = 1.0 / n
    else:
        rec = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.6},
               "domain": {"kind": "box", "cells": [1, 1, 1]}}
        solid, h, _ = recipe_cell_voxels(rec, n)
    s = stiffness_properties(solid, h, 100.0, 0.3, directions=200)
    hs = s["hashin_shtrikman"]
    assert 0 < hs["bulk"] <= hs["bulk_upper"]
    assert 0 < hs["shear_voigt"] <= hs["shear_upper"]
    assert hs["within"]
    # cubic symmetry of both cells: E1 = E2 = E3
    e = s["engineering"]
    assert abs(e["E1"] / e["E3"] - 1) < 1e-6 and abs(e["E2"] / e["E3"] - 1) < 1e-6


def test_engineering_constants_and_directional_modulus_of_an_isotropic_solid():
    C = isotropic_stiffness(70.0, 0.33)
    e = engineering_constants(C)
    assert abs(e["E1"] - 70.0) < 1e-9 and abs(e["nu12"] - 0.33) < 1e-12
    assert abs(e["G12"] - 70.0 / 2.66) < 1e-9 and abs(e["zener_ratio"] - 1) < 1e-12
    d = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_allclose(directional_modulus(C, d), 70.0, rtol=1e-12)


def test_directional_modulus_of_a_cubic_crystal():
    """Copper (C11 = 168.4, C12 = 121.4, C44 = 75.4 GPa; Simmons & Wang 1971): E<100> = 66.7, E<111> = 191.1 GPa."""
    C = np.zeros((6, 6))
    C[:3, :3] = 121.4
    C[np.arange(3), np.arange(3)] = 168.4
    C[np.arange(3, 6), np.arange(3, 6)] = 75.4
    e100, e111 = directional_modulus(C, [[1, 0, 0], [1, 1, 1]])
    assert abs(e100 - 66.7) < 0.2 and abs(e111 - 191.1) < 0.3


def test_gibson_ashby_fit_recovers_the_exponent():
    rho = np.array([0.1, 0.2, 0.3, 0.5])
    fit = gibson_ashby_fit(rho, 0.8 * rho ** 2.1)
    assert abs(fit["n"] - 2.1) < 1e-9 and abs(fit["C"] - 0.8) < 1e-9 and fit["r2"] > 0.999999
    with pytest.raises(InputError):
        gibson_ashby_fit([0.3], [0.1])


def test_hashin_shtrikman_bound_of_a_full_solid_is_the_solid():
    hs = hashin_shtrikman_upper(10.0, 0.3, 1.0)
    assert abs(hs["young_upper"] - 10.0) < 1e-9


@pytest.mark.parametrize("E,nu,match", [(0.0, 0.3, "Young"), (-5, 0.3, "Young"), (1.0, 0.5, "Poisson"),
                                        (1.0, -1.0, "Poisson"), (float("nan"), 0.3, "Young")])
def test_non_physical_moduli_are_refused(E, nu, match):
    with pytest.raises(InputError, match=match):
        homogenise_stiffness(np.zeros((4, 4, 4), np.int32), 0.1, [(E, nu)])


def test_disconnected_solid_has_no_load_path():
    ph = np.full((8, 8, 8), -1, np.int32)
    ph[2:5, 2:5, 2:5] = 0  # a floating cube
    with pytest.raises(InputError, match="no load path"):
        homogenise_stiffness(ph, 0.1, [(1.0, 0.3)])
    ph = np.full((8, 8, 8), -1, np.int32)
    ph[:, :, 2:4] = 0  # plates normal to x: span y and z, not x
    with pytest.raises(InputError, match="along x"):
        homogenise_stiffness(ph, 0.1, [(1.0, 0.3)])


def test_floating_pieces_are_removed_and_reported():
    ph = np.full((8, 8, 8), -1, np.int32)
    ph[:, 3:5, :] = 0  # a slab spanning x and z...
    ph[:, :, 3:5] = 0  # ...and one spanning y and z: together all three
    ph[1, 0, 0] = 0  # a floating voxel (touches the frame only by an edge)
    out = homogenise_stiffness(ph, 0.1, [(1.0, 0.3)])
    assert out["removed_voxels"] == 1


def test_too_large_job_is_refused_up_front_with_the_estimate():
    with pytest.raises(ResourceError, match="GiB"):
        homogenise_stiffness(np.zeros((64, 64, 64), np.int32), 0.1, [(1.0, 0.3)], memory_limit=200 * 2**20)
