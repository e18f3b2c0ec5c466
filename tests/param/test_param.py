"""Hexahedral parameterisation of closed bodies (porecad.param; 000 ch.3): heat geodesics, cube edges, grids."""

import numpy as np
import pytest
import trimesh

from porecad import datasets
from porecad.errors import InputError
from porecad.param import (
    CUBE,
    CUBE_EDGES,
    HeatGeodesics,
    choose_corners,
    cotangent_laplacian,
    cube_edges,
    descent_path,
    dijkstra_path,
    edge_graph,
    grid_to_hexes,
    hex_parameterisation,
    mass_matrix,
    scaled_jacobian,
    surface_patches,
)

BOX = (2.0, 3.0, 5.0)  # x shortest → u, y → v, z longest → w


def _mesh(m):
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def _fine(m, edge):
    v, f = trimesh.remesh.subdivide_to_size(m.vertices, m.faces, max_edge=edge)
    return _mesh(trimesh.Trimesh(v, f))  # merges the duplicated vertices


@pytest.fixture(scope="module")
def box():
    return _fine(trimesh.creation.box(BOX), 0.25)


@pytest.fixture(scope="module")
def sphere():
    return _mesh(trimesh.creation.icosphere(4, radius=1.0))


def _box_corner_positions():
    return (CUBE - 0.5) * np.array(BOX)


# ----------------------------------------------------------------------------------------- heat method


def test_cotangent_laplacian_and_mass(sphere):
    v, f = sphere
    L = cotangent_laplacian(v, f)
    assert abs(L - L.T).max() < 1e-12
    assert np.abs(np.asarray(L.sum(axis=1))).max() < 1e-10
    A = mass_matrix(v, f)
    assert A.sum() == pytest.approx(trimesh.Trimesh(v, f).area, rel=1e-12)
    # on the unit sphere L x = −2 H n A (n outward, H = 1): −L x / A is twice the outward normal
    hn = -(L @ v) / A[:, None]
    mag = np.linalg.norm(hn, axis=1)
    assert np.average(mag, weights=A) == pytest.approx(2.0, rel=0.01)
    assert np.all(np.abs(mag - 2.0) < 0.3)  # barycentric areas are coarse at the 12 valence-5 vertices
    assert np.all(np.einsum("ij,ij->i", hn, v) > 0)


def test_heat_distance_matches_great_circles(sphere):
    v, f = sphere
    heat = HeatGeodesics(v, f)
    assert heat.t == pytest.approx(heat.h ** 2)
    for s in (0, 1234):  # one factorisation, several sources
        d = heat.distance(s)
        exact = np.arccos(np.clip(v @ v[s], -1.0, 1.0))
        assert d[s] == 0.0
        assert np.abs(d - exact).max() < 0.05


def test_descent_path_strictly_decreases(sphere):
    v, f = sphere
    heat = HeatGeodesics(v, f)
    src, dst = 0, int(np.argmin(v @ v[0]))
    d = heat.distance(src)
    for step in ("smallest", "steepest"):
        path, fb = descent_path(d, heat.graph, dst, src, return_fallback=True, step=step)
        assert path[0] == dst and path[-1] == src and not fb
        assert np.all(np.diff(d[path]) < 0)
        assert np.all(np.asarray(heat.graph[path[:-1], path[1:]]).ravel() > 0)  # along mesh edges
        length = np.linalg.norm(np.diff(v[path], axis=0), axis=1).sum()
        assert np.pi <= length < 1.2 * np.pi


def test_descent_path_falls_back_to_dijkstra(sphere):
    v, f = sphere
    g = edge_graph(v, f)
    src, dst = 0, int(np.argmin(v @ v[0]))
    d = np.arccos(np.clip(v @ v[src], -1.0, 1.0))
    ring = g.indices[g.indptr[dst]:g.indptr[dst + 1]]
    d[ring] = 10.0  # the destination becomes a local minimum
    path, fb = descent_path(d, g, dst, src, return_fallback=True)
    assert fb and path[0] == dst and path[-1] == src
    assert np.all(np.asarray(g[path[:-1], path[1:]]).ravel() > 0)
    with pytest.raises(InputError):
        descent_path(d, g, dst, src, step="sideways")


