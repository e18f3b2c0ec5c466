"""The cheaper report analysis (issue 53) answers as the plain route did: exact distances on any thread
count, field walls within their stated error, the pore analysis unchanged by not asking twice."""

import numpy as np
import pytest

import porecad.kernel_threads as kt
from porecad.analysis.domain import FieldDomain
from porecad.analysis.surface_index import SurfaceIndex


def _sphere():
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    return np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)


@pytest.mark.parametrize("n", [1, 63, 1000, 4097])
def test_nearest_in_blocks_is_the_same_on_any_thread_count(monkeypatch, n):
    """Each thread's run takes blocks of neighbouring points: the same arrays as one run, and exact."""
    v, f = _sphere()
    g = np.linspace(-1.4, 1.4, 17)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    p = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)          # raster order, as the callers ask
    p = np.resize(p, (n, 3)) + 1e-3 * np.arange(n)[:, None] / n
    out = []
    for t in (1, 2, 3):
        monkeypatch.setattr(kt, "thread_count", lambda t=t: t)
        out.append(SurfaceIndex(v, f, cell=0.2).nearest(p, 2.0, with_triangles=True))
    for other in out[1:]:
        for a, b in zip(out[0], other):
            assert np.array_equal(a, b, equal_nan=True)
    # one cell holding every triangle (each point tests them all): the same exact distances
    d, c = SurfaceIndex(v, f, cell=10.0).nearest(p, 2.0)
    assert np.allclose(out[0][0], d, atol=1e-12) and np.allclose(out[0][1], c, atol=1e-12)
    assert np.all(np.abs(d - np.abs(np.linalg.norm(p, axis=1) - 1.0)) < 0.02)


def test_field_wall_forward_differences():
    """A field domain's wall distance (|f| / |grad f|, gradient by forward differences) on a sphere SDF:
    within 5e-5 mm of the exact distance (at most 1.3 mm here), the closest point as near the sphere."""
    from porecad.fields.sdf import Sphere

    dom = FieldDomain(Sphere((0, 0, 0), 5.0), (-5, -5, -5), (5, 5, 5))
    rng = np.random.default_rng(1)
    p = rng.normal(size=(2000, 3))
    p *= (rng.uniform(3.5, 4.99, 2000) / np.linalg.norm(p, axis=1))[:, None]
    d, c = dom.wall(p, 2.0)
    true = 5.0 - np.linalg.norm(p, axis=1)
    near = true < 2.0
    assert np.all(np.abs(d[near] - true[near]) < 5e-5)
    assert np.all(np.abs(np.linalg.norm(c[near], axis=1) - 5.0) < 5e-5)
    assert np.all(d[~near] == 2.0) and np.all(np.isnan(c[~near]))


def test_ridge_not_asked_twice_gives_the_same_sizes():
    """Seeds whose distance is exact are not queried again on the ridge: the sizes of a slab and a
    slot are those of asking every ridge voxel (to float32 rounding of the distances)."""
    import manifold3d as m3

    import porecad.analysis.thickness as th
    from porecad.analysis.pores import pore_analysis

    slot = m3.Manifold.cube([6, 6, 2]) + m3.Manifold.cube([6, 6, 2]).translate([0, 0, 3])
    m = slot.to_mesh()
    v = np.asarray(m.vert_properties)[:, :3].astype(np.float64)
    f = np.asarray(m.tri_verts).astype(np.int64)
    cheap = pore_analysis(v, f)
    plain_balls = th.phase_balls

    def ask_all(phase, dist, cp, origin, h, exact, known=None):
        return plain_balls(phase, dist, cp, origin, h, exact)

    th.phase_balls = ask_all
    try:
        plain = pore_analysis(v, f)
    finally:
        th.phase_balls = plain_balls
    for key in ("pore_size", "strut_size"):
        for q in ("mean", "d10", "d50", "d90", "max"):
            assert abs(cheap[f"{key}_{q}"] - plain[f"{key}_{q}"]) <= 1e-5 * plain[f"{key}_{q}"]
