"""Porosity held in any body (issue 20, item 6): the threshold calibrated on the body's own samples.

Every achieved porosity here is measured independently of the job's report: ``1 − V(solid) / V(body)``
from the written mesh and the body mesh (trimesh volumes), or by classifying random points.
"""

import numpy as np
import pytest
import trimesh

from porecad.bodies import MeshBody
from porecad.bodies import body_porosity as bp
from porecad.calibration import porosity_of_threshold, threshold_for_porosity, valid_range
from porecad.io import read_mesh, write_mesh


def _capsule(tmp_path, radius, height, name="rod.stl", shift=(1.3, 0.7, 0.0)):
    m = trimesh.creation.capsule(height=height, radius=radius, count=[24, 24])
    m.apply_translation(shift)
    path = tmp_path / name
    write_mesh(path, np.asarray(m.vertices), np.asarray(m.faces))
    return path, abs(m.volume)


def _measured(out, body_volume):
    v, f = read_mesh(out)
    return 1.0 - abs(trimesh.Trimesh(v, f, process=False).volume) / body_volume


def test_calibration_grid_is_incommensurate_with_the_cell():
    """The samples modulo the cell spread over the whole cell (a spacing dividing the cell would not)."""
    xs, ys, zs = bp.sample_axes([0, 0, 0], [40, 40, 40], [4.0, 4.0, 4.0], volume=64000.0, target_inside=200_000)
    for ax in (xs, ys, zs):
        step = ax[1] - ax[0]
        assert np.allclose(np.diff(ax), step)
        frac = np.sort((ax % 4.0) / 4.0)
        assert np.max(np.diff(frac)) < 3.0 / len(ax)  # equidistributed: no gap of a few spacings' worth
        assert abs(4.0 / step - round(4.0 / step)) > 0.2
    assert len(xs) * len(ys) * len(zs) == pytest.approx(200_000, rel=0.3)
    # never finer than asked (half the job's voxel)
    xs, _, _ = bp.sample_axes([0, 0, 0], [10, 10, 10], [4.0, 4.0, 4.0], volume=1000.0, min_spacing=0.5)
    assert xs[1] - xs[0] >= 0.5


@pytest.mark.parametrize("structure", ["pore", "rod", "sheet"])
def test_structure_key_orders_void(structure):
    phi = np.linspace(-1.5, 1.5, 1001).astype(np.float32)
    c = 0.4 if structure == "sheet" else 0.2
    from porecad.solids import StructureField
    from porecad.fields.base import Constant

    class Values:  # a "field" returning the given values
        def sample_grid(self, xs, ys, zs):
            return phi.reshape(1, 1, -1).copy()

    void = StructureField(Values(), structure, Constant(c)).sample_grid([0] * len(phi), [0], [0]).ravel() > 0
    key = bp.structure_key(phi, structure)
    kc = c if structure == "pore" else -c
    assert np.array_equal(void, key < kc)
    assert bp.key_threshold(kc, structure) == pytest.approx(c)


def test_whole_cells_give_the_whole_cell_curve(tmp_path):
    """In a body that is a box of whole cells, the body calibration is the whole-cell calibration."""
    from porecad.lattice.plan import hold_porosity, plan_lattice
    from porecad.jobs.runner import parse
    box = trimesh.creation.box(extents=(12.0, 12.0, 12.0))
    path = tmp_path / "box.stl"
    write_mesh(path, np.asarray(box.vertices) + 6.0, np.asarray(box.faces))
    _, spec, _, _ = parse({"job": "infill", "tpms": {"type": "G", "structure": "pore", "porosity": 0.6,
                                                        "cell_size": 4.0},
                           "domain": {"kind": "mesh", "path": str(path)}, "sampling": {"voxel": 0.2}})
    plan = plan_lattice(spec)
    hold_porosity(plan)
    cal = plan.threshold_info["calibration"]
    # the samples are solved for the target less the lattice's mesh bias at this voxel (20 samples per cell)
    assert 0 <= cal["mesh_bias"] < 0.004
    target = 0.6 - cal["mesh_bias"]
    assert abs(cal["lattice_porosity"] - target) < 0.005
    assert abs(plan.threshold_info["threshold"] - threshold_for_porosity("G", "pore", target)) < 0.02
    assert abs(cal["sample_porosity"] - target) < 1e-3 and cal["samples"] > 100_000


def test_thin_rod_holds_porosity_where_whole_cells_miss(tmp_path, run_json):
    """A rod of radius a quarter cell: the whole-cell threshold misses 0.6 by far; the calibrated one holds it."""
    body, vol = _capsule(tmp_path, radius=2.5, height=25.0)
    rep = run_json("infill", body, "G", "--structure", "pore", "--porosity", 0.6, "-L", 10, "--voxel", 0.25,
                   "-o", tmp_path / "cal.stl")
    assert rep["closed"] and rep["manifold"]
    achieved = _measured(tmp_path / "cal.stl", vol)
    assert abs(achieved - 0.6) < 0.01
    assert rep["porosity"] == pytest.approx(achieved, abs=1e-3)
    assert rep["target_porosity"] == 0.6 and rep["calibration"]["requested"] == 0.6
    # the same lattice at the whole-cell threshold: far off
    c0 = rep["threshold_cells"]
    assert c0 == pytest.approx(threshold_for_porosity("G", "pore", 0.6))
    run_json("infill", body, "G", "--structure", "pore", "--threshold", c0, "-L", 10, "--voxel", 0.25,
             "-o", tmp_path / "cells.stl")
    assert abs(_measured(tmp_path / "cells.stl", vol) - 0.6) > 0.05
    # the lattice itself had to be more open than 0.6 to make the rod 0.6
    assert abs(rep["calibration"]["lattice_porosity"] - 0.6) > 0.05


