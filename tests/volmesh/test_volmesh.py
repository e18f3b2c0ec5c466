"""Tetrahedral meshes (porecad.volmesh): checks, adjacency, colouring, quality, BCC meshing, file I/O."""

import importlib.util
import math
import os

import meshio
import numpy as np
import pytest
import trimesh

from porecad.errors import InputError, OutputError, ResourceError
from porecad.mesh.validate import signed_volume
from porecad.volmesh import (
    FACE_LOCAL,
    VOLUME_MESH_SUFFIXES,
    bcc_tet_mesh,
    boundary_faces,
    check_tet_mesh,
    cube_tets,
    face_adjacency,
    icosahedron_tets,
    is_volume_mesh_path,
    locate_points,
    rainbow_coloring,
    read_tet_mesh,
    regular_tetrahedron,
    signed_volumes,
    tet_quality,
    two_tetrahedra,
    write_tet_mesh,
)

SHAPES = {
    "regular": (lambda: regular_tetrahedron(2.0), 2.0**3 / (6 * math.sqrt(2)), 4),
    "two": (lambda: two_tetrahedra(2.0), 2 * 2.0**3 / (6 * math.sqrt(2)), 6),
    "icosahedron": (lambda: icosahedron_tets(3.0),
                    5 / 12 * (3 + math.sqrt(5)) * (3.0 / math.sin(2 * math.pi / 5)) ** 3, 20),
    "cube": (lambda: cube_tets(2.0), 8.0, 12),
}


def _is_rainbow(colors, tets):
    c = np.sort(colors[tets], axis=1)
    return bool(np.array_equal(c, np.broadcast_to(np.arange(4), c.shape)))


# ---------------------------------------------------------------- shapes, boundary, adjacency


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_shapes_are_valid_with_expected_volume_and_outward_boundary(name):
    make, volume, n_boundary = SHAPES[name]
    p, t = make()
    p2, t2 = check_tet_mesh(p, t)
    assert np.array_equal(t2, t) and t2.dtype == np.int64 and p2.dtype == np.float64
    vol = signed_volumes(p, t)
    assert (vol > 0).all()
    assert vol.sum() == pytest.approx(volume, rel=1e-12)
    bf, owner, local = boundary_faces(t)
    assert len(bf) == n_boundary
    assert np.array_equal(bf, t[owner[:, None], FACE_LOCAL[local]])
    # every boundary normal points away from its tet, and the surface encloses the volume
    n = np.cross(p[bf[:, 1]] - p[bf[:, 0]], p[bf[:, 2]] - p[bf[:, 0]])
    out = p[bf].mean(axis=1) - p[t[owner]].mean(axis=1)
    assert (np.einsum("ij,ij->i", n, out) > 0).all()
    assert signed_volume(p, bf) == pytest.approx(volume, rel=1e-12)


def test_face_adjacency_is_symmetric_and_matches_shared_faces():
    p, t = two_tetrahedra()
    nb = face_adjacency(t)
    # the shared face (0, 1, 2) is opposite the apex (3 or 4) of each tet
    expect = np.full((2, 4), -1)
    expect[0, list(t[0]).index(3)] = 1
    expect[1, list(t[1]).index(4)] = 0
    assert np.array_equal(nb, expect)
    for make in (cube_tets, icosahedron_tets):
        p, t = make()
        nb = face_adjacency(t)
        assert ((nb >= 0).sum(axis=1) == (2 if make is cube_tets else 3)).all()
        for ti, k in zip(*np.nonzero(nb >= 0)):
            u = nb[ti, k]
            assert ti in nb[u]
            shared = set(t[ti]) - {t[ti, k]}
            assert shared <= set(t[u])


# ---------------------------------------------------------------- check_tet_mesh errors


def test_all_negative_mesh_is_flipped():
    p, t = cube_tets(1.5)
    neg = t[:, [1, 0, 2, 3]]
    assert (signed_volumes(p, neg) < 0).all()
    _, fixed = check_tet_mesh(p, neg)
    assert (signed_volumes(p, fixed) > 0).all()
    assert np.array_equal(np.sort(fixed, axis=1), np.sort(t, axis=1))


def test_inverted_tet_is_named():
    p, t = cube_tets(1.0)
    t = t.copy()
    t[4] = t[4, [1, 0, 2, 3]]
    with pytest.raises(InputError, match=r"^tet 4 is inverted \(signed volume -0\.1667 mm³; "
                                         r"vertices \d+, \d+, \d+, \d+\)$"):
        check_tet_mesh(p, t)
    # majority negative: the positive tet is the inverted one
    t = t[:, [1, 0, 2, 3]]
    with pytest.raises(InputError, match=r"^tet 4 is inverted \(signed volume 0\.1667 mm³ while 5 of 6"):
        check_tet_mesh(p, t)


