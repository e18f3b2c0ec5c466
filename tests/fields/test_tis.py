"""Tetrahedral implicit surfaces (document 002, dissertation 000 ch.4): functions, tables, continuity, CLI."""


import numpy as np
import pytest

from porecad.errors import InputError
from porecad.fields.tis import (RELATIVE_RANGES, relative_threshold, tis_derivatives, tis_value)
from porecad.maps.tis_mesh import tis_field_values, tis_grid_mesh, tis_lattice_mesh
from porecad.mesh.topology import edge_topology
from porecad.mesh.validate import check_solid, signed_volume
from porecad.volmesh import TetLocator, icosahedron_tets, rainbow_coloring, regular_tetrahedron, two_tetrahedra

TAU = 2 * np.pi

# 002 Table 3 (relative threshold, porosity %) for one regular tetrahedron, λ = 1, 200 samples
TABLE3 = {
    "P": [(0.118, 18.36), (0.157, 35.80), (0.196, 49.36), (0.235, 61.17), (0.275, 71.86)],
    "D": [(0.569, 57.35), (0.618, 66.88), (0.667, 75.73), (0.716, 83.04), (0.765, 89.90)],
    "G": [(0.431, 44.03), (0.480, 57.29), (0.529, 67.76), (0.578, 76.09), (0.627, 84.04)],
}


def _volume(points, tets):
    x = points[tets]
    return float(np.sum(np.linalg.det(x[:, 1:] - x[:, :1])) / 6)


def _solid_ok(v, f):
    chk = check_solid(v, f, check_self_intersections=len(f) < 300_000)
    assert chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"], chk
    if len(f) < 300_000:
        assert chk["self_intersections"] == 0
    return chk


@pytest.mark.parametrize("kind", ["P", "D", "G"])
def test_table3_porosity_regular_tet(kind):
    """Acceptance 1: 200 samples per edge, porosity within 1 point of 002 Table 3 at all five thresholds."""
    pts, tets = regular_tetrahedron(1.0)
    vol = _volume(pts, tets)
    for rel, ref in TABLE3[kind]:
        res = tis_lattice_mesh(pts, tets, kind, 1.0, relative=rel, subdivisions=199)
        mesh_por = 100 * (1 - signed_volume(res.vertices, res.faces) / vol)
        assert abs(mesh_por - ref) < 1.0, (kind, rel, mesh_por, ref)
        assert abs(100 * res.sample_porosity - ref) < 1.0, (kind, rel, res.sample_porosity, ref)
    _solid_ok(res.vertices, res.faces)


def _exact_porosity(kind, rel, n=120):
    """Void fraction of one tet on an endpoint-inclusive Cartesian grid (independent of the lattice code)."""
    V = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 1], [0, 1, 1]], float)
    xs = np.linspace(0, 1, n)
    g = np.stack(np.meshgrid(xs, xs, xs, indexing="ij"), -1).reshape(-1, 3)
    M = np.linalg.inv(np.vstack([V.T, np.ones(4)]))
    b = (M @ np.vstack([g.T, np.ones(len(g))])).T
    b = b[(b >= -1e-12).all(axis=1)]
    v = tis_value(TAU * b, kind)
    return 100 * np.mean(v < relative_threshold(v, rel))


def test_printed_g_fails_table3_and_cyclic_g_matches():
    """Erratum: 002 eq. 3 prints G with its first two terms repeated; only the cyclic form fits Table 3."""
    printed = [_exact_porosity("G-printed", r) for r, _ in TABLE3["G"]]
    cyclic = [_exact_porosity("G", r) for r, _ in TABLE3["G"]]
    ref = [p for _, p in TABLE3["G"]]
    assert max(abs(a - b) for a, b in zip(cyclic, ref)) < 1.0
    assert max(abs(a - b) for a, b in zip(printed, ref)) > 8.0
    # P and D as printed do reproduce their rows
    for kind in ("P", "D"):
        got = [_exact_porosity(kind, r) for r, _ in TABLE3[kind]]
        assert max(abs(a - p) for a, (_, p) in zip(got, TABLE3[kind])) < 1.0


def test_tis_values_ranges_and_symmetry():
    """Ranges of the functions on the tet (P max 5 at the vertices, min −0.625 at face centres)."""
    b = np.array([[1, 0, 0, 0], [1 / 3, 1 / 3, 1 / 3, 0], [0.25] * 4])
    p = tis_value(TAU * b, "P")
    assert p[0] == pytest.approx(5.0)
    assert p[1] == pytest.approx(-0.625)
    rng = np.random.default_rng(1)
    th = rng.uniform(0, TAU, (50, 4))
    perm = th[:, [2, 0, 3, 1]]
    for kind in ("P", "D"):  # symmetric in the four coordinates
        assert np.allclose(tis_value(th, kind), tis_value(perm, kind))
    # cyclic G is invariant under rotating the coordinates, not under every permutation
    assert np.allclose(tis_value(th, "G"), tis_value(th[:, [1, 2, 3, 0]], "G"))
    assert not np.allclose(tis_value(th, "G"), tis_value(th[:, [1, 0, 2, 3]], "G"))


