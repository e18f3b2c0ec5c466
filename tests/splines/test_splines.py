"""Spline layer: B-spline bases, B-spline volumes / TBSS, LSPIA, TBSS construction and mesh fits.

References are independent of the code under test where possible: scipy's
``BSpline`` (de Boor) for bases and volumes, finite differences for
derivatives, analytic volumes for primitives, explicit support sets for
local LSPIA.
"""

from pathlib import Path

import manifold3d as m3
import numpy as np
import pytest
import trimesh
from scipy.interpolate import BSpline

from porecad.errors import InputError
from porecad.splines import (TBSS, BSplineVolume, basis_functions, basis_matrix, box_tbss,
                             clamped_uniform_knots, cylinder_tbss, disc_map, disc_tbss, find_spans,
                             fit_grid, fit_grid_lstsq, fit_map, fit_tbss_to_mesh, greville,
                             local_lspia, loft_tbss, tube_tbss)

FEMUR = Path(__file__).resolve().parents[3] / "shared" / "data" / "femur.stl"


def _random_knots(rng, n, p):
    inner = np.sort(rng.uniform(0.05, 0.95, n - p - 1))
    if inner.size >= 3 and p >= 2:
        inner[1] = inner[2]                       # a repeated interior knot
    return np.concatenate([np.zeros(p + 1), inner, np.ones(p + 1)])


def _scipy_basis(knots, p, t, nu=0):
    n = len(knots) - p - 1
    out = np.zeros((len(t), n))
    for i in range(n):
        c = np.zeros(n)
        c[i] = 1.0
        out[:, i] = BSpline(knots, c, p)(t, nu=nu)
    return out


# ---------------------------------------------------------------- basis
@pytest.mark.parametrize("p", [0, 1, 2, 3, 4])
def test_basis_partition_of_unity_and_derivatives(p):
    rng = np.random.default_rng(p)
    knots = _random_knots(rng, p + 7, p)
    t = np.concatenate([rng.uniform(0, 1, 200), [0.0, 1.0]])
    spans, vals = basis_functions(knots, p, t, n_derivs=p + 1)
    assert vals.shape == (p + 2, t.size, p + 1)
    np.testing.assert_allclose(vals[0].sum(axis=1), 1.0, atol=1e-14)
    assert np.all(vals[0] >= -1e-15)
    assert np.all(vals[p + 1] == 0.0)                      # derivative of order > p
    # against de Boor (scipy), all derivative orders up to p
    for k in range(p + 1):
        dense = basis_matrix(knots, p, t, deriv=k).toarray()
        ref = _scipy_basis(knots, p, t, nu=k)
        scale = max(1.0, np.abs(ref).max())
        np.testing.assert_allclose(dense, ref, atol=1e-10 * scale)
    # each derivative against central differences of the one below, away from knots
    h = 1e-6
    tt = rng.uniform(0, 1, 100)
    tt = tt[np.min(np.abs(tt[:, None] - knots[None, :]), axis=1) > 1e-3]
    for k in range(1, p + 1):
        lo = basis_matrix(knots, p, tt - h, deriv=k - 1).toarray()
        hi = basis_matrix(knots, p, tt + h, deriv=k - 1).toarray()
        d = basis_matrix(knots, p, tt, deriv=k).toarray()
        np.testing.assert_allclose(d, (hi - lo) / (2 * h), rtol=1e-5, atol=1e-5 * max(1.0, np.abs(d).max()))


def test_basis_matrix_rows_spans_and_greville():
    knots = clamped_uniform_knots(9, 3)
    t = np.linspace(0, 1, 101)
    B = basis_matrix(knots, 3, t)
    assert B.shape == (101, 9)
    np.testing.assert_allclose(np.asarray(B.sum(axis=1)).ravel(), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(basis_matrix(knots, 3, t, deriv=1).sum(axis=1)).ravel(), 0.0,
                               atol=1e-11)
    s = find_spans(knots, 3, [0.0, 0.5, 1.0])
    assert s.tolist() == [3, 6, 8]                         # t == 1: last non-empty span
    assert B[-1, 8] == 1.0 and B[0, 0] == 1.0              # clamped ends interpolate
    # linear precision: sum_i N_i(t) g_i = t
    np.testing.assert_allclose(B @ greville(knots, 3), t, atol=1e-14)