@pytest.mark.parametrize("structure", ["pore", "sheet"])
def test_skin_counts_in_the_porosity(tmp_path, run_json, structure):
    """With a solid skin the body's porosity (skin included) is the one asked for."""
    body, vol = _capsule(tmp_path, radius=6.0, height=12.0, name="cap.stl")
    out = tmp_path / f"skin-{structure}.stl"
    rep = run_json("infill", body, "G", "--structure", structure, "--porosity", 0.6, "-L", 4, "--voxel", 0.2,
                   "--boundary", "skin", "--skin", 0.8, "-o", out)
    assert rep["closed"] and rep["manifold"]
    assert abs(_measured(out, vol) - 0.6) < 0.01
    cal = rep["calibration"]
    assert 0.5 < cal["core_fraction"] < 0.9        # the skin holds a good part of the body
    assert cal["lattice_porosity"] > 0.65           # so the lattice inside it is more open


def test_skin_too_thick_for_the_porosity_builds_the_nearest_and_says_so(tmp_path, run_cli):
    """A skin that leaves too little room: the most open valid lattice, requested and achieved reported."""
    import json
    body, vol = _capsule(tmp_path, radius=3.0, height=10.0, name="thin.stl")
    out = tmp_path / "x.stl"
    code, stdout, err = run_cli("infill", body, "G", "--porosity", 0.7, "-L", 4, "--voxel", 0.25, "--boundary",
                                "skin", "--skin", 1.4, "-o", out, "--json")
    assert code == 0, err
    rep = json.loads(stdout)
    assert rep["in_valid_range"] and "porecad: warning:" in err and "thinner skin" in err
    lo, hi = valid_range("G", rep["structure"])["porosity"]
    assert rep["calibration"]["lattice_porosity"] == pytest.approx(hi, abs=2e-3)  # the most open valid lattice
    assert rep["target_porosity"] == 0.7
    assert rep["porosity"] < 0.6 and rep["porosity"] == pytest.approx(_measured(out, vol), abs=2e-3)


def test_graded_porosity_per_shell_in_a_skinned_body(tmp_path, run_json):
    """A porosity graded with depth, in a body with a solid skin: each depth shell within 2 points.

    Checked by random points classified by their exact depth (MeshBody with a band past the deepest point)
    and by the written solid's winding number, not by the job's own region report.
    """
    body, vol = _capsule(tmp_path, radius=7.0, height=16.0, name="graded.stl")
    out = tmp_path / "graded-out.stl"
    rep = run_json("infill", body, "G", "--structure", "pore", "--porosity", "0.45 + 0.3 * dn", "-L", 4,
                   "--voxel", 0.2, "--boundary", "skin", "--skin", 0.4, "-o", out)
    assert rep["closed"] and rep["manifold"] and rep["calibration"]["converged"]
    for region in rep["regions"]["shells"] + rep["regions"]["slabs"]:
        assert abs(region["achieved"] - region["requested"]) < 0.02
    dmax = rep["regions"]["max_depth"]
    vb, fb = read_mesh(body)
    rng = np.random.default_rng(3)
    pts = rng.uniform(vb.min(0), vb.max(0), (400_000, 3))
    mb = MeshBody(vb, fb, band=dmax + 1.0)
    pts = pts[mb.winding(pts) > 0.5]
    depth = -mb(pts)
    vo, fo = read_mesh(out)
    void = MeshBody(vo, fo, band=1.0).winding(pts) < 0.5
    target = 0.45 + 0.3 * np.clip(depth / dmax, 0, 1)
    edges = np.linspace(0.0, dmax, 6)
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (depth >= a) & (depth < b)
        assert sel.sum() > 2000
        assert abs(void[sel].mean() - target[sel].mean()) < 0.02, (a, b)
    # the outer shell is largely skin: its lattice had to be much more open than asked
    assert rep["calibration"]["shell_correction"][0] > 0.1
    assert abs(_measured(out, vol) - target.mean()) < 0.015


def test_whole_cell_curve_is_untouched_in_whole_mode(tmp_path, run_json):
    """``whole`` keeps complete cells, where the whole-cell curve is exact: no body calibration."""
    body, _ = _capsule(tmp_path, radius=7.0, height=16.0, name="whole.stl")
    rep = run_json("infill", body, "G", "--porosity", 0.6, "-L", 4, "--voxel", 0.25, "--boundary", "whole",
                   "-o", tmp_path / "w.stl")
    assert "calibration" not in rep
    assert rep["threshold"] == pytest.approx(threshold_for_porosity("G", rep["structure"], 0.6))
    assert abs(rep["porosity_cells"] - 0.6) < 0.01
    assert porosity_of_threshold("G", rep["structure"], rep["threshold"]) == pytest.approx(0.6, abs=1e-3)
