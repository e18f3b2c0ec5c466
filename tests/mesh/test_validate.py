"""Tests of porecad.mesh.validate."""

import numpy as np
import pytest
import trimesh
from scipy.optimize import linprog

from porecad.errors import InputError
from porecad.mesh.topology import edge_topology
from porecad.mesh.validate import (
    check_solid,
    self_intersections,
    signed_volume,
    surface_area,
)


def sphere(subdivisions=3, radius=1.0, center=(0.0, 0.0, 0.0)):
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + center, np.asarray(m.faces, dtype=np.int64)


def concat(*meshes):
    vs, fs, n = [], [], 0
    for v, f in meshes:
        vs.append(v)
        fs.append(f + n)
        n += len(v)
    return np.vstack(vs), np.vstack(fs)


TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def bowtie():
    """Two unit tetrahedra meeting only at vertex 3 = (0, 0, 1)."""
    v = np.vstack([TET_V, TET_V[1:] + (0, 0, 1)])
    f = np.vstack([TET_F, np.where(TET_F == 0, 3, TET_F + 3)])
    return v, f


# --------------------------------------------------------------- topology


def test_icosphere_is_a_valid_solid():
    v, f = sphere(3)
    r = check_solid(v, f)
    assert r["closed"] and r["manifold"] and r["oriented"] and r["outward"]
    assert r["self_intersections"] == 0
    assert r["euler"] == 2
    m = trimesh.Trimesh(v, f, process=False)
    assert r["volume"] == pytest.approx(m.volume, rel=1e-12)
    assert r["area"] == pytest.approx(m.area, rel=1e-12)


def test_removed_face_is_not_closed():
    v, f = sphere(2)
    t = edge_topology(f[1:])
    assert not t["closed"] and not t["manifold"]
    assert t["boundary_edges"] == 3
    assert t["oriented"]  # an open mesh can still be consistently oriented


def test_flipped_face_is_not_oriented():
    v, f = sphere(2)
    f = f.copy()
    f[7] = f[7, ::-1]
    t = edge_topology(f)
    assert t["closed"] and t["manifold"]
    assert not t["oriented"]
    assert t["misoriented_edges"] == 3


def test_all_flipped_is_inside_out():
    v, f = sphere(2)
    r = check_solid(v, f[:, ::-1])
    assert r["closed"] and r["manifold"] and r["oriented"]
    assert not r["outward"]
    assert r["volume"] < 0


def test_bowtie_vertex_is_not_manifold():
    v, f = bowtie()
    t = edge_topology(f)
    assert t["closed"] and t["oriented"]
    assert t["boundary_edges"] == 0 and t["nonmanifold_edges"] == 0
    assert t["nonmanifold_vertices"] == 1
    assert not t["manifold"]


def test_edge_shared_by_three_faces():
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    t = edge_topology(f)
    assert t["nonmanifold_edges"] == 1
    assert not t["manifold"] and not t["oriented"]


def test_degenerate_face():
    v, f = sphere(1)
    f = np.vstack([f, [[0, 0, 1]]])
    t = edge_topology(f)
    assert t["degenerate_faces"] == 1 and t["closed"] and not t["manifold"]


def test_bad_input():
    with pytest.raises(InputError):
        edge_topology(np.zeros((3, 4), int))
    with pytest.raises(InputError):
        check_solid(np.zeros((3, 3)), np.array([[0, 1, 5]]))
    with pytest.raises(InputError):
        signed_volume(np.full((3, 3), np.nan), np.array([[0, 1, 2]]))


# --------------------------------------------------------------- measures


def test_volume_area_of_a_far_box():
    m = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    v = np.asarray(m.vertices) + 1e7  # far from the origin
    assert signed_volume(v, m.faces) == pytest.approx(6.0, rel=1e-9)
    assert surface_area(v, m.faces) == pytest.approx(22.0, rel=1e-9)


# --------------------------------------------------------------- self-intersections