# ---------------------------------------------------------------- volumes
def _volume_ref(ctrl, knots, degs, u, v, w, nu=(0, 0, 0)):
    out = np.zeros((len(u), ctrl.shape[3]))
    for m in range(len(u)):
        c = ctrl
        for a, t in enumerate((u[m], v[m], w[m])):
            c = BSpline(knots[a], c, degs[a], axis=0)(t, nu=nu[a])
        out[m] = c
    return out


@pytest.mark.parametrize("d", [1, 3])
def test_volume_evaluate_grid_and_derivatives_against_de_boor(d):
    rng = np.random.default_rng(10 + d)
    degs = (2, 3, 1)
    n = (5, 7, 4)
    knots = [_random_knots(rng, n[a], degs[a]) for a in range(3)]
    ctrl = rng.normal(size=n + (d,))
    vol = BSplineVolume(ctrl, degs, knots)
    u, v, w = rng.uniform(0, 1, (3, 120))
    u[:3] = [0.0, 1.0, knots[0][3]]
    v[:3] = [1.0, 0.0, knots[1][4]]
    ref = _volume_ref(ctrl, knots, degs, u, v, w)
    np.testing.assert_allclose(vol.evaluate(u, v, w), ref, atol=1e-13)
    val, du, dv, dw = vol.derivatives(u, v, w)
    np.testing.assert_allclose(val, ref, atol=1e-13)
    for got, nu in ((du, (1, 0, 0)), (dv, (0, 1, 0)), (dw, (0, 0, 1))):
        exp = _volume_ref(ctrl, knots, degs, u, v, w, nu)
        np.testing.assert_allclose(got, exp, atol=1e-10 * max(1.0, np.abs(exp).max()))
    us, vs, ws = np.sort(rng.uniform(0, 1, 6)), np.linspace(0, 1, 5), np.sort(rng.uniform(0, 1, 4))
    grid = vol.evaluate_grid(us, vs, ws)
    assert grid.shape == (6, 5, 4, d)
    U, V, W = np.meshgrid(us, vs, ws, indexing="ij")
    np.testing.assert_allclose(grid.reshape(-1, d), vol.evaluate(U, V, W), atol=1e-13)


def test_volume_input_errors():
    with pytest.raises(InputError, match="knot vector v"):
        BSplineVolume(np.zeros((4, 4, 4, 1)), 3, [None, np.linspace(0, 1, 8), None])
    with pytest.raises(InputError, match="control net"):
        BSplineVolume(np.zeros((4, 4)), 3)
    tb = box_tbss((1, 1, 1))
    with pytest.raises(InputError, match="outside the domain"):
        tb.map_points(np.array([[0.5, 1.2, 0.5]]))
    with pytest.raises(InputError, match="3-D control points"):
        TBSS(np.zeros((4, 4, 4, 2)), 3)
    with pytest.raises(InputError, match="periodic"):
        TBSS(tb.control, 3, periodic=(True, False, False))
    with pytest.raises(InputError, match="unknown face"):
        tb.boundary_points("x0", 4)


def test_map_points_matches_evaluate_on_many_points():
    rng = np.random.default_rng(3)
    tb = cylinder_tbss(5.0, 8.0)
    p = rng.uniform(0, 1, (200_000, 3))
    x = tb.map_points(p)
    assert x.shape == (200_000, 3)
    sub = rng.choice(len(p), 50, replace=False)
    ref = _volume_ref(tb.control, tb.knots, tb.degrees, p[sub, 0], p[sub, 1], p[sub, 2])
    np.testing.assert_allclose(x[sub], ref, atol=1e-12)


