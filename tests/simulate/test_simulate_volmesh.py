"""Tetrahedral volume meshes of closed porecad solids; the volmesh and properties commands (issue 23)."""

import json

import meshio
import numpy as np
import pytest

from porecad.errors import MeshError
from porecad.mesh import polygonise
from porecad.mesh.validate import signed_volume
from porecad.pipeline import plan_tpms
from porecad.simulate.mesh_quality import periodic_face_mismatch
from porecad.simulate.tetmesh_solid import periodic_volume_mesh, quadratic_tets, volume_mesh
from porecad.volmesh import tet_quality

pytest.importorskip("tetgen")

GYROID = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.6, "cell_size": 1.0},
          "domain": {"kind": "box", "cells": [1, 1, 1]}, "sampling": {"resolution": 21}}


@pytest.fixture(scope="module")
def gyroid_surface():
    plan = plan_tpms(GYROID)
    res = polygonise(plan.field.sample_grid, plan.grid)
    return res.vertices, res.faces


@pytest.fixture(scope="module")
def gyroid_mesh(gyroid_surface):
    return volume_mesh(*gyroid_surface, order=2)


def test_gyroid_sheet_cell_mesh_is_valid_and_accurate(gyroid_surface, gyroid_mesh):
    v, f = gyroid_surface
    q = gyroid_mesh["quality"]
    assert q["inverted"] == 0 and q["volume_min"] > 0
    assert q["dihedral_deg"]["min"] >= 5.0 and q["below_5deg"] == 0
    assert abs(q["volume"] / signed_volume(v, f) - 1) <= 0.005
    assert sum(q["dihedral_deg"]["histogram"]["counts"]) == 6 * q["tets"]
    # the marching-cubes input really had sliver triangles (that would give sliver tets)
    assert gyroid_mesh["surface"]["min_angle_in_deg"] < 2.0 and gyroid_mesh["surface"]["remeshed"]


@pytest.mark.parametrize("suffix", [".msh", ".vtu", ".inp"])
def test_quadratic_mesh_written_and_loaded_by_meshio(run_cli, tmp_path, gyroid_mesh, suffix):
    from porecad.simulate.tetmesh_solid import write_volume_mesh
    out = write_volume_mesh(tmp_path / f"g{suffix}", gyroid_mesh["points"], gyroid_mesh["cells"], "tetra10")
    m = meshio.read(out)
    t10 = np.concatenate([c.data for c in m.cells if c.type == "tetra10"])
    assert len(t10) == gyroid_mesh["quality"]["tets"]
    # mid-edge nodes sit halfway along their edges (same node order after the round trip)
    p = m.points
    np.testing.assert_allclose(p[t10[:, 4]], 0.5 * (p[t10[:, 0]] + p[t10[:, 1]]), atol=1e-9)
    np.testing.assert_allclose(p[t10[:, 8]], 0.5 * (p[t10[:, 1]] + p[t10[:, 3]]), atol=1e-9)


def test_quadratic_tets_share_edge_nodes():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    p2, t10 = quadratic_tets(pts, tets)
    assert len(p2) == 5 + 9  # 9 distinct edges
    assert set(t10[0, 4:]) & set(t10[1, 4:])  # the shared face's three edges


def test_periodic_cell_mesh_has_matching_opposite_faces():
    plan = plan_tpms(GYROID)
    m = periodic_volume_mesh(plan.field, np.zeros(3), np.ones(3), 1 / 8)
    per = m["periodic"]
    assert per["matched"]
    for a in "xyz":
        assert per[a]["nodes_low"] == per[a]["nodes_high"] > 20
        assert per[a]["max_distance"] <= 1e-9
    assert m["quality"]["inverted"] == 0
    assert abs(m["volume_error"]) <= 0.005