def test_overlapping_spheres_intersect():
    a = sphere(3)
    b = sphere(3, center=(1.0, 0.3, 0.1))
    v, f = concat(a, b)
    pairs, n = self_intersections(v, f, max_report=10**6)
    assert n > 0 and len(pairs) == n
    nf = len(a[1])
    # every reported pair has one face of each sphere, i < j, no duplicates
    assert np.all(pairs[:, 0] < nf) and np.all(pairs[:, 1] >= nf)
    assert len(np.unique(pairs, axis=0)) == n
    few, n2 = self_intersections(v, f, max_report=5)
    assert n2 == n and few.shape == (5, 2)
    assert check_solid(v, f)["self_intersections"] == n


def test_separate_spheres_do_not_intersect():
    v, f = concat(sphere(3), sphere(3, center=(2.5, 0, 0)))
    assert self_intersections(v, f)[1] == 0


def test_overlapping_tetrahedra():
    v, f = concat((TET_V, TET_F), (TET_V + 0.2, TET_F))
    pairs, n = self_intersections(v, f)
    assert n > 0
    assert np.all(pairs[:, 0] < 4) and np.all(pairs[:, 1] >= 4)


def test_tetrahedra_touching_at_shared_vertex_only():
    # bowtie: the two tetrahedra meet only at the shared vertex
    v, f = bowtie()
    assert self_intersections(v, f)[1] == 0
    # push the second one down so it pokes into the first: faces sharing
    # vertex 3 now cross each other
    v[4:] -= (0, 0, 0.6)
    v[4:, :2] *= 0.5
    assert self_intersections(v, f)[1] > 0


def test_fold_along_shared_edge():
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 0.5, 0]], float)
    f = np.array([[0, 1, 2], [1, 0, 3]])
    pairs, n = self_intersections(v, f)  # 3 folded onto the same side as 2
    assert n == 1 and pairs.tolist() == [[0, 1]]
    v[3] = (0.5, -0.5, 0)  # unfolded, flat
    assert self_intersections(v, f)[1] == 0
    v[3] = (0.5, 0.5, 0.1)  # nearly folded but not coplanar: touch along the edge only
    assert self_intersections(v, f)[1] == 0


def test_fold_in_grid():
    # 3x3 grid, centre vertex dragged past its right neighbour: its fan folds
    # over the neighbouring triangles
    x, y = np.meshgrid(np.arange(3.0), np.arange(3.0), indexing="ij")
    v = np.c_[x.ravel(), y.ravel(), np.zeros(9)]
    idx = np.arange(9).reshape(3, 3)
    f = []
    for i in range(2):
        for j in range(2):
            a, b, c, d = idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]
            f += [[a, b, c], [a, c, d]]
    f = np.array(f)
    assert self_intersections(v, f)[1] == 0
    v[4, 0] = 2.6
    assert self_intersections(v, f)[1] > 0


def test_duplicate_face():
    v, f = sphere(1)
    assert self_intersections(v, np.vstack([f, f[:1]]))[1] == 1


def _lp_intersect(p, q):
    """Independent oracle: is there a common point of the two triangles?"""
    a_eq = np.zeros((5, 6))
    a_eq[:3, :3] = p.T
    a_eq[:3, 3:] = -q.T
    a_eq[3, :3] = 1
    a_eq[4, 3:] = 1
    r = linprog(np.zeros(6), A_eq=a_eq, b_eq=[0, 0, 0, 1, 1], bounds=[(0, None)] * 6, method="highs")
    return r.status == 0


def test_triangle_pairs_against_linear_programming():
    rng = np.random.default_rng(1)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    hits = 0
    for k in range(300):
        p, q = rng.random((3, 3)), rng.random((3, 3))
        if k % 3 == 0:  # coplanar pairs
            p[:, 2] = q[:, 2] = 0.25
        expected = _lp_intersect(p, q)
        got = self_intersections(np.vstack([p, q]), f)[1] == 1
        assert got == expected, k
        hits += expected
    assert 50 < hits < 250  # both outcomes exercised