# ---------------------------------------------------------------- TBSS primitives
def test_box_is_exact_linear_map():
    a, b, c = 3.0, 4.0, 5.0
    tb = box_tbss((a, b, c), origin=(1, 2, 3), n_ctrl=(5, 4, 6))
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 1, (1000, 3))
    np.testing.assert_allclose(tb.map_points(p), [1, 2, 3] + p * [a, b, c], atol=1e-13)
    J = tb.jacobian(p[:, 0], p[:, 1], p[:, 2])
    np.testing.assert_allclose(J, np.broadcast_to(np.diag([a, b, c]), J.shape), atol=1e-12)
    assert tb.volume() == pytest.approx(a * b * c, rel=1e-13)
    info = tb.check_jacobian()
    assert info["min_det"] == pytest.approx(a * b * c, rel=1e-12)
    np.testing.assert_allclose(tb.bounds(), [[1, 2, 3], [1 + a, 2 + b, 3 + c]], atol=1e-12)
    np.testing.assert_allclose(tb.boundary_points("w1", 3)[..., 2], 3 + c)


def test_cylinder_round_and_positive():
    R, H = 10.0, 20.0
    tb = cylinder_tbss(R, H)
    info = tb.check_jacobian()
    assert info["min_det"] > 0.02 * info["mean_det"]
    # volume within 0.2 % of pi R^2 h; boundary radius within [0.999, 1.005] R
    assert tb.volume() == pytest.approx(np.pi * R * R * H, rel=2e-3)
    side = np.concatenate([tb.boundary_points(f, 120).reshape(-1, 3) for f in ("u0", "u1", "v0", "v1")])
    r = np.hypot(side[:, 0], side[:, 1])
    assert r.min() > 0.999 * R and r.max() < 1.005 * R
    np.testing.assert_allclose(tb.boundary_points("w0", 10)[..., 2], 0.0, atol=1e-12)


def test_tube_seam_and_volume():
    ri, ro, H = 5.0, 10.0, 20.0
    tb = tube_tbss(ri, ro, H)
    assert tb.periodic == (True, False, False)
    np.testing.assert_array_equal(tb.boundary_points("u0", 9), tb.boundary_points("u1", 9))
    info = tb.check_jacobian()
    assert info["min_det"] > 0
    assert tb.volume() == pytest.approx(np.pi * (ro ** 2 - ri ** 2) * H, rel=1e-4)
    for face, r0 in (("v0", ri), ("v1", ro)):
        pts = tb.boundary_points(face, 64).reshape(-1, 3)
        np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), r0, rtol=5e-4)


def test_disc_shape_and_volume():
    W, D, H = 50.0, 35.0, 11.0
    tb = disc_tbss(W, D, H)
    info = tb.check_jacobian()
    assert info["min_det"] > 0
    lo, hi = tb.bounds()
    np.testing.assert_allclose(hi[:2] - lo[:2], [W, D], rtol=0.01)
    # analytic volume: Gauss quadrature of det J of the analytic map (central differences)
    f = disc_map(W, D, H)
    g, gw = np.polynomial.legendre.leggauss(60)
    s, sw = 0.5 * (g + 1), 0.5 * gw
    U, V = np.meshgrid(s, s, indexing="ij")
    h = 1e-6

    def xyz(u, v, w):
        return np.stack(f(u, v, w), axis=-1)

    w = np.full_like(U, 0.5)
    Ju = (xyz(U + h, V, w) - xyz(U - h, V, w)) / (2 * h)
    Jv = (xyz(U, V + h, w) - xyz(U, V - h, w)) / (2 * h)
    Jw = (xyz(U, V, w + h) - xyz(U, V, w - h)) / (2 * h)
    det = np.einsum("...i,...i", Ju, np.cross(Jv, Jw))
    ref = float(np.einsum("ab,a,b->", det, sw, sw))
    assert tb.volume() == pytest.approx(ref, rel=5e-3)
    # kidney: the posterior boundary (y < 0) is concave at the midline
    mid = tb.boundary_points("w0", 201)
    edge = np.concatenate([mid[0], mid[-1], mid[:, 0], mid[:, -1]])
    post = edge[edge[:, 1] < 0]
    y_mid = post[np.abs(post[:, 0]) < 1.0, 1].min()
    y_side = post[np.abs(np.abs(post[:, 0]) - 10.0) < 1.0, 1].min()
    assert y_mid > y_side + 1.0


