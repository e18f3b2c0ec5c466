"""TPMS cells mapped into structured hex meshes by 8- and 20-node shape functions (000 ch.3, 004)."""

import numpy as np
import pytest

from porecad.errors import InputError
from porecad.io import read_mesh
from porecad.maps.hexmesh import (check_jacobian, cylinder_nodes, frustum_nodes, hex_scaffold, map_hex8, map_hex20,
                                  scaled_jacobians)
from porecad.mesh.topology import edge_topology
from porecad.mesh.validate import check_solid


@pytest.mark.parametrize("body", ["frustum", "cylinder"])
@pytest.mark.parametrize("tpms", ["P", "IWP"])
def test_generated_bodies_closed(run_json, tmp_path, body, tpms):
    """004's examples: P and I-WP in a frustum and a cylinder, closed, manifold, no self-intersections."""
    out = tmp_path / f"{body}.stl"
    r = run_json("hex", body, tpms, "--grid", "3", "3", "4", "--element", "hex20", "--structure", "pore",
                 "--threshold", "0", "--resolution", "10", "-o", out)
    assert r["closed"] and r["manifold"] and r["self_intersections"] == 0
    assert r["min_scaled_jacobian"] > 0
    v, f = read_mesh(out)
    assert edge_topology(f)["boundary_edges"] == 0
    assert 0.2 < r["porosity"] < 0.8


def test_hex20_follows_the_cylinder_closer(run_json):
    """Acceptance 4: on the curved side, 20-node cells stay much closer to the cylinder than 8-node cells."""
    d = {}
    for el in ("hex8", "hex20"):
        r = run_json("hex", "cylinder", "P", "--grid", "4", "4", "2", "--element", el, "--porosity", "0.6",
                     "--resolution", "12")
        d[el] = r["boundary_distance"]
    assert d["hex20"]["max"] < d["hex8"]["max"] / 5
    assert d["hex20"]["mean"] < d["hex8"]["mean"] / 5


def test_a_porosity_outside_the_valid_range_is_refused_like_every_job(run_cli, tmp_path):
    """Issue 38: hex held a porosity to no valid range (the one rule now lives in calibration.constant_threshold)."""
    out = tmp_path / "x.stl"
    code, text, err = run_cli("hex", "cylinder", "P", "--grid", "2", "2", "2", "--porosity", "0.95", "-o", out)
    assert code != 0 and "outside the valid range" in err and "--allow-closed-pores" in err and not out.exists()
    code, text, err = run_cli("hex", "cylinder", "P", "--grid", "2", "2", "2", "--porosity", "0.6",
                              "--threshold", "0", "-o", out)
    assert code != 0 and "exactly one of" in err and not out.exists()


def test_shape_functions_interpolate_and_are_continuous():
    nodes = cylinder_nodes((2, 3, 2), element="hex20")
    corners = nodes[::2, ::2, ::2]
    # hex20 reproduces its nodes (corners and mid-edges), hex8 its corners
    p = np.array([[1.0, 2.0, 1.0], [0.5, 0.0, 0.0], [2.0, 1.5, 2.0], [1.0, 1.0, 0.5]])
    idx = np.rint(2 * p).astype(int)
    assert np.allclose(map_hex20(nodes, p), nodes[idx[:, 0], idx[:, 1], idx[:, 2]])
    q = np.array([[1.0, 2.0, 1.0], [2.0, 0.0, 2.0]])
    qi = q.astype(int)
    assert np.allclose(map_hex8(corners, q), corners[qi[:, 0], qi[:, 1], qi[:, 2]])
    # continuity across the shared face u = 1 from both cells
    rng = np.random.default_rng(0)
    face = np.column_stack([np.ones(50), rng.uniform(0, 3, 50), rng.uniform(0, 2, 50)])
    eps = np.array([1e-12, 0, 0])
    for f in (lambda x: map_hex20(nodes, x), lambda x: map_hex8(corners, x)):
        assert np.allclose(f(face - eps), f(face + eps), atol=1e-9)


def test_jacobian_check_names_the_cell():
    nodes = frustum_nodes((3, 3, 3))
    assert scaled_jacobians(nodes).min() > 0.9
    bad = nodes.copy()
    bad[1, 1, 1], bad[2, 1, 1] = nodes[2, 1, 1].copy(), nodes[1, 1, 1].copy()  # swap two nodes: folds cells
    with pytest.raises(InputError, match=r"hexahedron \(\d+, \d+, \d+\) is inverted"):
        check_jacobian(bad)
    flat = nodes.copy()
    flat[:, :, 1] = flat[:, :, 0]
    with pytest.raises(InputError, match="degenerate|inverted"):
        hex_scaffold(flat, "P", "pore", 0.0, 8)