def test_broad_phase_independent_of_cell_size():
    rng = np.random.default_rng(2)
    centres = rng.random((400, 3))
    v = np.repeat(centres, 3, axis=0) + 0.04 * rng.standard_normal((1200, 3))
    f = np.arange(1200).reshape(-1, 3)
    ref = self_intersections(v, f, max_report=10**6, cell_factor=1e6)  # one cell: all pairs
    assert ref[1] > 20
    for cf in (0.3, 1.0, 2.0, 5.0):
        pairs, n = self_intersections(v, f, max_report=10**6, cell_factor=cf)
        assert n == ref[1]
        assert np.array_equal(pairs, ref[0])


def test_high_valence_vertices():
    # cone: apex and base centre each have 100 faces (sorting path of the fan count)
    c = trimesh.creation.cone(radius=1.0, height=1.0, sections=100)
    v, f = np.asarray(c.vertices), np.asarray(c.faces)
    t = edge_topology(f)
    assert t["closed"] and t["manifold"] and t["oriented"]
    # glue a mirrored copy at the apex: one vertex with two fans
    apex = int(np.argmax(v[:, 2]))
    f2 = f[:, ::-1] + len(v)
    f2[f2 == apex + len(v)] = apex
    t = edge_topology(np.vstack([f, f2]))
    assert t["nonmanifold_vertices"] == 1 and t["nonmanifold_edges"] == 0
    assert t["closed"] and t["oriented"] and not t["manifold"]


def test_marching_cubes_patches_never_fold():
    """Every cube case, random corner magnitudes: the cube's surface patch has no self-intersection.

    Loops of 5+ vertices through an ambiguous face used to be strip-triangulated
    and folded through themselves for some edge parameters (found on the femur
    where the body crease meets the lattice); they are now stars around a
    centre vertex.
    """
    from porecad.mesh.polygonise import Grid, polygonise
    from porecad.mesh.validate import self_intersections

    rng = np.random.default_rng(7)
    grid = Grid((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (2, 2, 2))
    folded = 0
    for case in range(1, 255):
        signs = np.array([-1.0 if (case >> c) & 1 else 1.0 for c in range(8)])
        for _ in range(12):  # 12 magnitude draws per case (40 found nothing more; 3,048 cubes in ~30 s)
            mags = rng.uniform(1e-3, 1.0, 8) ** 3
            vals = signs * mags
            cube = np.empty((2, 2, 2), dtype=np.float32)   # [z, y, x]
            for c in range(8):
                cube[(c >> 2) & 1, (c >> 1) & 1, c & 1] = vals[c]
            res = polygonise(lambda xs, ys, zs, cube=cube: cube[: len(zs)], grid, caps=False)
            folded += self_intersections(res.vertices, res.faces, max_report=0)[1] > 0
    assert folded == 0


def test_bounds_and_checked_topology_match_numpy():
    """The one-pass bounds and the topology of checked faces agree with numpy and with edge_topology."""
    from porecad.mesh.topology import edge_topology, topology_of_checked
    from porecad.mesh.validate import bounds, check_solid
    rng = np.random.default_rng(3)
    v = rng.normal(size=(1000, 3)) * [1, 100, 1e-3] - [5, 0, 7]
    lo, hi = bounds(v)
    assert np.array_equal(lo, v.min(axis=0)) and np.array_equal(hi, v.max(axis=0))
    f = rng.integers(0, 1000, (3000, 3)).astype(np.int32)
    f[:7, 1] = f[:7, 0]         # degenerate faces, left out of the other counts
    for faces in (f, f.astype(np.int64), f[7:]):
        assert topology_of_checked(np.ascontiguousarray(faces)) == edge_topology(faces)
    n_deg = int(np.count_nonzero((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])))
    assert n_deg >= 7 and edge_topology(f)["degenerate_faces"] == n_deg
    rep = check_solid(v, f[7:], check_self_intersections=False)
    assert rep["bounds"] == [v.min(axis=0).tolist(), v.max(axis=0).tolist()]
