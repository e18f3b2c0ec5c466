"""Grading (issue 3 item 4) and the per-region report (item 5)."""

import json

import numpy as np
import pytest
import SimpleITK as sitk
import trimesh

from porecad.bodies.distance import BodyDepth
from porecad.bodies.mesh import MeshBody
from porecad.fields.graded_cell import GradedCellTPMS
from porecad.fields.gridded import GriddedField
from porecad.grading import ImageMapField, ThinPlateField
from porecad.pipeline import run_recipe


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    p = tmp_path_factory.mktemp("ball") / "ball.stl"
    trimesh.creation.icosphere(subdivisions=5, radius=10.0).export(p)
    return p


def test_depth_of_a_sphere():
    m = trimesh.creation.icosphere(subdivisions=5, radius=10.0)
    depth = BodyDepth(MeshBody(m.vertices, m.faces, band=0.5), 0.5)
    p = np.random.default_rng(0).uniform(-11, 11, (20000, 3))
    r = np.linalg.norm(p, axis=1)
    err = np.abs(depth(p) - (10.0 - r))
    assert err[r > 2].max() < 0.1          # exact up to trilinear interpolation of a smooth function
    assert abs(depth.max_depth - 10.0) < 0.1


def test_gridded_field_grid_matches_points():
    rng = np.random.default_rng(3)
    g = GriddedField(rng.random((5, 6, 7)), (1.0, -2.0, 0.5), (0.5, 0.4, 0.3))
    xs, ys, zs = np.linspace(0.8, 4.5, 9), np.linspace(-2.2, 0.3, 8), np.linspace(0.4, 2.0, 7)
    grid = g.sample_grid(xs, ys, zs)
    pts = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), -1).reshape(-1, 3)
    ref = g(pts).reshape(len(xs), len(ys), len(zs)).transpose(2, 1, 0)
    assert np.allclose(grid, ref, atol=1e-6)


def test_thin_plate_reproduces_linear_and_clamps():
    rng = np.random.default_rng(1)
    p = rng.uniform(-10, 10, (12, 3))
    val = 0.6 + 0.01 * p[:, 2]
    f = ThinPlateField(p, val)
    q = rng.uniform(-5, 5, (200, 3))
    assert np.allclose(f(q), np.clip(0.6 + 0.01 * q[:, 2], val.min(), val.max()), atol=1e-6)
    assert f(np.array([[0.0, 0.0, 1e4]]))[0] == pytest.approx(val.max())


def test_image_map_in_physical_coordinates(tmp_path):
    arr = np.zeros((10, 12, 8), dtype=np.float32)
    arr[:] = 0.5 + 0.02 * np.arange(8)[None, None, :]          # grows with the k index
    img = sitk.GetImageFromArray(arr.transpose(2, 1, 0).copy())
    img.SetSpacing((1.0, 1.0, 2.0))
    img.SetOrigin((-5.0, -6.0, -8.0))
    p = tmp_path / "map.nrrd"
    sitk.WriteImage(img, str(p))
    f = ImageMapField(p, scale=2.0, offset=-0.5)
    z = np.array([-8.0, -5.0, 0.0, 6.0])
    pts = np.stack([np.zeros(4), np.zeros(4), z], axis=1)
    k = (z + 8.0) / 2.0
    assert np.allclose(f(pts), -0.5 + 2.0 * (0.5 + 0.02 * k), atol=1e-6)


def test_graded_cell_phase_is_the_integral_of_the_frequency():
    g = GradedCellTPMS("G", 2.0, 4.0, axis="z", start=0.0, end=20.0)
    s = np.linspace(-5, 25, 3001)
    dpsi = np.gradient(g.phase(s), s)
    assert np.allclose(dpsi, 1.0 / g.cell_size_at(s), rtol=2e-3)
    # phase and field are continuous across the ramp ends
    for s0 in (0.0, 20.0):
        a, b = g.phase(np.array([s0 - 1e-7, s0 + 1e-7]))
        assert abs(a - b) < 1e-6
    assert g.phase(np.array([20.0]))[0] == pytest.approx(np.log(2.0) / 0.1)


def _recipe(body, grading=None, tpms=None, **extra):
    rec = {"job": "tpms", "tpms": {"type": "G", "structure": "pore", "cell_size": 2.5, **(tpms or {})},
           "domain": {"kind": "mesh", "path": str(body)}, "sampling": {"voxel": 0.2}}
    if grading:
        rec["grading"] = grading
    rec.update(extra)
    return rec


def test_distance_grading_by_shell(ball):
    """Yoo's distance grading on a ball: porosity 0.5 at the surface to 0.8 at the centre, per shell."""
    rep = run_recipe(_recipe(ball, {"kind": "distance", "of": "porosity", "from": 0.5, "to": 0.8}))
    shells = rep["regions"]["shells"]
    assert len(shells) == 5 and rep["closed"]
    req = [s["requested"] for s in shells]
    assert req == sorted(req) and req[0] < 0.58 and req[-1] > 0.72
    for s in shells[:-1]:  # the central shell holds few cells
        assert abs(s["achieved"] - s["requested"]) < 0.02
    assert abs(shells[-1]["achieved"] - shells[-1]["requested"]) < 0.04