def test_remeshed_periodic_surface_keeps_its_box_faces():
    # at 40 samples per cell the remeshed surface has slivers whose collapse must not move a vertex on a
    # face of the cell (the remesher renumbers vertices: the fixed mask must follow them; bug found by
    # bench/simulate.py fecheck, mismatch 0.006-0.025 mm)
    from porecad.simulate.surface_prep import box_face_vertices, periodic_cell_surface, remesh_surface
    lo, hi = np.zeros(3), np.ones(3)
    v, f = periodic_cell_surface(plan_tpms(GYROID).field, lo, hi, 40)
    v2, f2, info = remesh_surface(v, f, size=0.05, fixed=box_face_vertices(v, lo, hi))
    assert info["sliver_triangles"]["collapsed"] + info["sliver_triangles"]["flipped"] > 0
    per = periodic_face_mismatch(v2, lo, hi)
    assert per["matched"] and max(per[a]["max_distance"] for a in "xyz") <= 1e-9
    on_faces = v2[box_face_vertices(v2, lo, hi)]
    assert len(on_faces) == box_face_vertices(v, lo, hi).sum()   # the fixed vertices, no more, no fewer


def test_periodic_mismatch_is_detected():
    p = np.array([[0, 0.2, 0.3], [1, 0.2, 0.3], [0.5, 0, 0.5], [0.5, 1, 0.5001], [0.2, 0.3, 0], [0.2, 0.3, 1]])
    rep = periodic_face_mismatch(p, np.zeros(3), np.ones(3))
    assert not rep["matched"] and rep["y"]["max_distance"] > 1e-5 and rep["x"]["max_distance"] == 0


def test_quality_of_a_regular_tet():
    s = np.sqrt(2.0)
    p = np.array([[1, 0, -1 / s], [-1, 0, -1 / s], [0, 1, 1 / s], [0, -1, 1 / s]])
    q = tet_quality(p, [[0, 1, 2, 3]])
    assert abs(q["dihedral_deg"]["min"] - 70.5288) < 1e-3 and abs(q["radius_ratio"]["min"] - 1) < 1e-9
    assert abs(q["aspect_ratio"]["max"] - 1) < 1e-9


def test_too_fine_a_mesh_is_refused_up_front():
    import trimesh
    from porecad.errors import ResourceError
    s = trimesh.creation.icosphere(2, radius=10.0)
    with pytest.raises(ResourceError, match="larger element size"):
        volume_mesh(s.vertices, s.faces, size=0.01)


def test_default_size_of_a_fine_surface_keeps_to_the_tet_budget():
    """Issue 42: no size on a finely sampled solid (its mean edge would mean millions of tets): a budget size."""
    import trimesh
    from porecad.simulate.tetmesh_solid import DEFAULT_TETS
    s = trimesh.creation.icosphere(5)  # mean edge 0.03: about 6 M tets at the old default
    m = volume_mesh(s.vertices, s.faces)
    assert DEFAULT_TETS / 4 < len(m["tets"]) < 2 * DEFAULT_TETS
    assert abs(m["volume_error"]) < 0.005


def test_open_mesh_is_refused():
    import trimesh
    s = trimesh.creation.icosphere(2)
    with pytest.raises(MeshError, match="open"):
        volume_mesh(s.vertices, s.faces[:-3])


def test_volmesh_cli_on_a_recipe_periodic_and_not(run_cli, run_json, tmp_path):
    rec = tmp_path / "g.json"
    rec.write_text(json.dumps(GYROID))
    out = tmp_path / "cell.inp"
    r = run_json("volmesh", rec, "-o", out, "--periodic", "--size", 0.125, "--order", 2)
    assert r["element"] == "C3D10" and r["periodic"]["matched"]
    assert meshio.read(out).cells[0].type == "tetra10"
    code, _, err = run_cli("volmesh", rec, "-o", out, "--periodic")
    assert code != 0 and "already exists" in err and len(err.strip().splitlines()) == 1