def test_folded_tbss_refused():
    tb = box_tbss((10, 10, 10), n_ctrl=(4, 4, 4))
    c = tb.control.copy()
    c[[0, 1], 0, 0] = c[[1, 0], 0, 0]                       # swap two control points
    with pytest.raises(InputError, match=r"folds: .* at \(u, v, w\) = \(0, 0, 0\)"):
        TBSS(c, 3, tb.knots).check_jacobian()
    with pytest.raises(InputError, match="folds"):
        TBSS(c[::-1], 3, tb.knots).check_jacobian()      # mirrored: inverted everywhere


def test_fit_map_refuses_folding_map():
    with pytest.raises(InputError, match="folds"):
        fit_map(lambda u, v, w: (u, v * (u - 0.5), w), (6, 6, 4))


# ---------------------------------------------------------------- LSPIA
def _field(n):
    x = np.linspace(0, 1, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    return np.sin(2 * np.pi * X) * np.cos(3 * Y) + Z ** 2 + 0.3 * np.exp(
        -((X - 0.5) ** 2 + (Y - 0.4) ** 2 + (Z - 0.6) ** 2) / 0.02)


def test_lspia_100_cubed_to_20_cubed():
    q = _field(100)
    vol, rep = fit_grid(q, 20, degree=3, tol=1e-6, max_iter=500)
    h = np.array(rep.rms_history)
    assert rep.converged and rep.iterations == len(h) - 1 < 500
    assert np.all(np.diff(h) <= 1e-12 * h[0])              # monotone non-increasing
    assert h[-1] < 0.01 * h[0] and rep.rms == h[-1] < 1e-4
    assert rep.max_error < 2e-3
    # LSPIA converges to the least-squares fit
    ls = fit_grid_lstsq(q, 20, degree=3)
    x = np.linspace(0, 1, 100)
    g = ls.evaluate_grid(x, x, x)[..., 0]
    assert np.sqrt(np.mean((g - q) ** 2)) == pytest.approx(rep.rms, rel=1e-3)
    # the returned volume reproduces the reported residual
    g2 = vol.evaluate_grid(x, x, x)[..., 0]
    assert np.sqrt(np.mean((g2 - q) ** 2)) == pytest.approx(rep.rms, rel=1e-9)


def test_lspia_zero_init_and_errors():
    q = _field(24)
    vol, rep = fit_grid(q[..., None] * [1.0, -2.0], 6, init="zero", max_iter=2000, tol=1e-9)
    assert vol.dim == 2 and rep.rms_history[0] > 0.3
    assert np.all(np.diff(rep.rms_history) <= 1e-12)
    with pytest.raises(InputError, match="init"):
        fit_grid(q, 6, init="cubic")
    with pytest.raises(InputError, match="strictly increasing"):
        fit_grid(q, 6, params=[np.zeros(24)] * 3)
    with pytest.raises(InputError, match="cannot determine"):
        fit_grid_lstsq(q[:4], 6)


def test_local_lspia_moves_only_the_support():
    n = 40
    q = _field(n)
    vol, _ = fit_grid(q, 10, max_iter=50)
    edited = np.array([[20, 20, 20], [21, 20, 20], [5, 30, 35]])
    q2 = q.copy()
    q2[tuple(edited.T)] += [0.5, 0.5, -0.3]
    new, moved, rep = local_lspia(vol, q2, edited)
    # expected: control i moves iff B_i(t_j) > 0 for some edited vertex j
    t = np.linspace(0, 1, n)
    S = [basis_matrix(vol.knots[a], 3, t[edited[:, a]]).toarray() > 0 for a in range(3)]
    expected = np.einsum("ki,kj,kl->ijl", *[s.astype(int) for s in S]) > 0
    np.testing.assert_array_equal(moved, expected)
    assert 0 < moved.sum() < moved.size
    np.testing.assert_array_equal(new.control[~moved], vol.control[~moved])   # bit-identical
    assert np.any(new.control[moved] != vol.control[moved])
    assert rep.rms < 0.05 * rep.rms_history[0]
    got = new.evaluate(*(t[edited].T))[:, 0]
    np.testing.assert_allclose(got, q2[tuple(edited.T)], atol=0.02)
    with pytest.raises(InputError, match="outside"):
        local_lspia(vol, q2, [[40, 0, 0]])


# ---------------------------------------------------------------- lofting and mesh fits
def test_loft_frustum():
    z = np.linspace(0, 30, 16)
    th = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    radii = 10 - 0.15 * z
    curves = [np.stack([r * np.cos(th + 0.3 * k), r * np.sin(th + 0.3 * k), np.full_like(th, zk)], axis=1)
              for k, (r, zk) in enumerate(zip(radii, z))]
    tb = loft_tbss(curves, n_ctrl=(8, 8, 4))
    assert tb.check_jacobian()["min_det"] > 0
    ref = np.pi * 30 / 3 * (10 ** 2 + 10 * radii[-1] + radii[-1] ** 2)
    assert tb.volume() == pytest.approx(ref, rel=3e-3)
    np.testing.assert_allclose(tb.boundary_points("w1", 5)[..., 2], 30.0, atol=1e-9)


def test_radial_fit_of_ellipsoid():
    m = trimesh.creation.icosphere(subdivisions=4)
    m.apply_scale([20.0, 12.0, 8.0])
    tb, info = fit_tbss_to_mesh(m.vertices, m.faces, method="radial")
    assert info["method"] == "radial"
    assert info["min_det"] > 0 and tb.check_jacobian()["min_det"] > 0
    assert info["rms_distance"] < 0.1 and info["max_distance"] < 0.8      # mm, body 40 mm long
    assert info["covered_fraction"] == pytest.approx(1.0, abs=0.005)
    # independent check of the boundary: points lie on the ellipsoid
    pts = np.concatenate([tb.boundary_points(f, 20).reshape(-1, 3) for f in ("u0", "v1", "w0")])
    e = np.sqrt(((pts / [20.0, 12.0, 8.0]) ** 2).sum(axis=1))
    assert np.abs(e - 1).max() < 0.05


def test_radial_fit_refuses_non_star_shaped_body():
    body = (m3.Manifold.sphere(10.0, 48) + m3.Manifold.sphere(10.0, 48).translate([40, 0, 0])
            + m3.Manifold.cylinder(40.0, 3.0, 3.0, 32).rotate([0, 90, 0]))
    mesh = body.to_mesh()
    v, f = np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts)
    with pytest.raises(InputError, match="not star-shaped"):
        fit_tbss_to_mesh(v, f, method="radial")
    with pytest.raises(InputError, match="outside the body"):
        fit_tbss_to_mesh(v, f, method="radial", centre=(0, 0, 30))
    with pytest.raises(InputError, match="unknown TBSS fitting method"):
        fit_tbss_to_mesh(v, f, method="spherical")


def test_sliced_fit_of_femur():
    if FEMUR.exists():
        m = trimesh.load(FEMUR, force="mesh")
    else:                                   # generated stand-in: a long capsule
        m = trimesh.creation.capsule(height=120.0, radius=14.0, count=[48, 48])
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    tb, info = fit_tbss_to_mesh(v, f, method="sliced", n_ctrl=(8, 8, 12))
    assert info["method"] == "sliced"
    chk = tb.check_jacobian()
    assert chk["min_det"] > 0 and info["min_det"] > 0
    length = float(np.ptp(v @ np.asarray(info["axis"])))
    assert 0.5 < info["covered_fraction"] <= 1.01
    assert 0.6 < info["length_fraction"] <= 1.0
    assert info["rms_distance"] < 0.002 * length
    assert info["max_distance"] < 0.02 * length