def test_heat_refuses_disconnected_meshes():
    a, b = trimesh.creation.icosphere(1), trimesh.creation.icosphere(1)
    b.apply_translation((5, 0, 0))
    with pytest.raises(InputError, match="connected parts"):
        HeatGeodesics(*_mesh(trimesh.util.concatenate([a, b])))


# ----------------------------------------------------------------------------------------- corners, edges, faces


def _rigid(v, seed=3):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return v @ q.T + rng.normal(size=3), q


def test_choose_corners_is_the_oriented_box(box):
    v, f = box
    c = choose_corners(v, f)
    p = v[c]
    # the eight corners of the box, in marching-cubes order
    assert np.allclose(p, p[0] + CUBE @ np.stack([p[1] - p[0], p[3] - p[0], p[4] - p[0]]), atol=1e-12)
    assert np.allclose(np.sort(np.abs(p), axis=0), np.sort(np.abs(_box_corner_positions()), axis=0))
    # the longest axis is w, corners 0–3 one end and 4–7 the other; k + 4 above k
    assert np.allclose(np.abs(p[4:] - p[:4])[:, 2], 5.0)
    assert np.allclose(np.linalg.norm(p[1] - p[0]), 2.0) and np.allclose(np.linalg.norm(p[3] - p[0]), 3.0)
    # right-handed (u, v, w)
    assert np.linalg.det(np.stack([p[1] - p[0], p[3] - p[0], p[4] - p[0]])) > 0
    # a rigid motion picks the same eight vertices, again as a right-handed box
    w, _ = _rigid(v)
    c2 = choose_corners(w, f)
    assert set(c2.tolist()) == set(c.tolist())
    q = w[c2]
    assert np.allclose(q, q[0] + CUBE @ np.stack([q[1] - q[0], q[3] - q[0], q[4] - q[0]]), atol=1e-9)
    assert np.linalg.det(np.stack([q[1] - q[0], q[3] - q[0], q[4] - q[0]])) > 0


def test_cube_edges_follow_the_box_edges(box):
    v, f = box
    c = choose_corners(v, f)
    paths = cube_edges(v, f, c)
    assert len(paths) == 12
    for k, (a, b) in enumerate(CUBE_EDGES):
        p = paths[k]
        assert p[0] == c[a] and p[-1] == c[b]
        seg = v[p] - v[c[a]]
        direction = (v[c[b]] - v[c[a]]) / np.linalg.norm(v[c[b]] - v[c[a]])
        off = seg - np.outer(seg @ direction, direction)
        assert np.abs(off).max() < 1e-9  # straight along the box edge
        assert np.all(np.diff(seg @ direction) > 0)
    geo = cube_edges(v, f, c, sides="geodesic")
    assert all(np.array_equal(x, y) for x, y in zip(geo, paths))


def test_surface_patches_are_the_box_faces(box):
    v, f = box
    c = choose_corners(v, f)
    lab = surface_patches(v, f, cube_edges(v, f, c))
    assert lab.shape == (len(f),) and set(lab) == set(range(6))
    p = v[c]
    u, vv, w = (p[1] - p[0]) / 2.0, (p[3] - p[0]) / 3.0, (p[4] - p[0]) / 5.0
    outward = {0: -w, 1: w, 2: -vv, 3: u, 4: vv, 5: -u}
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    for fc, d in outward.items():
        assert np.allclose(n[lab == fc] @ d, 1.0)