def test_parametric_solid_maps_closed():
    res = hex_scaffold(frustum_nodes((2, 2, 2), element="hex20"), "G", "sheet", 0.4, 10, element="hex20")
    chk = check_solid(res["vertices"], res["faces"], check_self_intersections=True)
    assert chk["closed"] and chk["outward"] and chk["self_intersections"] == 0


def test_hex_cli_errors(run_cli, tmp_path):
    code, _, err = run_cli("hex", "cylinder", "P", "--grid", "2", "2", "2", "--element", "hex27", "--threshold", "0")
    assert code != 0 and len(err.strip().splitlines()) == 1 and "hex27" in err
    code, _, err = run_cli("hex", "cylinder", "P", "--grid", "0", "2", "2", "--threshold", "0")
    assert code != 0 and "positive" in err and len(err.strip().splitlines()) == 1
    code, _, err = run_cli("hex", "cylinder", "P", "--grid", "2", "2", "2")
    assert code != 0 and "exactly one" in err
    code, _, err = run_cli("hex", tmp_path / "nope.stl", "P", "--grid", "2", "2", "2", "--threshold", "0")
    assert code != 0 and "no such file" in err


@pytest.mark.parametrize("body,tpms", [("frustum", "P"), ("cylinder", "IWP")])
def test_point_refinement_shrinks_pores_in_proportion(run_json, tmp_path, body, tpms):
    """Acceptance 1: refined around a grid vertex (004's point template), still closed; pores shrink with the cells."""
    r = run_json("hex", body, tpms, "--grid", "4", "4", "4", "--threshold", "0", "--refine-point", "1", "1", "1",
                 "--resolution", "12", "-o", tmp_path / "r.stl")
    assert r["closed"] and r["manifold"] and r["self_intersections"] == 0
    ref = r["refinement"]
    assert ref["hexahedra"] == 64 + 8 * 3  # the 8 cells at the vertex become 4 each
    assert ref["pore_size_ratio"] < 0.55
    assert abs(ref["pore_size_ratio"] / ref["cell_size_ratio"] - 1) < 0.4, ref


def test_refine_templates_are_conforming():
    from porecad.volmesh.hexshapes import hex_grid, hex_volumes
    from porecad.volmesh.refine import refine_points
    P, H = hex_grid(3, 3, 3, 2.0)
    corner_ids = [0, 63]  # two vertices far apart (a corner of the grid and the opposite one)
    P2, H2 = refine_points(P, H, corner_ids)
    assert len(H2) == 27 + 2 * 3
    assert hex_volumes(P2, H2).sum() == pytest.approx(216.0)
    with pytest.raises(InputError, match="two refinement points"):
        refine_points(P, H, [0, 1])


def test_hex_mesh_file_unstructured(run_json, run_cli, tmp_path):
    import meshio

    from porecad.volmesh.hexshapes import hex_grid
    from porecad.volmesh.refine import refine_points
    P, H = hex_grid(3, 3, 3, 4.0)
    P2, H2 = refine_points(P, H, [21])
    path = tmp_path / "ref.vtu"
    meshio.write(path, meshio.Mesh(P2, [("hexahedron", H2)]))
    r = run_json("hex", path, "IWP", "--threshold", "0", "--resolution", "10", "-o", tmp_path / "a.stl")
    assert r["closed"] and r["manifold"] and r["self_intersections"] == 0 and r["hexahedra"] == 51
    v, f = read_mesh(tmp_path / "a.stl")
    assert edge_topology(f)["boundary_edges"] == 0
    code, _, err = run_cli("hex", path, "G", "--threshold", "0")
    assert code != 0 and "symmetric" in err and len(err.strip().splitlines()) == 1
    # a hanging node (one hex on top of two) is refused, naming the place
    pts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0],
                    [0, 0, 1], [1, 0, 1], [2, 0, 1], [0, 1, 1], [1, 1, 1], [2, 1, 1],
                    [0, 0, 2], [2, 0, 2], [2, 1, 2], [0, 1, 2]], float)
    hx = np.array([[0, 1, 4, 3, 6, 7, 10, 9], [1, 2, 5, 4, 7, 8, 11, 10], [6, 8, 11, 9, 12, 13, 14, 15]])
    bad = tmp_path / "hanging.vtu"
    meshio.write(bad, meshio.Mesh(pts, [("hexahedron", hx)]))
    code, _, err = run_cli("hex", bad, "P", "--threshold", "0")
    assert code != 0 and "not conforming" in err and len(err.strip().splitlines()) == 1
    tets = tmp_path / "tets.vtu"
    meshio.write(tets, meshio.Mesh(pts, [("tetra", np.array([[0, 1, 3, 6]]))]))
    code, _, err = run_cli("hex", tets, "P", "--threshold", "0")
    assert code != 0 and "no hexahedra" in err