def test_degenerate_and_repeated_and_out_of_range():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1.0]])
    with pytest.raises(InputError, match=r"^tet 1 is degenerate \(signed volume 0 mm³"):
        check_tet_mesh(p, [[0, 1, 2, 4], [0, 1, 2, 3]])
    with pytest.raises(InputError, match=r"^tet 1 repeats a vertex \(vertices 0, 1, 1, 4\)$"):
        check_tet_mesh(p, [[0, 1, 2, 4], [0, 1, 1, 4]])
    with pytest.raises(InputError, match=r"^tet 0 references vertex 7, outside 0\.\.4"):
        check_tet_mesh(p, [[0, 1, 7, 4]])
    q = p.copy()
    q[2, 1] = np.nan
    with pytest.raises(InputError, match=r"^point 2 has a non-finite coordinate"):
        check_tet_mesh(q, [[0, 1, 2, 4]])
    with pytest.raises(InputError, match=r"tets must have shape \(T, 4\)"):
        check_tet_mesh(p, [[0, 1, 2]])
    with pytest.raises(InputError, match="no tetrahedra"):
        check_tet_mesh(p, np.zeros((0, 4), int))


def test_face_shared_by_three_tets():
    p, t = two_tetrahedra()
    p = np.vstack([p, p[3] + [0, 0, 0.5]])  # a third tet on the shared face, overlapping the first
    t = np.vstack([t, [[0, 1, 2, 5]]])
    assert (signed_volumes(p, t) > 0).all()
    with pytest.raises(InputError, match=r"^tet mesh is not conforming: face \(0, 1, 2\) is shared by "
                                         r"3 tets \(0, 1, 2\)$"):
        check_tet_mesh(p, t)
    with pytest.raises(InputError, match=r"face \(0, 1, 2\) is shared by 3 tets"):
        face_adjacency(t)


def test_hanging_node_is_not_conforming():
    p, t = two_tetrahedra()
    # split the second tet at the midpoint of edge 0-1 but not the first: a hanging node
    m = len(p)
    p = np.vstack([p, (p[0] + p[1]) / 2])
    split = np.array([[m if x == 1 else x for x in t[1]], [m if x == 0 else x for x in t[1]]])
    assert np.array_equal(check_tet_mesh(p, split)[1], split)  # the split tet alone is fine
    t = np.vstack([t[:1], split])
    assert (signed_volumes(p, t) > 0).all()
    with pytest.raises(InputError, match=r"^tet mesh is not conforming: boundary edge \(\d+, \d+\) is "
                                         r"used by 4 boundary face\(s\) \(hanging node or gap near tet \d\)$"):
        check_tet_mesh(p, t)


# ---------------------------------------------------------------- colouring, quality, location


def test_rainbow_coloring_exists_for_foldable_meshes_and_not_for_icosahedron():
    for make in (regular_tetrahedron, two_tetrahedra, cube_tets):
        p, t = make()
        c = rainbow_coloring(t)
        assert c is not None and c.dtype == np.int8 and _is_rainbow(c, t)
    p, t = two_tetrahedra()
    assert rainbow_coloring(t)[3] == rainbow_coloring(t)[4]  # both apexes get the colour the face lacks
    assert rainbow_coloring(icosahedron_tets()[1]) is None


def test_regular_tet_quality():
    p, t = regular_tetrahedron(3.0)
    q = tet_quality(p, t)
    assert q["tets"] == 1 and q["vertices"] == 4
    assert q["radius_ratio_min"] == pytest.approx(1.0, abs=1e-12)
    assert q["dihedral_min_deg"] == pytest.approx(math.degrees(math.acos(1 / 3)), abs=1e-9)
    assert q["dihedral_max_deg"] == pytest.approx(70.528779, abs=1e-6)
    assert q["edge_length_mean"] == pytest.approx(3.0)
    assert q["volume_total"] == pytest.approx(27 / (6 * math.sqrt(2)))
    # the cube's Kuhn tets: right angles and 45° / 60° dihedrals
    q = tet_quality(*cube_tets())
    assert q["dihedral_min_deg"] == pytest.approx(45.0)
    assert q["dihedral_max_deg"] == pytest.approx(90.0)
    assert 0 < q["radius_ratio_min"] < 1


def test_locate_points_in_cube():
    p, t = cube_tets(2.0)
    q = np.random.default_rng(3).uniform(-0.5, 2.5, size=(3000, 3))
    tet, bary = locate_points(p, t, q)
    inside = (q > 0).all(axis=1) & (q < 2).all(axis=1)
    clear = np.abs(q - 1).max(axis=1) < 0.999 - 1e-6
    assert np.array_equal((tet >= 0)[clear | ~inside], inside[clear | ~inside])
    found = tet >= 0
    rebuilt = np.einsum("ij,ijk->ik", bary[found], p[t[tet[found]]])
    assert np.allclose(rebuilt, q[found], atol=1e-12)
    assert (bary[found] >= -1e-9).all() and np.isnan(bary[~found]).all()