def test_folded_corner_choices_are_refused(box):
    v, f = box
    c = choose_corners(v, f)
    mirrored = c[[0, 3, 2, 1, 4, 7, 6, 5]]  # left-handed: every face lies on the wrong side of its edges
    with pytest.raises(InputError, match=r"folds face f\d") as err:
        cube_edges(v, f, mirrored)
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match=r"folds face f\d"):
        hex_parameterisation(v, f, (2, 3, 5), corners=mirrored)
    # corner 1 halfway up the vertical edge 0–4: edge e8 runs through it
    mid = int(np.argmin(np.linalg.norm(v - (v[c[0]] + v[c[4]]) / 2, axis=1)))
    moved = c.copy()
    moved[1] = mid
    with pytest.raises(InputError, match="corner"):
        cube_edges(v, f, moved, sides="geodesic")
    with pytest.raises(InputError, match="corners 2 and 3 are the same vertex"):
        cube_edges(v, f, c[[0, 1, 2, 2, 4, 5, 6, 7]])


def test_surface_patches_refuses_touching_paths(box):
    v, f = box
    c = choose_corners(v, f)
    paths = cube_edges(v, f, c)
    # reroute e1 (1 → 2) back along e0 to its middle vertex, then on to corner 2
    e0 = paths[0]
    mid = len(e0) // 2
    tail = dijkstra_path(edge_graph(v, f), int(c[2]), int(e0[mid]))[::-1]  # e0[mid] → corner 2
    bad = list(paths)
    bad[1] = np.concatenate([e0[::-1][:len(e0) - mid], tail[1:]])
    assert bad[1][0] == c[1] and bad[1][-1] == c[2] and len(np.unique(bad[1])) == len(bad[1])
    with pytest.raises(InputError, match="touch or cross"):
        surface_patches(v, f, bad)
    with pytest.raises(InputError, match="not a mesh edge"):
        surface_patches(v, f, paths[:11] + [np.array([c[3], c[7]])])


def test_bad_inputs_are_refused(box):
    v, f = box
    with pytest.raises(InputError, match="not a closed manifold"):
        hex_parameterisation(v, f[1:], (2, 2, 2))
    for grid in ((2, 2), (0, 2, 2), (2, 2.5, 2), "abc"):
        with pytest.raises(InputError, match="grid"):
            hex_parameterisation(v, f, grid)
    with pytest.raises(InputError, match="8 vertex indices"):
        hex_parameterisation(v, f, (2, 2, 2), corners=[0, 1, 2])
    with pytest.raises(InputError, match="weights"):
        hex_parameterisation(v, f, (2, 2, 2), weights="uniform")


# ----------------------------------------------------------------------------------------- hexes and quality


def _unit_grid(n=(2, 3, 4)):
    axes = [np.linspace(0.0, 1.0, k + 1) for k in n]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def test_grid_to_hexes_vtk_order():
    nodes = _unit_grid()
    pts, hexes = grid_to_hexes(nodes)
    assert pts.shape == (3 * 4 * 5, 3) and hexes.shape == (24, 8) and hexes.dtype == np.int64
    assert np.allclose(pts[hexes[0]], CUBE * np.array([0.5, 1 / 3, 0.25]))
    sj = scaled_jacobian(pts, hexes)
    assert np.allclose(sj, 1.0)
    mirrored = pts * np.array([-1.0, 1.0, 1.0])
    assert np.allclose(scaled_jacobian(mirrored, hexes), -1.0)
    sheared = pts.copy()
    sheared[:, 0] += sheared[:, 2]  # shear 45°: corner Jacobian cos 45°
    assert np.allclose(scaled_jacobian(sheared, hexes), np.sqrt(0.5))
    with pytest.raises(InputError):
        grid_to_hexes(nodes[..., :2])


# ----------------------------------------------------------------------------------------- parameterisations


def test_box_reproduces_the_regular_grid(box):
    v, f = box
    grid = (4, 6, 10)
    nodes, info = hex_parameterisation(v, f, grid)
    assert nodes.shape == (5, 7, 11, 3)
    p = v[info.corners]
    origin, axes = p[0], np.stack([p[1] - p[0], p[3] - p[0], p[4] - p[0]])
    exact = origin + _unit_grid(grid) @ axes
    assert np.abs(nodes - exact).max() < 1e-3
    assert info.corner_choice == "box"
    assert info.min_scaled_jacobian > 0.999 and info.fraction_below_poor == 0.0
    assert info.nodes == 5 * 7 * 11 and info.hexes == 240 and info.interior_nodes == 3 * 5 * 9
    assert set(info.times) >= {"geodesics", "patches", "surface_grid", "volume", "total"}


