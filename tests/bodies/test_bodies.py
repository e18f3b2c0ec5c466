"""Bodies: loading and repair, winding-number inside test, infill cut/skin/whole (issue 3)."""

import json

import numpy as np
import pytest
import trimesh

from porecad.bodies import MeshBody, load_body
from porecad.errors import InputError, ResourceError
from porecad.io import read_mesh, write_mesh


def _sphere(tmp_path, name="ball.stl", radius=10.0, subdivisions=3, center=(0, 0, 0)):
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    path = tmp_path / name
    write_mesh(path, np.asarray(m.vertices) + center, np.asarray(m.faces))
    return path


def test_winding_and_distance_match_trimesh(tmp_path):
    v, f = read_mesh(_sphere(tmp_path))
    body = MeshBody(v, f, band=1.5)
    pts = np.random.default_rng(1).uniform(-12, 12, size=(4000, 3))
    # away from the faceted surface the inside test is the analytic ball (no rtree needed)
    r = np.linalg.norm(pts, axis=1)
    far = np.abs(r - 10.0) > 0.2
    assert np.array_equal(body.contains(pts[far]), r[far] < 10.0)
    pts = pts[far]
    # brute-force reference distances: closest point on every triangle (trimesh), for 300 points
    q = pts[:300]
    tri = v[f]
    cp = trimesh.triangles.closest_point(np.repeat(tri[None], len(q), 0).reshape(-1, 3, 3),
                                         np.repeat(q, len(f), 0))
    dist = np.linalg.norm(cp - np.repeat(q, len(f), 0), axis=1).reshape(len(q), len(f)).min(axis=1)
    ref = np.clip(np.where(np.linalg.norm(q, axis=1) < 10.0, -dist, dist), -1.5, 1.5)
    assert np.allclose(body.evaluate(q), ref, atol=1e-9)


def test_lattice_evaluation_equals_pointwise(tmp_path):
    """MeshBody.evaluate_lattice decides most samples of a mapped grid from a coarser lattice (Lipschitz bound):
    its values must equal evaluate's exactly, on a twisted, unevenly stretched lattice crossing the surface."""
    v, f = read_mesh(_sphere(tmp_path, radius=10.0, subdivisions=4))
    body = MeshBody(v, f, band=0.8)
    s = np.linspace(0.0, 1.0, 37)
    U, V, W = np.meshgrid(s, np.linspace(0.0, 1.0, 29), np.linspace(0.0, 1.0, 41), indexing="ij")
    ang = 1.2 * W                                   # a twist about z and a stretch toward one side
    x, y = -14 + 28 * U ** 1.5, -13 + 26 * V
    P = np.stack([x * np.cos(ang) - y * np.sin(ang), x * np.sin(ang) + y * np.cos(ang), -12 + 24 * W], axis=-1)
    ref = body.evaluate(P.reshape(-1, 3)).reshape(P.shape[:3])
    assert 0.05 < np.mean(np.abs(ref) < 0.8) < 0.5   # the lattice crosses the band, most samples lie beyond
    for stride in (2, 4, 8):
        assert np.array_equal(body.evaluate_lattice(P, stride=stride), ref)
    assert np.array_equal(body.evaluate_lattice(P[:5, :5, :5]), ref[:5, :5, :5])   # too small: point by point
    with pytest.raises(InputError):
        body.evaluate_lattice(P.reshape(-1, 3))


def test_nested_and_overlapping_shells_by_winding_number(tmp_path):
    a = trimesh.creation.icosphere(subdivisions=2, radius=10.0)
    b = trimesh.creation.icosphere(subdivisions=2, radius=4.0)
    # a cavity: the inner sphere inverted
    v = np.vstack([a.vertices, b.vertices])
    f = np.vstack([a.faces, b.faces[:, ::-1] + len(a.vertices)])
    body = MeshBody(v, f, band=1.0)
    assert list(body.contains([[0, 0, 0], [7, 0, 0], [0, 0, 11]])) == [False, True, False]
    # two overlapping balls: the union
    c = trimesh.creation.icosphere(subdivisions=2, radius=6.0)
    v = np.vstack([c.vertices, c.vertices + (5, 0, 0)])
    f = np.vstack([c.faces, c.faces + len(c.vertices)])
    body = MeshBody(v, f, band=1.0)
    assert list(body.contains([[2.5, 0, 0], [-5, 0, 0], [10, 0, 0], [0, 7, 0]])) == [True, True, True, False]


def test_repairs_are_reported(tmp_path):
    m = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    # inverted
    write_mesh(tmp_path / "inv.stl", v, f[:, ::-1])
    v2, f2, rep = load_body(tmp_path / "inv.stl")
    assert any("inverted" in r for r in rep["repairs"]) and rep["volume"] > 0
    # a small hole: one triangle missing
    write_mesh(tmp_path / "hole.stl", v, f[1:])
    v2, f2, rep = load_body(tmp_path / "hole.stl")
    assert any("filled" in r for r in rep["repairs"])
    assert rep["volume"] == pytest.approx(m.volume, rel=1e-3)
    # a few faces flipped
    g = f.copy()
    g[:5] = g[:5, ::-1]
    write_mesh(tmp_path / "flip.stl", v, g)
    _, _, rep = load_body(tmp_path / "flip.stl")
    assert any("re-oriented" in r for r in rep["repairs"])