# ---------------------------------------------------------------- BCC lattice meshing


@pytest.fixture(scope="module")
def ball():
    m = trimesh.creation.icosphere(subdivisions=3, radius=10)
    return np.asarray(m.vertices), np.asarray(m.faces), float(m.volume)


def test_bcc_unsnapped_is_the_pure_lattice(ball):
    v, f, vol = ball
    p, t, info = bcc_tet_mesh(v, f, spacing=2.5, snap=False)
    h = info["spacing"]
    assert h == 2.5 and info["target_tets"] is None and info["snapped_vertices"] == 0
    assert np.array_equal(check_tet_mesh(p, t)[1], t)
    assert np.allclose(signed_volumes(p, t), h**3 / 12)
    q = info["quality"]
    assert q["dihedral_min_deg"] == pytest.approx(60.0) and q["dihedral_max_deg"] == pytest.approx(90.0)
    assert q["radius_ratio_min"] == pytest.approx(3 / math.sqrt(10))
    assert info["coverage"] == 1.0
    assert vol < q["volume_total"] < 2 * vol
    assert _is_rainbow(info["colors"], t)


def test_bcc_sphere_hits_target_covers_and_is_rainbow(ball):
    v, f, vol = ball
    p, t, info = bcc_tet_mesh(v, f, target_tets=2000)
    assert abs(info["tets"] - 2000) <= 200 and info["tets"] == len(t) and info["points"] == len(p)
    assert np.array_equal(check_tet_mesh(p, t)[1], t)
    assert info["coverage"] >= 0.99
    q = info["quality"]
    assert q["volume_min"] > 0
    assert q["radius_ratio_min"] >= 0.25 - 1e-9
    assert q["dihedral_min_deg"] > 5.0  # measured 10.3° (rr floor 0.25); unsnapped lattice 60°
    # snapping pulled the boundary in: the domain hugs the ball (measured 1.07 x its volume)
    assert vol < q["volume_total"] < 1.15 * vol
    assert 0 < info["snapped_vertices"] <= info["boundary_vertices"]
    assert info["boundary_distance_mean"] < 0.2 * info["spacing"]
    colors = info["colors"]
    assert colors.dtype == np.int8 and _is_rainbow(colors, t)
    bfs = rainbow_coloring(t)
    assert bfs is not None and _is_rainbow(bfs, t)
    # the colouring of a connected mesh is unique up to a permutation of the colours
    perm = {int(a): int(b) for a, b in zip(colors, bfs)}
    assert len(perm) == 4 and len(set(perm.values())) == 4


def test_bcc_higher_quality_floor_trades_hugging_for_angles(ball):
    v, f, vol = ball
    _, _, lo = bcc_tet_mesh(v, f, spacing=2.5)
    _, _, hi = bcc_tet_mesh(v, f, spacing=2.5, min_radius_ratio=0.6)
    assert hi["quality"]["dihedral_min_deg"] > lo["quality"]["dihedral_min_deg"]
    assert hi["quality"]["radius_ratio_min"] >= 0.6 - 1e-9
    assert hi["quality"]["volume_total"] > lo["quality"]["volume_total"] > vol
    assert hi["coverage"] >= 0.99


def test_bcc_thin_and_nonconvex_bodies_stay_conforming():
    # an annulus at a coarse spacing keeps tets that meet only along an edge
    # unless the mesher closes them up; every result must pass the checks
    for m, target in ((trimesh.creation.annulus(r_min=8, r_max=12, height=5), 50),
                      (trimesh.creation.torus(major_radius=20, minor_radius=4), 500)):
        p, t, info = bcc_tet_mesh(m.vertices, m.faces, target_tets=target)
        check_tet_mesh(p, t)
        assert info["coverage"] >= 0.99
        assert _is_rainbow(info["colors"], t)


def test_bcc_femur(femur_path):
    from porecad.bodies import load_body

    v, f, _ = load_body(femur_path, check_intersections=False)
    p, t, info = bcc_tet_mesh(v, f, target_tets=1000)
    assert abs(info["tets"] - 1000) <= 100
    assert info["coverage"] >= 0.99
    assert info["quality"]["volume_min"] > 0
    assert _is_rainbow(info["colors"], t)