def test_box_with_few_triangles_is_subdivided():
    v, f = _mesh(trimesh.creation.box(BOX))
    nodes, info = hex_parameterisation(v, f, (2, 3, 5))
    assert info.subdivisions >= 1 and len(info.faces) > 12
    assert np.array_equal(info.vertices[:8], v)  # input vertex indices stay valid
    p = v[info.corners]
    exact = p[0] + _unit_grid((2, 3, 5)) @ np.stack([p[1] - p[0], p[3] - p[0], p[4] - p[0]])
    assert np.abs(nodes - exact).max() < 1e-9


def test_cylinder_grid_is_valid_and_on_the_surface():
    v, f = _fine(trimesh.creation.cylinder(radius=1.0, height=4.0, sections=48), 0.15)
    nodes, info = hex_parameterisation(v, f, (4, 4, 8))
    assert info.min_scaled_jacobian > 0
    # the six boundary slices lie on the (faceted) cylinder
    bnd = np.concatenate([nodes[[0, -1]].reshape(-1, 3), nodes[:, [0, -1]].reshape(-1, 3),
                          nodes[:, :, [0, -1]].reshape(-1, 3)])
    r, z = np.hypot(bnd[:, 0], bnd[:, 1]), bnd[:, 2]
    on_side = (r > np.cos(np.pi / 48) - 1e-9) & (r < 1 + 1e-9)
    on_cap = np.isclose(np.abs(z), 2.0) & (r < 1 + 1e-9)
    assert np.all(on_side | on_cap)
    inner = nodes[1:-1, 1:-1, 1:-1].reshape(-1, 3)
    assert np.all(np.hypot(inner[:, 0], inner[:, 1]) < 1) and np.all(np.abs(inner[:, 2]) < 2)
    # shared cube edges: the patch grids meet exactly (nodes are unique points)
    pts, hexes = grid_to_hexes(nodes)
    assert len(np.unique(np.round(pts, 9), axis=0)) == len(pts)


def test_mean_value_weights_also_work(sphere):
    v, f = sphere
    nodes, info = hex_parameterisation(v, f, (3, 3, 3), weights="mean-value")
    assert info.patch_maps == ["mean-value"] * 6
    assert info.min_scaled_jacobian > 0
    bnd = nodes[[0, -1]].reshape(-1, 3)
    assert np.all(np.linalg.norm(bnd, axis=1) <= 1 + 1e-9) and np.all(np.linalg.norm(bnd, axis=1) > 0.99)


def _hex_volume(pts, hexes):
    """Total volume of VTK hexahedra split into six tetrahedra around the diagonal 0–6."""
    vol = 0.0
    for a, b, c in ((1, 2, 6), (2, 3, 6), (3, 7, 6), (7, 4, 6), (4, 5, 6), (5, 1, 6)):
        e = pts[hexes[:, [a, b, c]]] - pts[hexes[:, 0]][:, None, :]
        vol += np.linalg.det(e).sum() / 6.0
    return vol


def test_hex_volume_helper():
    pts, hexes = grid_to_hexes(_unit_grid())
    assert _hex_volume(pts, hexes) == pytest.approx(1.0)


@pytest.fixture(scope="module")
def femur(femur_path):
    from porecad.bodies import load_body

    v, f, _ = load_body(femur_path)
    return v, f