def test_fold_inside_a_cell_with_valid_corners_is_refused():
    """Positive corner Jacobians do not make a trilinear cell injective; the sampled check catches the fold."""
    from porecad.maps.hexmesh import sampled_jacobians
    g = np.array([[0.286, -0.362, -0.167], [-0.175, -0.164, 0.581], [-0.192, 1.357, 0.403], [0.034, 1.201, 1.317],
                  [0.811, 0.648, -0.018], [1.426, 0.287, 0.982], [0.452, 0.663, -0.192], [0.526, 0.845, 0.005]]
                 ).reshape(2, 2, 2, 3)
    assert scaled_jacobians(g).min() > 0.1
    assert sampled_jacobians(g).min() < 0
    with pytest.raises(InputError, match=r"hexahedron \(0, 0, 0\) folds inside"):
        check_jacobian(g)


def test_hex_report_directory(run_json, tmp_path):
    """The full analysis runs on a mapped scaffold (a NaN distance once broke it) and has finite pore sizes."""
    import json
    rep = tmp_path / "rep"
    run_json("hex", "frustum", "P", "--grid", "2", "2", "2", "--threshold", "0", "--report", rep)
    data = json.loads((rep / "report.json").read_text(encoding="utf-8"))
    text = json.dumps(data)
    assert "NaN" not in text
    assert (rep / "report.html").exists()


def test_femur_hex_5x7x20(run_json, tmp_path, femur_path):
    """Acceptance 2 (5x7x20): the parameterised femur, P cells, closed, manifold, no self-intersections."""
    r = run_json("hex", femur_path, "P", "--grid", "5", "7", "20", "--threshold", "0", "--resolution", "8",
                 "-o", tmp_path / "femur.stl")
    assert r["closed"] and r["manifold"] and r["self_intersections"] == 0
    assert r["min_scaled_jacobian"] > 0 and r["min_sampled_jacobian_ratio"] > 0
    assert 0.2 < r["porosity"] < 0.8


def test_femur_field_cut_matches_boolean(femur_path):
    """The field-space cut (max of structure and body distance, one MC pass) gives the Boolean's solid.

    D and G cut by the mesh Boolean once left slivers (self-intersecting pairs);
    the field cut is checked here against the Boolean's volume and for being
    a clean solid.
    """
    from porecad.bodies.mesh import MeshBody
    from porecad.maps.hex_grid import HexBody, hex_nodes
    from porecad.maps.hexmesh import cut_band, hex_scaffold
    from porecad.mesh.boolean import intersect
    from porecad.mesh.validate import check_solid, signed_volume
    nodes, body, _ = hex_nodes(HexBody("mesh", str(femur_path)), (5, 7, 20), "hex8")
    ext = float(np.max(body[0].max(axis=0) - body[0].min(axis=0)))
    clip = MeshBody(body[0], body[1], band=0.05 * ext)
    cut = hex_scaffold(nodes, "D", "pore", 0.0, 8, clip=clip)
    chk = check_solid(cut["vertices"], cut["faces"], check_self_intersections=False)
    assert chk["closed"] and chk["manifold"] and chk["outward"]
    whole = hex_scaffold(nodes, "D", "pore", 0.0, 8)
    vb, fb = intersect(whole["vertices"], whole["faces"], *body)
    v_field, v_bool = signed_volume(cut["vertices"], cut["faces"]), signed_volume(vb, fb)
    # 8 samples per cell edge: the cut is faceted at 1/7 cell (0.4 % at 12 samples, measured)
    assert abs(v_field - v_bool) < 0.02 * v_bool, (v_field, v_bool)
    assert v_field < 0.99 * signed_volume(whole["vertices"], whole["faces"])  # it did cut
    # the job's body field is exact only a few sample steps deep (cut_band): the same mesh as the wide band's
    band = cut_band(nodes, "hex8", 8)
    assert band < 0.8 * 0.05 * ext
    narrow = hex_scaffold(nodes, "D", "pore", 0.0, 8, clip=MeshBody(body[0], body[1], band=band))
    assert np.array_equal(narrow["faces"], cut["faces"]) and np.array_equal(narrow["vertices"], cut["vertices"])