def test_expression_grading_and_slabs(ball):
    rep = run_recipe(_recipe(ball, {"kind": "expression", "of": "porosity", "expr": "0.6 + 0.01 * z"},
                             analysis={"regions": 4, "region_axis": "z"}))
    slabs = rep["regions"]["slabs"]
    assert rep["regions"]["axis"] == "z" and len(slabs) == 4
    for s in slabs:
        mid = 0.5 * (s["from"] + s["to"])
        assert abs(s["requested"] - (0.6 + 0.01 * mid)) < 0.02
        assert abs(s["achieved"] - s["requested"]) < 0.02


def test_points_and_map_grading_cli(ball, tmp_path, run_json):
    pts = tmp_path / "pts.csv"
    pts.write_text("x,y,z,porosity\n" + "\n".join(
        f"{x},{y},{z},{0.65 + 0.01 * z}" for x in (-10, 10) for y in (-10, 10) for z in (-10, 10)))
    rep = run_json("infill", ball, "G", "--porosity-points", pts, "-L", "2.5", "--voxel", "0.25",
                   "--region-axis", "z", "-o", tmp_path / "pts.stl")
    slabs = rep["regions"]["slabs"]
    assert slabs[0]["requested"] < slabs[-1]["requested"]
    assert all(abs(s["achieved"] - s["requested"]) < 0.025 for s in slabs)
    img = sitk.GetImageFromArray(np.full((4, 4, 4), 70, dtype=np.uint8))
    img.SetSpacing((10.0, 10.0, 10.0))
    img.SetOrigin((-15.0, -15.0, -15.0))
    sitk.WriteImage(img, str(tmp_path / "map.nrrd"))
    rep = run_json("infill", ball, "G", "--porosity-map", tmp_path / "map.nrrd", "--map-scale", "0.01",
                   "-L", "2.5", "--voxel", "0.25", "-o", tmp_path / "map.stl")
    assert abs(rep["porosity"] - 0.70) < 0.02 and rep["porosity_min"] == pytest.approx(0.7)


def test_cell_size_ramp_cli(tmp_path, run_json, run_cli):
    body = tmp_path / "rod.stl"
    trimesh.creation.capsule(height=30.0, radius=6.0, count=[32, 32]).export(body)
    rep = run_json("infill", body, "G", "--porosity", "0.7", "--cell-size-ramp", "2", "4", "--voxel", "0.2",
                   "-o", tmp_path / "ramp.stl")
    assert rep["closed"] and rep["manifold"] and rep["cell_size_grading"]["L0"] == 2.0
    # the local porosity stays the target: volume fractions are affine-invariant
    assert abs(rep["porosity"] - 0.7) < 0.02
    assert all(abs(s["achieved"] - 0.7) < 0.03 for s in rep["regions"]["slabs"])
    code, _, err = run_cli("infill", body, "G", "--porosity", "0.7", "--cell-size-ramp", "2", "4",
                           "--boundary", "whole", "-o", tmp_path / "w.stl")
    assert code == 2 and "give one cell size" in err


@pytest.mark.parametrize("args, message", [
    (["tpms", "G", "--porosity", "0.5 + 0.1 * d", "-o", "{out}"], "d and dn need a body"),
    (["tpms", "G", "--porosity", "0.5 + ", "-o", "{out}"], "grading expression is not valid"),
    (["tpms", "G", "--porosity", "__import__('os')", "-o", "{out}"], "unknown name"),
    (["infill", "{ball}", "G", "--porosity", "0.5 + 0.6 * dn", "-o", "{out}"], "porosity"),
    (["infill", "{ball}", "G", "--porosity-points", "{missing}", "-o", "{out}"], "no such file"),
    (["infill", "{ball}", "G", "--porosity", "0.6", "--threshold", "0.1", "-o", "{out}"], "not several"),
])
def test_grading_errors_are_one_line(ball, tmp_path, run_cli, args, message):
    out = tmp_path / "x.stl"
    subst = {"{out}": str(out), "{ball}": str(ball), "{missing}": str(tmp_path / "none.csv")}
    code, _, err = run_cli(*[subst.get(a, a) for a in args])
    assert code != 0 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_coarse_voxel_for_thin_walls_warns(ball, tmp_path, run_cli):
    """A sheet thinner than the voxel loses volume in the mesh: the user is told, not left guessing."""
    code, out, err = run_cli("infill", ball, "D", "--structure", "sheet", "--porosity", "0.75", "-L", "5",
                             "--voxel", "0.7", "-o", tmp_path / "thin.stl", "--json")
    rep = json.loads(out)
    assert code == 0 and abs(rep["porosity"] - rep["porosity_voxel"]) > 0.02
    assert "porecad: warning: the voxel is coarse" in err and rep["warnings"]
    coarse = [w for w in rep["warning_details"] if w["code"] == "voxel-coarse"]  # structured: code and numbers
    assert len(coarse) == 1 and abs(coarse[0]["values"]["porosity_mesh"] - coarse[0]["values"]["porosity_samples"]) > 0.02
    assert coarse[0]["values"]["porosity_samples"] == rep["porosity_voxel"]
    code, out, err = run_cli("infill", ball, "D", "--structure", "sheet", "--porosity", "0.75", "-L", "5",
                             "--voxel", "0.2", "-o", tmp_path / "fine.stl", "--json")
    rep = json.loads(out)
    assert code == 0 and not rep["warnings"] and "warning" not in err