@pytest.mark.parametrize("grid", [(5, 7, 20), (5, 10, 60)])
def test_femur_grids_have_positive_jacobians(femur, grid):
    v, f = femur
    nodes, info = hex_parameterisation(v, f, grid)
    assert nodes.shape == tuple(n + 1 for n in grid) + (3,)
    assert info.min_scaled_jacobian > 0
    pts, hexes = grid_to_hexes(nodes)
    assert np.all(scaled_jacobian(pts, hexes) > 0)
    # and the trilinear map does not fold inside any cell (positive corners alone do not ensure it)
    from porecad.maps.hexmesh import sampled_jacobians

    assert info.min_scaled_jacobian_inside > 0
    inside = sampled_jacobians(nodes)  # fine resampling of suspect cells
    assert inside.min() > 0
    assert 0.0 <= info.fraction_below_poor < 0.2
    # (times are reported by bench/hex.py, not asserted here)
    # the boundary nodes lie on the body: within the mesh's bounding box and near a vertex or facet
    lo, hi = v.min(0) - 1e-6, v.max(0) + 1e-6
    assert np.all((pts >= lo) & (pts <= hi))
    # the parameterisation maps the whole body: the hexahedra fill its volume
    assert _hex_volume(pts, hexes) == pytest.approx(trimesh.Trimesh(v, f).volume, rel=0.15)


def test_straighten_folded_unfolds_a_curved_element_and_keeps_the_rest():
    """A mid-edge node pushed across its element folds the 20-node map; straightening unfolds it.

    The corner nodes never move, elements far from the fold keep their nodes,
    and a fully straightened element is its (valid) trilinear corner cell.
    """
    from porecad.param.grid_untangle import element_quality
    from porecad.param.half_grid import straighten_folded

    s = np.linspace(0.0, 1.0, 9)
    g = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1)
    g = g + 0.03 * np.sin(3.0 * g[..., ::-1])  # a smooth, valid, curved half-step grid of 4x4x4 elements
    sj, si = element_quality(g, "hex20")
    assert min(sj.min(), si.min()) > 0
    bad = g.copy()
    bad[3, 4, 4] += 1.2 * (g[4, 6, 4] - g[4, 2, 4])  # the mid-edge node of u-edge (2..4, 4, 4) across 2 cells
    sj, si = element_quality(bad, "hex20")
    q = np.minimum(sj, si)
    assert q.min() <= 0
    out, info = straighten_folded(bad)
    sj2, si2 = element_quality(out, "hex20")
    assert min(sj2.min(), si2.min()) > 0 and info["quality"] > 0
    assert 1 <= info["elements"] <= 8 and 0 < info["max_blend"] <= 1.0
    np.testing.assert_array_equal(out[::2, ::2, ::2], bad[::2, ::2, ::2])
    moved = np.linalg.norm(out - bad, axis=-1) > 0
    assert moved[3, 4, 4] and not moved[6:, 6:, :].any() and not moved[:, :, :2].any()
    # a grid whose corner cells fold cannot be straightened: the quality says so
    inv = g.copy()
    inv[4, 4, 4] = g[8, 8, 8] + 0.5
    _, info = straighten_folded(inv)
    assert info["quality"] is None and info["corner_cells_fold"]


def test_cube_map_refuses_handles_and_separate_parts_by_their_topology():
    torus = trimesh.creation.torus(10.0, 3.0)
    with pytest.raises(InputError, match="genus 1"):
        hex_parameterisation(torus.vertices, torus.faces, grid=(4, 4, 4))
    two = trimesh.util.concatenate([trimesh.creation.icosphere(), trimesh.creation.icosphere().apply_translation([5, 0, 0])])
    with pytest.raises(InputError, match="2 separate parts"):
        hex_parameterisation(two.vertices, two.faces, grid=(4, 4, 4))


def test_weighted_laplace_keeps_an_affine_grid_and_spacing_reads_the_cells():
    """Both weightings of the discrete Laplace equation reproduce the affine map of a box (its solution for any
    constant axis weights); ``axis_spacing`` reads the box's cell sides."""
    from porecad.param.patch_maps import axis_spacing, laplace_volume
    n = (4, 5, 9)
    s = [np.linspace(0.0, 1.0, k + 1) for k in n]
    U = np.stack(np.meshgrid(*s, indexing="ij"), axis=-1)
    A = np.array([[10.0, 1.0, 0.0], [0.0, 6.0, 2.0], [0.0, 0.0, 90.0]])
    exact = U @ A.T + np.array([1.0, -2.0, 3.0])
    start = exact.copy()
    start[1:-1, 1:-1, 1:-1] = 0.0
    h = axis_spacing(exact)
    np.testing.assert_allclose(h, np.linalg.norm(A, axis=0) / np.array(n), rtol=1e-12)
    for w in (None, 1.0 / h ** 2, 7.0 / h ** 2):  # any constant weights, at any scale
        np.testing.assert_allclose(laplace_volume(start, w), exact, atol=1e-9)