@pytest.mark.parametrize("kind", ["P", "D", "G"])
def test_tis_derivatives_match_finite_differences(kind):
    rng = np.random.default_rng(2)
    th = rng.uniform(0, TAU, (20, 4))
    v, g, H = tis_derivatives(th, kind)
    assert np.allclose(v, tis_value(th, kind))
    h = 1e-5
    for i in range(4):
        e = np.zeros(4)
        e[i] = h
        vp, gp, _ = tis_derivatives(th + e, kind)
        vm, gm, _ = tis_derivatives(th - e, kind)
        assert np.allclose((vp - vm) / (2 * h), g[:, i], atol=1e-6)
        assert np.allclose((gp - gm) / (2 * h), H[:, i, :], atol=1e-6)


def test_relative_threshold_eq7():
    v = np.array([-1.0, 0.0, 3.0])
    assert relative_threshold(v, 0.25) == pytest.approx(0.0)
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        relative_threshold(v, 1.5)


def _face_vertices(v, f, a, b, c, tol=1e-9):
    """Mesh vertices lying on the triangle abc's plane and inside it."""
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    on = np.abs((v - a) @ n) < tol * max(1.0, np.abs(v).max())
    return v[on]


@pytest.mark.parametrize("kind", ["P", "D", "G"])
def test_two_tets_weld_and_match_single_tets(kind):
    """Acceptance 2: both tets polygonised alone put the same vertices on the shared face as the welded mesh."""
    pts, tets = two_tetrahedra(10.0)
    res = tis_lattice_mesh(pts, tets, kind, 1.0, relative=RELATIVE_RANGES[kind][0] + 0.05, subdivisions=20)
    _solid_ok(res.vertices, res.faces)
    topo = edge_topology(res.faces)
    assert topo["boundary_edges"] == 0 and topo["nonmanifold_edges"] == 0
    shared = sorted(set(tets[0]) & set(tets[1]))
    a, b, c = pts[shared]
    sides = []
    colors = rainbow_coloring(tets)
    assert colors is not None
    for t in range(2):
        one = tis_lattice_mesh(pts, tets[t:t + 1], kind, 1.0, threshold=res.threshold, subdivisions=20,
                               colors=colors)
        sides.append(np.round(_face_vertices(one.vertices, one.faces, a, b, c), 9))
    s0 = {tuple(r) for r in sides[0]}
    s1 = {tuple(r) for r in sides[1]}
    assert len(s0) > 10 and s0 == s1
    # the welded solid has no vertex on the shared face except where its caps meet the outer boundary
    assert res.face_jump == 0.0


@pytest.mark.parametrize("kind", ["P", "D"])
def test_icosahedron_closed_and_continuous(kind):
    pts, tets = icosahedron_tets(10.0)
    res = tis_lattice_mesh(pts, tets, kind, 1.0, relative=RELATIVE_RANGES[kind][0] + 0.04, subdivisions=16)
    _solid_ok(res.vertices, res.faces)
    assert edge_topology(res.faces)["boundary_edges"] == 0
    assert res.face_jump == 0.0
    por = 1 - signed_volume(res.vertices, res.faces) / _volume(pts, tets)
    assert 0.05 < por < 0.95


def test_icosahedron_g_is_closed_but_reports_its_jumps():
    """The 20-tet icosahedron has no rainbow colouring, so cyclic G differs across some faces."""
    pts, tets = icosahedron_tets(10.0)
    assert rainbow_coloring(tets) is None
    res = tis_lattice_mesh(pts, tets, "G", 1.0, relative=0.5, subdivisions=12)
    _solid_ok(res.vertices, res.faces)
    assert res.slots == "sorted vertex ids"
    assert res.face_jump > 0.1


def test_lattice_and_grid_methods_agree_on_porosity():
    pts, tets = two_tetrahedra(10.0)
    vol = _volume(pts, tets)
    lat = tis_lattice_mesh(pts, tets, "P", 1.0, relative=0.2, subdivisions=40)
    grid = tis_grid_mesh(pts, tets, "P", 1.0, relative=0.2, resolution=41)
    _solid_ok(grid["vertices"], grid["faces"])
    p_lat = 1 - signed_volume(lat.vertices, lat.faces) / vol
    p_grid = 1 - signed_volume(grid["vertices"], grid["faces"]) / vol
    assert abs(p_lat - p_grid) < 0.03, (p_lat, p_grid)
    assert abs(lat.threshold - grid["threshold"]) < 0.05