def test_bcc_refuses_bad_input(ball):
    v, f, _ = ball
    with pytest.raises(InputError, match=r"^body mesh is not closed: 3 boundary edges"):
        bcc_tet_mesh(v, f[1:])
    for bad in (0, -5, 2.5, "many"):
        with pytest.raises(InputError, match="target_tets must be a positive integer"):
            bcc_tet_mesh(v, f, target_tets=bad)
    with pytest.raises(InputError, match="spacing must be a positive"):
        bcc_tet_mesh(v, f, spacing=0.0)
    with pytest.raises(InputError, match="encloses no volume"):
        bcc_tet_mesh(v, f[:, ::-1])
    with pytest.raises(ResourceError, match=r"too large: about 6e\+06 tets"):
        bcc_tet_mesh(v, f, target_tets=6_000_000)
    with pytest.raises(ResourceError, match=r"tets at spacing 0\.01 mm"):
        bcc_tet_mesh(v, f, spacing=0.01)
    with pytest.raises(ResourceError, match="too large for this machine"):
        bcc_tet_mesh(v, f, target_tets=100_000, memory_limit=10_000_000)


# ---------------------------------------------------------------- file I/O


@pytest.mark.parametrize("suffix", [".vtu", ".msh", ".vtk", ".inp", ".mesh"])
def test_round_trip(tmp_path, suffix):
    p, t = cube_tets(2.5)
    p = p + [1.0, -2.0, 3.0]
    path = tmp_path / f"cube{suffix}"
    assert write_tet_mesh(path, p, t) == path
    p2, t2 = read_tet_mesh(path)
    assert np.allclose(p2, p, rtol=0, atol=1e-12) and np.array_equal(t2, t)
    assert sorted(os.listdir(tmp_path)) == [path.name]  # no temporary files left


def test_write_refuses_existing_file_without_force(tmp_path):
    p, t = regular_tetrahedron()
    path = tmp_path / "tet.vtu"
    write_tet_mesh(path, p, t)
    before = path.read_bytes()
    with pytest.raises(OutputError, match="already exists"):
        write_tet_mesh(path, *two_tetrahedra())
    assert path.read_bytes() == before
    write_tet_mesh(path, *two_tetrahedra(), force=True)
    assert len(read_tet_mesh(path)[1]) == 2
    with pytest.raises(InputError, match="is inverted"):
        write_tet_mesh(tmp_path / "bad.vtu", p, np.array([[0, 1, 2, 3], [0, 2, 1, 3]]))
    assert not (tmp_path / "bad.vtu").exists()


def test_read_refusals_and_conversions(tmp_path):
    hexa = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                     [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.0]])
    path = tmp_path / "BODY.vtu"
    meshio.write(path, meshio.Mesh(hexa, [("hexahedron", np.arange(8)[None])]))
    with pytest.raises(InputError, match=r"BODY\.vtu holds no tetrahedra \(cell types: hexahedron\)$"):
        read_tet_mesh(path)
    with pytest.raises(InputError, match="no such file"):
        read_tet_mesh(tmp_path / "missing.vtu")
    (tmp_path / "junk.msh").write_bytes(b"\x00 not a mesh\n")
    with pytest.raises(InputError, match=r"junk\.msh: cannot read as a volume mesh") as exc:
        read_tet_mesh(tmp_path / "junk.msh")
    assert "\n" not in str(exc.value)
    with pytest.raises(InputError, match="not a volume mesh format"):
        read_tet_mesh(tmp_path / "x.stl")
    # quadratic tets give their corners; an all-negative file comes back flipped
    p, t = cube_tets()
    mid = (p[t[:, [0, 0, 0, 1, 1, 2]]] + p[t[:, [1, 2, 3, 2, 3, 3]]]) / 2
    p10 = np.vstack([p, mid.reshape(-1, 3)])
    t10 = np.hstack([t[:, [1, 0, 2, 3]], len(p) + np.arange(6 * len(t)).reshape(-1, 6)])
    meshio.write(tmp_path / "quad.vtu", meshio.Mesh(p10, [("tetra10", t10), ("triangle", t[:, :3])]))
    p2, t2 = read_tet_mesh(tmp_path / "quad.vtu")
    assert len(p2) == len(p10) and (signed_volumes(p2, t2) > 0).all()
    assert np.array_equal(np.sort(t2, axis=1), np.sort(t, axis=1))


def test_xdmf_needs_h5py_or_round_trips(tmp_path):
    p, t = cube_tets()
    path = tmp_path / "cube.xdmf"
    if importlib.util.find_spec("h5py") is None:
        with pytest.raises(OutputError, match="needs the h5py package"):
            write_tet_mesh(path, p, t)
        assert os.listdir(tmp_path) == []
        return
    write_tet_mesh(path, p, t)
    p2, t2 = read_tet_mesh(path)
    assert np.allclose(p2, p) and np.array_equal(t2, t)


def test_volume_mesh_suffixes():
    assert VOLUME_MESH_SUFFIXES == (".vtk", ".vtu", ".msh", ".inp", ".mesh", ".xdmf")
    assert is_volume_mesh_path("a/B.VTU") and is_volume_mesh_path("x.msh")
    assert not is_volume_mesh_path("femur.stl") and not is_volume_mesh_path("noext")