def test_long_bone_gets_a_valid_8x8x8_grid_from_the_proportional_laplace_grid():
    """Issue 20, acceptance 1: with equal axis weights the Laplace grid of a long curved bone at 8×8×8 folds 100
    of its 512 cells and the untangling stalls (15 inverted cells in 68 s); weighted by the body's proportions
    (the box's Laplace equation, not the cube's) 3-4 fold, and the untangled grid is valid in seconds."""
    v, f = datasets.curved_bone(8000)
    nodes, info = hex_parameterisation(v, f, (8, 8, 8))
    assert info.min_scaled_jacobian > 0 and info.min_scaled_jacobian_inside > 0
    folded = {g["choice"]: g["folded_elements"] for g in info.laplace_grids}
    pairs = [(folded[c], folded[c + ", proportional"]) for c in folded if c + ", proportional" in folded]
    assert pairs and all(p < e for e, p in pairs)  # fewer folded cells for every corner choice tried
    assert info.corner_choice.endswith(", proportional")


@pytest.mark.parametrize("grid", [(8, 8, 8), (6, 6, 12)])
def test_femur_with_few_cells_along_it_is_valid(femur, grid):
    """Issue 20, acceptance 1: long cells on the femur. At these grids the mesh, subdivided for the mean cell,
    left the corner-end corridors of some side edges without a path ("no corner choice"); the corner choices
    are then tried again on a mesh subdivided once more."""
    v, f = femur
    nodes, info = hex_parameterisation(v, f, grid)
    assert nodes.shape == tuple(n + 1 for n in grid) + (3,)
    assert info.min_scaled_jacobian > 0 and info.min_scaled_jacobian_inside > 0


def test_stretch_balancing_gives_a_squeezed_protrusion_room_and_keeps_the_map_one_to_one():
    """A harmonic patch map squeezes a tall bump near a corner (an ear) into a sliver of the square; stretch
    balancing (Yoshizawa, Belyaev & Seidel 2004) gives it a share of the square closer to its share of the area,
    lowers the largest stretch, and stays one-to-one (positive weights, convex boundary)."""
    from porecad.param.patch_maps import _signed_areas, harmonic_map, vertex_stretch
    n = 41
    s = np.linspace(0.0, 1.0, n)
    X, Y = np.meshgrid(s, s, indexing="ij")
    Z = 1.5 * np.exp(-((X - 0.78) ** 2 + (Y - 0.78) ** 2) / 0.004)
    x = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tri = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    bnd = np.unique(np.concatenate([idx[0], idx[-1], idx[:, 0], idx[:, -1]]))
    area3 = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
    bump = Z.ravel()[tri].mean(axis=1) > 0.3
    share3 = area3[bump].sum() / area3.sum()
    shares, peaks = [], []
    for rounds in (0, 2):
        uv = harmonic_map(x, tri, bnd, x[bnd, :2], "cotangent", balance=rounds)
        a2 = _signed_areas(uv, tri)
        assert np.all(a2 > 0)                                  # one-to-one: no triangle flips
        assert np.allclose(uv[bnd], x[bnd, :2])                # the boundary stays where it was put
        shares.append(a2[bump].sum() / a2.sum())
        peaks.append(float(vertex_stretch(x, tri, uv).max()))
    assert shares[0] < 0.05 * share3                           # squeezed by the harmonic map (0.07 % for 23 %)
    assert shares[1] > 0.2 * share3 and peaks[1] < 0.1 * peaks[0]   # balanced twice: 8 %, stretch 67 -> 2.1
    with pytest.raises(InputError):
        harmonic_map(x, tri, bnd, x[bnd, :2], "cotangent", balance=-1)