def test_locator_finds_containing_tets():
    pts, tets = icosahedron_tets(5.0)
    loc = TetLocator(pts, tets)
    rng = np.random.default_rng(3)
    # random points inside random tets
    t = rng.integers(0, len(tets), 500)
    w = rng.dirichlet(np.ones(4), 500)
    q = np.einsum("ij,ijk->ik", w, pts[tets[t]])
    got, bary = loc.locate(q)
    assert (got >= 0).all()
    assert np.allclose(np.einsum("ij,ijk->ik", bary, pts[tets[got]]), q)
    far = np.array([[100.0, 0, 0]])
    assert loc.locate(far)[0][0] == -1
    vals, ins = tis_field_values(loc, np.tile(np.arange(4), (len(tets), 1)), np.ones((len(tets), 4)), "P", q)
    assert ins.all() and np.all(np.isfinite(vals))


def test_bad_lattice_inputs():
    pts, tets = regular_tetrahedron(1.0)
    with pytest.raises(InputError, match="lambda"):
        tis_lattice_mesh(pts, tets, "P", 0.0, relative=0.2)
    with pytest.raises(InputError, match="exactly one"):
        tis_lattice_mesh(pts, tets, "P", 1.0)
    with pytest.raises(InputError, match="unknown TIS type"):
        tis_lattice_mesh(pts, tets, "Q", 1.0, relative=0.2)


def test_tis_curvature_is_asymmetric_unlike_tpms():
    """002 Table 2 / issue 8: TIS mean curvature is skewed with a non-zero mean; exact TPMS curvature is symmetric.

    Exact H from the field (chain rule through the barycentric map) at the
    surface vertices of one unit-volume tet at 002's display thresholds.
    """
    from porecad.fields.tpms import TPMSField
    from porecad.analysis.curvature import field_curvatures
    from porecad.maps.tis_mesh import tis_curvatures
    from porecad.mesh.polygonise import Grid, polygonise

    edge = (6 * np.sqrt(2)) ** (1 / 3)
    pts, tets = regular_tetrahedron(edge)
    for kind, rel in (("P", 0.16), ("D", 0.67), ("G", 0.5)):
        res = tis_lattice_mesh(pts, tets, kind, 1.0, relative=rel, subdivisions=60)
        surf = res.faces[: len(res.faces) - res.n_cap_faces]
        v = res.vertices[np.unique(surf)]
        H, K, bmin = tis_curvatures(pts, tets, kind, 1.0, v)
        h = H[(bmin > 0.02) & np.isfinite(H)]
        skew = np.mean((h - h.mean()) ** 3) / h.std() ** 3
        assert abs(h.mean()) > 0.3 * h.std(), (kind, h.mean(), h.std())
        assert abs(skew) > 0.2, (kind, skew)
        grid = Grid.from_box((0, 0, 0), (1, 1, 1), samples_per_axis=60)
        tp = polygonise(TPMSField(kind, cell_size=1.0).sample_grid, grid, caps=False)
        ht, _ = field_curvatures(TPMSField(kind, cell_size=1.0), tp.vertices, project=True)
        ht = ht[np.isfinite(ht)]
        assert abs(np.median(ht)) < 0.05 * ht.std() and abs(ht.max() + ht.min()) < 0.05 * ht.max()


def test_tis_curvature_matches_finite_differences():
    from porecad.maps.tis_mesh import tis_curvatures
    pts, tets = two_tetrahedra(10.0)
    rng = np.random.default_rng(5)
    w = rng.dirichlet(np.ones(4) * 3, 20)
    q = np.einsum("ij,jk->ik", w, pts[tets[1]])
    H, K, _ = tis_curvatures(pts, tets, "G", 1.0, q)
    # finite differences of the field through the locator
    loc = TetLocator(pts, tets)
    colors = rainbow_coloring(tets)
    slots = colors[tets]

    def phi(x):
        return tis_field_values(loc, slots, np.ones((2, 4)), "G", x)[0]

    h = 1e-3
    e = np.eye(3) * h
    g = np.stack([(phi(q + e[i]) - phi(q - e[i])) / (2 * h) for i in range(3)], axis=1)
    Hs = np.zeros((len(q), 3, 3))
    for i in range(3):
        for j in range(3):
            Hs[:, i, j] = (phi(q + e[i] + e[j]) - phi(q + e[i] - e[j]) - phi(q - e[i] + e[j])
                           + phi(q - e[i] - e[j])) / (4 * h * h)
    from porecad.analysis.curvature import implicit_curvatures
    Hf, Kf = implicit_curvatures(-g, -Hs)
    assert np.allclose(H, Hf, rtol=1e-3, atol=1e-5)
    assert np.allclose(K, Kf, rtol=1e-3, atol=1e-6)