def test_bad_input_gives_one_line_errors_and_no_files(one_line_error, tmp_path):
    import trimesh
    s = trimesh.creation.icosphere(2)
    opened = trimesh.Trimesh(s.vertices, s.faces[:-2], process=False)
    path = tmp_path / "open.stl"
    opened.export(path)
    one_line_error("volmesh", path, "-o", tmp_path / "o.msh", match="")
    assert not (tmp_path / "o.msh").exists()
    one_line_error("volmesh", path, "-o", tmp_path / "o.stl", match="unsupported volume mesh format")
    rec = tmp_path / "g.json"
    rec.write_text(json.dumps(GYROID))
    one_line_error("volmesh", rec, "-o", tmp_path / "o.mesh", "--order", 2, match="linear tets only")
    one_line_error("properties", rec, "--E", -1, match="Young's modulus")
    one_line_error("properties", rec, "--nu", 0.5, match="Poisson ratio")
    one_line_error("properties", rec, "--voxels", 100000, match="voxels")
    one_line_error("properties", tmp_path / "missing.stl", match="no such file")
    # a disconnected solid: two spheres in opposite corners of their bounding box (the cell)
    a = trimesh.creation.icosphere(2, radius=0.3).apply_translation([0.3, 0.3, 0.3])
    b = trimesh.creation.icosphere(2, radius=0.3).apply_translation([1.7, 1.7, 1.7])
    spheres = tmp_path / "spheres.stl"
    trimesh.util.concatenate([a, b]).export(spheres)
    one_line_error("properties", spheres, "--stiffness", "--voxels", 12, match="no load path")


def test_properties_cli_reports_stiffness_and_permeability(run_json, tmp_path):
    rec = tmp_path / "g.json"
    rec.write_text(json.dumps(GYROID))
    r = run_json("properties", rec, "--voxels", 16, "--E", 1000, "--nu", 0.3, "--report", tmp_path / "p.json")
    s, p = r["stiffness"], r["permeability"]
    assert 0 < s["engineering"]["E1"] < 1000 and s["hashin_shtrikman"]["within"]
    assert s["directional_modulus"]["E_max"] >= s["directional_modulus"]["E_min"] > 0
    k = np.array(p["permeability_mm2"])
    assert k[0, 0] > 0 and abs(k[0, 0] / k[2, 2] - 1) < 1e-6  # cubic symmetry of the gyroid
    assert p["kozeny_carman_mm2"] > 0 and all(t > 1 for t in p["tortuosity"].values())
    assert json.loads((tmp_path / "p.json").read_text())["stiffness"]["C_MPa"] == s["C_MPa"]


def test_properties_html_report_has_the_mechanics_and_flow_section(run_json, tmp_path):
    import re
    rec = tmp_path / "g.json"
    rec.write_text(json.dumps(GYROID))
    page = tmp_path / "mech.html"
    r = run_json("properties", rec, "--voxels", 12, "--E", 1000, "--report", page)
    text = page.read_text(encoding="utf-8")
    assert "Mechanics and flow" in text and "Hashin" in text and "Kozeny" in text
    c11 = r["stiffness"]["C_MPa"][0][0]
    assert f"{c11:.4g}" in text                                   # the tensor itself
    assert f"{r['permeability']['permeability_mm2'][0][0]:.4g}" in text
    assert len(re.findall(r'src="data:image/png;base64,', text)) == 1   # the directional-modulus map
    assert "http" not in text                                     # nothing fetched
    # a sweep: its table, fit and plot; the API writes the same page
    import porecad as pc
    out = pc.properties(GYROID, stiffness=False, permeability=False, voxels=10, sweep=[0.5, 0.7],
                        report=tmp_path / "sweep.html")
    text = (tmp_path / "sweep.html").read_text(encoding="utf-8")
    assert "Gibson" in text and f"{out['sweep']['fit']['n']:.3f}" in text
    assert text.count("data:image/png") == 1
    with pytest.raises(pc.OutputError):
        pc.properties(GYROID, stiffness=False, voxels=10, report=tmp_path / "sweep.html")


