"""Permeability by a Stokes solve against analytic and published references (issue 23)."""

import numpy as np
import pytest

from porecad.errors import InputError, ResourceError
from porecad.simulate.stokes import DARCY_MM2, stokes_permeability

#: Zick & Homsy, J. Fluid Mech. 115 (1982) 13-26, Table 2, simple cubic array: solid fraction -> drag
#: K = F / (6 pi mu a U) with U the superficial velocity (as tabulated in Basilisk's
#: src/test/spheres.c by S. Popinet).
ZICK_HOMSY_SC = {0.064: 2.810, 0.125: 4.292, 0.343: 15.4}


def test_hagen_poiseuille_channel_within_3_percent():
    """A straight cylindrical channel of radius R in a square cell L: k = pi R^4 / (8 L^2)."""
    L, R = 48, 20.0
    c = (L - 1) / 2
    y, x = np.mgrid[0:L, 0:L]
    disk = (x - c) ** 2 + (y - c) ** 2 <= R * R
    pore = np.repeat(disk[None], 2, axis=0)  # [z, y, x], channel along z
    h = 0.01
    out = stokes_permeability(pore, h, directions=[2])
    k = out["permeability_mm2"][2][2]
    exact = np.pi * (R * h) ** 4 / (8 * (L * h) ** 2)
    assert abs(k / exact - 1) < 0.03
    assert abs(out["permeability_darcy"][2][2] - k / DARCY_MM2) < 1e-9 * k / DARCY_MM2
    assert abs(out["tortuosity"]["z"] - 1.0) < 1e-6  # straight streamlines
    assert out["percolates"] == {"x": False, "y": False, "z": True}


def test_simple_cubic_spheres_match_zick_homsy_within_5_percent():
    """Drag F = 6 pi mu a K U balances the pressure force G L^3 per cell: k = L^3 / (6 pi a K).

    One solid fraction here (48^3 voxels, about 20 s); bench/simulate.py runs all three at 48^3 and 64^3.
    """
    c = 0.125
    L = 48
    a = L * (3 * c / (4 * np.pi)) ** (1 / 3)
    z, y, x = np.mgrid[0:L, 0:L, 0:L] + 0.5 - L / 2
    solid = x * x + y * y + z * z <= a * a
    out = stokes_permeability(~solid, 1.0, directions=[0])
    k = out["permeability_mm2"][0][0]
    k_ref = L ** 3 / (6 * np.pi * a * ZICK_HOMSY_SC[c])
    assert abs(k / k_ref - 1) < 0.05
    assert out["tortuosity"]["x"] > 1.0


def test_pore_space_that_does_not_percolate_gives_zero_with_a_statement():
    pore = np.zeros((12, 12, 12), bool)
    pore[3:8, 3:8, 3:8] = True  # a closed cavity
    out = stokes_permeability(pore, 0.1)
    assert out["percolates"] == {"x": False, "y": False, "z": False}
    assert np.all(np.array(out["permeability_mm2"]) == 0)
    assert "does not percolate" in out["note"]


def test_partial_percolation_is_labelled_and_closed_pores_removed():
    pore = np.zeros((8, 16, 16), bool)
    pore[:, 6:10, 6:10] = True  # a duct along z
    pore[:, 1:3, 1:3] = False
    pore[2:4, 12:14, 12:14] = True  # a closed pore
    out = stokes_permeability(pore, 0.1)
    k = np.array(out["permeability_mm2"])
    assert k[2, 2] > 0 and k[0, 0] == 0 and k[1, 1] == 0
    assert out["closed_pore_voxels"] == 8
    assert "along x, y" in out["note"]


def test_bad_input_and_too_large_jobs():
    with pytest.raises(InputError, match="no solid"):
        stokes_permeability(np.ones((4, 4, 4), bool), 0.1)
    with pytest.raises(InputError, match="voxel"):
        stokes_permeability(np.zeros((4, 4, 4), bool), -1.0)
    with pytest.raises(ResourceError, match="GiB"):
        stokes_permeability(np.ones((64, 64, 64), bool), 0.1, memory_limit=100 * 2**20)
