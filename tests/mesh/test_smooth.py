"""Tests of porecad.mesh.smooth and porecad.mesh.decimate."""

import numpy as np
import pytest
import trimesh

from porecad.errors import InputError, MeshError
from porecad.mesh.decimate import decimate
from porecad.mesh.smooth import laplacian_smooth, taubin_smooth, umbrella_matrix
from porecad.mesh.topology import edge_topology
from porecad.mesh.validate import check_solid


def noisy_sphere(subdivisions=4, noise=0.03, seed=0):
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(m.vertices)
    r = 1.0 + noise * np.random.default_rng(seed).standard_normal(len(v))
    return v * r[:, None], np.asarray(m.faces, dtype=np.int64)


def roughness(v):
    """Relative spread of the distances to the centroid."""
    r = np.linalg.norm(v - v.mean(axis=0), axis=1)
    return r.std() / r.mean()


def test_umbrella_matrix_rows():
    v, f = noisy_sphere(1)
    w = umbrella_matrix(f, len(v))
    assert np.allclose(np.asarray(w.sum(axis=1)).ravel(), 1.0)
    # vertex 0 of an icosphere has 5 neighbours
    assert w[0].nnz == 5 and np.allclose(w[0].data, 0.2)


@pytest.mark.parametrize("smoother, factor", [(laplacian_smooth, 0.25), (taubin_smooth, 0.5)])
def test_smoothing_reduces_roughness_and_keeps_topology(smoother, factor):
    v, f = noisy_sphere()
    before = roughness(v)
    f0, v0 = f.copy(), v.copy()
    out = smoother(v, f, iterations=10)
    assert roughness(out) < factor * before
    assert np.array_equal(v, v0) and np.array_equal(f, f0)  # inputs untouched
    r = check_solid(out, f)
    assert r["closed"] and r["manifold"] and r["oriented"] and r["outward"]
    assert r["self_intersections"] == 0


def test_taubin_shrinks_less_than_laplacian():
    v, f = noisy_sphere()
    vol0 = check_solid(v, f, check_self_intersections=False)["volume"]
    lap = check_solid(laplacian_smooth(v, f, 20), f, check_self_intersections=False)["volume"]
    tau = check_solid(taubin_smooth(v, f, 20), f, check_self_intersections=False)["volume"]
    assert lap < 0.95 * vol0
    assert abs(tau - vol0) < 0.25 * abs(lap - vol0)


def test_single_laplacian_step_formula():
    v, f = noisy_sphere(1)
    w = umbrella_matrix(f, len(v))
    expected = v + 0.3 * (w @ v - v)
    assert np.allclose(laplacian_smooth(v, f, iterations=1, lam=0.3), expected)
    assert np.array_equal(laplacian_smooth(v, f, iterations=0), v)


def test_fixed_vertices_do_not_move():
    v, f = noisy_sphere(3)
    fixed = v[:, 2] > 0.5  # a "cap"
    for out in (laplacian_smooth(v, f, 5, fixed=fixed), taubin_smooth(v, f, 5, fixed=fixed)):
        assert np.array_equal(out[fixed], v[fixed])
        assert not np.allclose(out[~fixed], v[~fixed])


def test_isolated_vertex_stays():
    v, f = noisy_sphere(1)
    v = np.vstack([v, [[5.0, 5.0, 5.0]]])
    assert np.array_equal(laplacian_smooth(v, f)[-1], [5.0, 5.0, 5.0])


def test_bad_parameters():
    v, f = noisy_sphere(1)
    with pytest.raises(InputError):
        laplacian_smooth(v, f, lam=1.5)
    with pytest.raises(InputError):
        taubin_smooth(v, f, lam=0.5, mu=-0.4)  # |mu| must exceed lam
    with pytest.raises(InputError):
        laplacian_smooth(v, f, fixed=np.zeros(3, bool))
    with pytest.raises(InputError):
        laplacian_smooth(v, f, iterations=-1)


# ------------------------------------------------------------------ decimation


def test_decimate_sphere_stays_closed_manifold():
    m = trimesh.creation.icosphere(subdivisions=5)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    dv, df = decimate(v, f, 1e-3)
    assert 100 < len(df) < 0.5 * len(f)
    r = check_solid(dv, df)
    assert r["closed"] and r["manifold"] and r["oriented"] and r["outward"]
    assert r["self_intersections"] == 0
    assert r["volume"] == pytest.approx(m.volume, rel=5e-3)
    # vertices of the result are a subset of the input's
    assert np.abs(np.linalg.norm(dv, axis=1) - 1.0).max() < 1e-9


def test_decimate_to_target_faces():
    m = trimesh.creation.icosphere(subdivisions=4)
    dv, df = decimate(m.vertices, m.faces, target_faces=500)
    assert 200 < len(df) <= 500
    t = edge_topology(df)
    assert t["closed"] and t["manifold"] and t["oriented"]


def test_decimate_rejects_open_mesh():
    m = trimesh.creation.icosphere(subdivisions=2)
    with pytest.raises(MeshError, match="NotManifold"):
        decimate(m.vertices, m.faces[1:], 1e-3)
    with pytest.raises(InputError):
        decimate(m.vertices, m.faces)