def test_sliver_triangles_collapsed_and_flipped_keeping_the_solid():
    """Marching cubes of a sphere sampled so that the level set passes near samples: needles and caps
    are removed, the surface stays closed, manifold and free of self-intersections, volume kept."""
    from porecad.mesh.validate import check_solid
    from porecad.mesh.polygonise import Grid
    from porecad.simulate.surface_slivers import remove_sliver_triangles

    grid = Grid.from_box(np.full(3, -1.0), np.full(3, 1.0), samples_per_axis=np.array([23, 23, 23]))

    def sphere(x, y, z):
        X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
        return (np.sqrt(X ** 2 + Y ** 2 + Z ** 2) - 0.7001).transpose(2, 1, 0).astype(np.float32)

    res = polygonise(lambda xs, ys, zs: sphere(xs, ys, zs), grid)
    v, f = np.asarray(res.vertices, float), np.asarray(res.faces, np.int64)
    v2, f2, info = remove_sliver_triangles(v, f, min_angle=10.0)
    assert info["min_angle_in_deg"] < 2.0  # the input really has slivers
    assert info["collapsed"] > 0 and info["min_angle_deg"] > 3 * info["min_angle_in_deg"]
    chk = check_solid(v2, f2, check_self_intersections=True)
    assert chk["closed"] and chk["manifold"] and chk["oriented"] and chk["self_intersections"] == 0
    assert abs(chk["volume"] / signed_volume(v, f) - 1) < 2e-3
    # fixed vertices never move
    fixed = v[:, 0] > 0.3
    v3, f3, _ = remove_sliver_triangles(v, f, min_angle=10.0, fixed=fixed)
    kept = {tuple(r) for r in np.round(v3, 12).tolist()}
    assert all(tuple(r) in kept for r in np.round(v[fixed], 12).tolist())


def test_tbss_disc_scaffold_tet_mesh_is_valid_with_min_dihedral_above_5_degrees(run_cli, tmp_path):
    """Issue 23 acceptance 3: a TBSS disc scaffold (sheet gyroid, coarse marching-cubes surface with
    sub-degree sliver triangles; 4.7 deg before the second sliver-repair pass on a finer one)."""
    from porecad.io import read_mesh

    stl = tmp_path / "disc.stl"
    code, _, err = run_cli("tbss", "disc", "G", "--structure", "sheet", "--periods", "2", "2", "1",
                           "--resolution", "8", "-o", stl)
    assert code == 0, err
    v, f = read_mesh(stl)
    out = tmp_path / "disc.vtu"
    code, text, err = run_cli("volmesh", stl, "-o", out, "--json")
    assert code == 0, err
    q = json.loads(text)["quality"]
    assert q["inverted"] == 0 and q["volume_min"] > 0
    assert q["dihedral_deg"]["min"] >= 5.0 and q["below_5deg"] == 0
    assert abs(q["volume"] / signed_volume(v, f) - 1) <= 0.005
    tets = meshio.read(out).cells_dict["tetra"]
    assert len(tets) == q["tets"]
    # the file's own tets: none inverted, smallest dihedral as reported
    mq = tet_quality(meshio.read(out).points, tets)
    assert mq["inverted"] == 0 and mq["dihedral_deg"]["min"] >= 5.0


def test_coarsening_a_fine_surface_keeps_a_valid_solid_and_its_volume():
    import trimesh

    from porecad.mesh.validate import check_solid
    from porecad.simulate.surface_coarsen import coarsen_surface, nonmanifold_vertex_ids

    s = trimesh.creation.icosphere(6)  # 81,920 triangles, edge ~0.02
    v, f, info = coarsen_surface(s.vertices, s.faces, size=0.15)
    assert info["coarsened"] and info["triangles"] < 0.2 * len(s.faces)
    rep = check_solid(v, f, check_self_intersections=True)
    assert rep["closed"] and rep["manifold"] and rep["oriented"] and rep["self_intersections"] == 0
    assert abs(rep["volume"] / s.volume - 1) <= 0.005
    # two tetrahedra sharing one vertex: that vertex is a bowtie
    bow = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2], [0, 4, 5], [0, 5, 6], [0, 6, 4], [4, 6, 5]])
    assert nonmanifold_vertex_ids(bow, 7).tolist() == [0]
    assert nonmanifold_vertex_ids(s.faces, len(s.vertices)).tolist() == []