def test_relax_self_intersections_unfolds_a_fold():
    """A vertex pushed through the far side of a sphere is pulled back by local umbrella steps only."""
    import trimesh

    from porecad.mesh.repair import relax_self_intersections
    from porecad.mesh.validate import self_intersections
    m = trimesh.creation.icosphere(subdivisions=4)
    v = np.array(m.vertices)
    f = np.array(m.faces)
    top = int(np.argmax(v[:, 2]))
    v[top] = [0.0, 0.0, -1.05]  # a spike through the bottom of the sphere
    _, n0 = self_intersections(v, f)
    assert n0 > 0
    v2, info = relax_self_intersections(v, f)
    assert info["pairs_before"] == n0 and info["pairs_after"] == 0
    assert self_intersections(v2, f)[1] == 0
    from porecad.mesh.validate import stored_coordinates
    moved = np.any(v2 != stored_coordinates(v), axis=1)  # the repair works on the coordinates as stored
    assert moved.sum() == info["vertices_moved"] and 0 < moved.sum() < 0.05 * len(v)  # only near the fold


def test_refine_box_full_template(run_json, tmp_path):
    """004's full template on a box of cells, with face/edge/point transitions: conforming, closed, smaller pores."""
    r = run_json("hex", "cylinder", "P", "--grid", "6", "6", "6", "--threshold", "0", "--refine-box", "1", "1", "1",
                 "3", "3", "3", "--resolution", "8", "-o", tmp_path / "rb.stl")
    assert r["closed"] and r["manifold"] and r["self_intersections"] == 0
    ref = r["refinement"]
    assert ref["hexahedra"] == 216 - 64 + 8 * 27 + 24 * 22 + 24 * 11 + 8 * 4  # box cells, face/edge/corner neighbours
    assert ref["pore_size_ratio"] < 0.6
    assert 0.5 < ref["pore_size_ratio"] / ref["cell_size_ratio"] < 1.6, ref


def test_folding_corner_choice_one_line(one_line_error, tmp_path):
    """Acceptance 5: corners that fold a face are refused naming the face."""
    import trimesh

    from porecad.io import read_mesh as _read
    from porecad.param.hexcube import choose_corners
    path = tmp_path / "box.stl"
    m = trimesh.creation.box((20.0, 30.0, 50.0))
    m = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(m.vertices, m.faces, 4.0))
    m.export(path)
    v, f = _read(path)
    c = choose_corners(v, f)
    mirrored = c[[0, 3, 2, 1, 4, 7, 6, 5]]
    one_line_error("hex", path, "P", "--grid", "2", "3", "5", "--threshold", "0", "--corners",
                   *[int(x) for x in mirrored], match="folds face f")


def test_relax_widens_the_region_of_a_fold_one_ring_cannot_flatten():
    """A fold of porecad's femur 5x10x60 D hex scaffold at its strained end (10,170 faces around 22 crossing pairs,
    tests/data/stuck_fold.npz): umbrella steps over one ring of neighbours leave 3 pairs after ten rounds, and the
    job refused the whole scaffold; a round that removes no pair now widens the region by a ring."""
    from pathlib import Path

    import porecad.mesh.repair as repair
    from porecad.mesh.validate import self_intersections
    with np.load(Path(__file__).parents[1] / "data" / "stuck_fold.npz") as z:
        v, f = z["vertices"].astype(np.float64), z["faces"].astype(np.int64)
    assert self_intersections(v, f)[1] == 22
    v2, info = repair.relax_self_intersections(v, f, max_rounds=10)
    assert info["pairs_before"] == 22 and info["pairs_after"] == 0 and info["rings"] > 1
    assert self_intersections(v2, f)[1] == 0 and info["max_move"] < 0.5     # mm, a local move
    # after a round only the faces near the moved ones are searched: the same rounds as a whole-mesh search
    # (22, 9, 11, then 3 for seven rounds, 0: measured with both)
    assert info["rounds"] == 10 and info["rings"] == 3
    old = repair.MAX_RINGS
    try:
        repair.MAX_RINGS = 1                                                    # one ring only, as before
        assert repair.relax_self_intersections(v, f, max_rounds=10)[1]["pairs_after"] > 0
    finally:
        repair.MAX_RINGS = old
