"""Scaffold analysis (issue 8): pore/strut sizes, interconnectivity, curvature, report directory."""

import json

import manifold3d as m3
import numpy as np
import pytest
import trimesh

from porecad.analysis.curvature import curvature_stats, vertex_curvatures
from porecad.analysis.thickness import local_thickness


@pytest.fixture(scope="module")
def channel_cube(tmp_path_factory):
    """10 mm cube, a 3x3 grid of 2 mm through-channels along z and one closed 2 mm spherical void."""
    solid = m3.Manifold.cube([10, 10, 10])
    for cx in (10 / 6, 5, 50 / 6):
        for cy in (10 / 6, 5, 50 / 6):
            solid = solid - m3.Manifold.cylinder(14, 1.0, 1.0, 64).translate([cx, cy, -2])
    solid = solid - m3.Manifold.sphere(1.0, 64).translate([10 / 3, 10 / 3, 5.0])
    mesh = solid.to_mesh()
    p = tmp_path_factory.mktemp("cube") / "channels.stl"
    trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts)).export(p)
    return p


def test_known_geometry_pores(channel_cube, run_json):
    """Acceptance 1: pore_size_mean within 0.2 mm of 2, closed_pores = 1."""
    rep = run_json("analyze", channel_cube, "--pores", "--voxel", "0.1")
    for key in ("pore_size_mean", "pore_size_d50", "strut_size_mean", "open_pore_fraction", "closed_pores"):
        assert key in rep
    assert abs(rep["pore_size_mean"] - 2.0) < 0.2
    assert rep["closed_pores"] == 1
    assert abs(rep["closed_pore_volume"] - 4.0 / 3.0 * np.pi) < 0.3
    channels = 9 * np.pi * 10.0
    assert abs(rep["open_pore_fraction"] - channels / (channels + 4.0 / 3.0 * np.pi)) < 0.005
    assert rep["percolation"] == {"x": False, "y": False, "z": True}
    assert rep["permeability_kozeny_carman_mm2"] > 0 and "estimate" in rep["permeability_note"]


def test_local_thickness_of_a_slab_and_a_ball():
    h = 0.05
    z = np.arange(-30, 31) * h
    slab = np.broadcast_to((np.abs(z) <= 0.5)[:, None, None], (61, 40, 40)).copy()  # 1 mm thick (21 voxels)
    dist = np.broadcast_to((0.5 + 0.5 * h - np.abs(z))[:, None, None], slab.shape)
    lt = local_thickness(slab, h, dist)
    assert np.allclose(lt[slab], 1.0 + h, atol=1e-6)
    g = np.arange(-25, 26) * h
    r = np.sqrt(g[:, None, None] ** 2 + g[None, :, None] ** 2 + g[None, None, :] ** 2)
    ball = r <= 1.0
    lt = local_thickness(ball, h)   # EDT distances
    assert abs(np.median(lt[ball]) - 2.0) < 2 * h


@pytest.mark.parametrize("ttype, structure", [("G", "sheet"), ("P", "pore"), ("D", "rod")])
def test_valid_range_tpms_is_fully_open(tmp_path, run_json, ttype, structure):
    """Acceptance 3: valid-range scaffolds are 100 % open and percolate along x, y and z."""
    out = tmp_path / "s.stl"
    run_json("tpms", ttype, "--structure", structure, "--porosity", "0.6", "--cells", "2", "2", "2",
             "--cell-size", "2", "--resolution", "24", "-o", out)
    rep = run_json("analyze", out, "--pores", "--voxel", "0.05")
    assert rep["open_pore_fraction"] > 0.999 and rep["closed_pores"] == 0
    assert rep["percolation"] == {"x": True, "y": True, "z": True}
    assert rep["solid_percolation"] == {"x": True, "y": True, "z": True}
    assert abs(rep["porosity_voxel"] - 0.6) < 0.02


def test_outside_valid_range_reports_closed_pores(tmp_path, run_json):
    out = tmp_path / "neovius.stl"
    run_json("tpms", "neovius", "--structure", "sheet", "--porosity", "0.6", "--cells", "2", "2", "2",
             "--cell-size", "2", "--resolution", "32", "--allow-closed-pores", "-o", out)
    rep = run_json("analyze", out, "--pores", "--voxel", "0.04")
    assert rep["closed_pores"] > 0 and rep["open_pore_fraction"] < 0.95


def test_curvature_of_sphere_torus_and_gyroid(tmp_path, run_json):
    s = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    H, K, A = vertex_curvatures(s.vertices, s.faces)
    assert abs(curvature_stats(H, A)["mean"] - 0.5) < 1e-3 and abs(curvature_stats(K, A)["mean"] - 0.25) < 2e-3
    t = trimesh.creation.torus(major_radius=3.0, minor_radius=1.0, major_sections=96, minor_sections=48)
    H, K, A = vertex_curvatures(t.vertices, t.faces)
    assert abs(curvature_stats(H, A)["mean"] - 0.5) < 5e-3   # ∫H dA / A = 1 / (2 r)
    assert abs((K * A).sum()) < 1e-6                          # Gauss-Bonnet: genus 1
    # 002 Table 2: TPMS curvature distributions are symmetric with mean near 0
    out = tmp_path / "g.stl"
    run_json("tpms", "G", "--structure", "surface", "--threshold", "0", "--cells", "2", "2", "2",
             "--resolution", "40", "-o", out)
    rep = run_json("analyze", out)
    mc = rep["mean_curvature"]
    assert abs(mc["mean"]) < 0.05 * mc["std"] + 1e-3 and abs(mc["median"]) < 0.1 * mc["std"] + 1e-3
    assert abs(mc["max"] + mc["min"]) < 0.25 * (mc["max"] - mc["min"])


def test_report_directory(channel_cube, tmp_path, run_cli):
    d = tmp_path / "report"
    code, out, err = run_cli("analyze", channel_cube, "--pores", "--voxel", "0.2", "--min-feature", "0.5",
                             "--report", d, "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert rep["thin_struts"]["regions"] >= 1 and rep["thin_struts"]["locations"]
    html = (d / "report.html").read_text(encoding="utf-8")
    for png in ("pore_sizes.png", "strut_sizes.png", "curvature.png", "sections.png", "preview.png"):
        data = (d / png).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and f'src="{png}"' in html
    assert json.loads((d / "report.json").read_text(encoding="utf-8"))["closed_pores"] == 1
    code, _, err = run_cli("analyze", channel_cube, "--report", d)
    assert code == 2 and "--force" in err and len(err.strip().splitlines()) == 1


def test_analyze_pores_needs_a_closed_solid(tmp_path, run_cli):
    m = trimesh.creation.box()
    m.faces = m.faces[:-2]
    p = tmp_path / "open.stl"
    m.export(p)
    code, _, err = run_cli("analyze", p, "--pores")
    assert code == 2 and "needs a closed" in err
