"""Regression targets from document 002 (Tables 3, 4, 5) and the TPMS catalogue."""

import numpy as np
import pytest

from porecad.fields import CATALOGUE, TPMSField
from porecad.mesh import Grid, polygonise

# 002 Table 3: (type, C, porosity %)
TABLE3 = [("P", -0.95, 22.79), ("P", -0.5, 35.71), ("P", 0.0, 49.98), ("P", 0.5, 64.28), ("P", 0.95, 77.21),
          ("D", -0.95, 10.28), ("D", -0.5, 29.42), ("D", 0.0, 49.94), ("D", 0.5, 70.57), ("D", 0.95, 89.71),
          ("G", -0.95, 18.77), ("G", -0.5, 33.81), ("G", 0.0, 50.00), ("G", 0.5, 66.19), ("G", 0.95, 81.22)]


@pytest.mark.parametrize("ttype,c,expected", TABLE3)
def test_table3_porosity_within_half_point(run_json, ttype, c, expected):
    r = run_json("tpms", ttype, "--structure", "pore", "--threshold", c, "--cells", 1, 1, 1,
                 "--cell-size", 1, "--resolution", 200)
    assert abs(100 * r["porosity"] - expected) < 0.5
    assert abs(100 * r["porosity_voxel"] - expected) < 0.5
    assert r["closed"] and r["manifold"]


@pytest.mark.parametrize("ttype,expected", [("P", 2.353180), ("D", 3.828864), ("G", 3.083422)])
def test_table4_area_per_volume_within_one_percent(run_json, ttype, expected):
    r = run_json("tpms", ttype, "--structure", "surface", "--threshold", 0, "--cells", 1, 1, 1,
                 "--cell-size", 1, "--resolution", 200)
    assert r["porosity"] is None  # a bare surface has no porosity (the common key is null)
    assert abs(r["area_per_volume"] - expected) / expected < 0.01


@pytest.mark.parametrize("n,expected", [(100, 74216), (200, 299672), (300, 675848), (400, 1203704),
                                        (500, 1882376)])
def test_table5_triangle_counts_within_two_percent(n, expected):
    grid = Grid.from_box([0, 0, 0], [1, 1, 1], samples_per_axis=n)
    res = polygonise(TPMSField("P", 1.0).sample_grid, grid, caps=False)
    assert abs(len(res.faces) - expected) / expected < 0.02


def test_catalogue_has_required_types():
    required = {"P", "D", "D2", "G", "IWP", "FRD", "L", "neovius", "tubular_P", "tubular_G", "I2Y",
                "fischer_koch_s", "split_P"}
    assert required <= set(CATALOGUE)
    for t in CATALOGUE.values():
        assert t.formula and t.source


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_grid_evaluation_matches_pointwise_and_is_periodic(name):
    f = TPMSField(name, cell_size=[1.0, 1.5, 2.0])
    xs, ys, zs = np.linspace(0, 2, 9), np.linspace(0, 3, 7), np.linspace(0, 4, 5)
    grid_vals = f.sample_grid(xs, ys, zs)
    z, y, x = np.meshgrid(zs, ys, xs, indexing="ij")
    pts = np.c_[x.ravel(), y.ravel(), z.ravel()]
    np.testing.assert_allclose(grid_vals.ravel(), f(pts), atol=2e-5 * max(1, np.abs(f(pts)).max()))
    rng = np.random.default_rng(1)
    p = rng.random((20, 3)) * 3
    np.testing.assert_allclose(f(p), f(p + [1.0, 1.5, 2.0]), atol=1e-9)


def test_four_term_d_differs_from_two_term_d():
    """000's two-term D does not reproduce 002 Table 3 (notes section 9.1)."""
    from porecad.calibration import porosity_of_threshold
    assert abs(100 * porosity_of_threshold("D", "pore", -0.95) - 10.28) < 0.1
    assert abs(100 * porosity_of_threshold("D2", "pore", -0.95) - 10.28) > 5