@pytest.mark.parametrize("case", ["big_hole", "garbage", "empty", "huge", "missing"])
def test_bad_bodies_refused_in_one_line(tmp_path, run_cli, case):
    m = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    path = tmp_path / "bad.stl"
    if case == "big_hole":
        write_mesh(path, v, f[v[f].mean(axis=1)[:, 2] < 5])  # the cap above z = 5 removed
    elif case == "garbage":
        path.write_bytes(b"\x00\xffnot a mesh" * 100)
    elif case == "empty":
        path.write_bytes(b"")
    elif case == "huge":
        n = 10**8  # a 1e8-triangle binary STL, sparse on disk
        with open(path, "wb") as fh:
            fh.write(b"x" * 80 + np.uint32(n).tobytes())
            fh.truncate(84 + 50 * n)
    else:
        path = tmp_path / "missing.stl"
    out = tmp_path / "out.stl"
    code, stdout, err = run_cli("infill", path, "G", "--threshold", 0, "--cell-size", 5, "--voxel", 0.5,
                                "-o", out)
    assert code != 0 and stdout == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()
    if case == "huge":
        assert "GiB" in err
    with pytest.raises((InputError, ResourceError)):
        load_body(path)


@pytest.mark.parametrize("boundary", ["cut", "skin", "whole"])
def test_infill_sphere(tmp_path, run_json, boundary):
    body_path = _sphere(tmp_path, radius=12.0, subdivisions=4)
    out = tmp_path / f"{boundary}.stl"
    args = ["infill", body_path, "G", "--structure", "pore", "--threshold", 0, "--cell-size", 5,
            "--voxel", 0.4, "--boundary", boundary, "-o", out, "--check-intersections"]
    if boundary == "skin":
        args += ["--skin", 1.2]
    r = run_json(*args)
    assert r["closed"] and r["manifold"] and r["oriented"] and r["outward"]
    assert r["self_intersections"] == 0
    vb, fb = read_mesh(body_path)
    body_volume = trimesh.Trimesh(vb, fb).volume
    assert r["body_volume"] == pytest.approx(body_volume, rel=1e-9)
    v, f = read_mesh(out)
    vol = trimesh.Trimesh(v, f).volume
    assert r["porosity"] == pytest.approx(1 - vol / body_volume, abs=0.02)  # acceptance 6
    body = MeshBody(vb, fb, band=2.0)
    if boundary == "cut":
        assert abs(r["porosity"] - 0.5) < 0.05
        assert np.all(body.evaluate(v) < 0.05)  # nothing outside the body
    if boundary == "skin":
        # points 0.3..0.9 mm below the surface are solid; the solid never leaves the body
        out_body = MeshBody(v, f, band=1.0)
        rng = np.random.default_rng(0)
        d = rng.normal(size=(3000, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        shell_pts = d * (12.0 - rng.uniform(0.3, 0.9, size=(3000, 1)))
        assert out_body.contains(shell_pts).mean() > 0.99
        assert r["porosity"] < 0.5  # the shell adds material
    if boundary == "whole":
        assert r["complete_cells"] >= 8
        assert abs(r["porosity_cells"] - 0.5) < 0.05
        # every vertex lies inside the body: no cell is cut by the body surface
        assert np.all(body.evaluate(v) < -0.2)


def test_infill_json_is_one_object_with_body_volume(tmp_path, run_cli):
    body_path = _sphere(tmp_path, radius=8.0)
    code, out, err = run_cli("infill", body_path, "P", "--porosity", 0.6, "--cell-size", 4, "--voxel", 0.5,
                             "-o", tmp_path / "p.stl", "--json")
    assert code == 0, err
    r = json.loads(out)
    assert {"porosity", "body_volume", "volume", "surface_area", "triangles", "closed", "manifold"} <= set(r)


@pytest.mark.parametrize("cell, expect", [(4.0, "cell"), (30.0, "body"), (0.1, "floor")])
def test_infill_default_voxel_follows_cell_and_body(tmp_path, run_json, cell, expect):
    """Default voxel: min(cell / 20, smallest extent / 50), never below that extent / 200."""
    from porecad.lattice.plan import default_voxel
    body_path = _sphere(tmp_path, radius=6.0, subdivisions=2)
    vb, _ = read_mesh(body_path)
    e = float((vb.max(axis=0) - vb.min(axis=0)).min())
    h = {"cell": cell / 20, "body": e / 50, "floor": e / 200}[expect]
    assert default_voxel(vb.max(axis=0) - vb.min(axis=0), cell) == pytest.approx(h)
    if expect == "floor":
        return  # 0.1 mm cells in a 12 mm ball: a large job, the rule is enough
    r = run_json("infill", body_path, "G", "--threshold", 0, "--cell-size", cell, "-o", tmp_path / "d.stl")
    assert np.allclose(r["grid"]["spacing"], h, rtol=0.03)  # the grid fits whole steps in the padded box
    assert r["closed"] and r["manifold"]
