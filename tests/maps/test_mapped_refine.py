"""Local refinement of mapped meshes where their flat triangles cross (issue 20: TBSS on the bunny and femur)."""

import numpy as np
import pytest

from porecad.maps.mapped_refine import refine_mapped_crossings, split_faces
from porecad.mesh.validate import check_solid, signed_volume


def _box(lo, hi):
    """A closed, outward box of 12 triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    v = lo + c * (hi - lo)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    if signed_volume(v, f) < 0:
        f = f[:, ::-1]
    return v, f


def _bend(p, radius=1.0, thickness=1.0):
    """A quarter-annulus map of the unit cube: u → angle (90°), w → radius, v → height; det J > 0."""
    p = np.asarray(p, float)
    th = 0.5 * np.pi * p[:, 0]
    r = radius + thickness * (p[:, 2] - 0.5)
    return np.stack([r * np.cos(th), r * np.sin(th), p[:, 1]], axis=1)


def test_split_faces_keeps_the_mesh_closed_and_its_volume():
    v, f = _box((0.1, 0.2, 0.3), (0.9, 0.7, 0.6))
    p2, f2 = split_faces(v, f, [0, 5])  # two faces cut into four, their neighbours closed green
    chk = check_solid(p2, f2)
    assert chk["closed"] and chk["manifold"] and chk["outward"] and chk["self_intersections"] == 0
    assert signed_volume(p2, f2) == pytest.approx(signed_volume(v, f), rel=1e-12)
    assert len(f2) > len(f) + 6
    # every new vertex is the midpoint of an old edge
    assert np.allclose(p2[:len(v)], v)


def test_split_faces_across_a_periodic_seam_takes_the_short_way():
    p = np.array([[0.95, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 1.0, 0.0]])
    p2, f2 = split_faces(p, np.array([[0, 1, 2]]), [0], periodic=(True, False, False))
    assert len(f2) == 4
    assert np.isclose(p2[3, 0], 0.0) or np.isclose(p2[3, 0], 1.0)  # not 0.5


def test_refinement_removes_chord_crossings_of_two_bent_slabs():
    # two slabs 2 % of the bend's thickness apart, the lower finely meshed (its chords hug the arc), the upper
    # coarsely: the upper slab's flat bottom dips through the lower one's top, as chords of a curved map do
    pa, fa = _box((0.1, 0.2, 0.3), (0.9, 0.8, 0.49))
    for _ in range(3):
        pa, fa = split_faces(pa, fa, np.arange(len(fa)))
    pb, fb = _box((0.1, 0.2, 0.51), (0.9, 0.8, 0.7))
    p, f = np.concatenate([pa, pb]), np.concatenate([fa, fb + len(pa)])
    assert check_solid(p, f)["self_intersections"] == 0  # not in the parameter domain
    v = _bend(p)
    before = check_solid(v, f)
    assert before["self_intersections"] > 0
    v2, p2, f2, info = refine_mapped_crossings(v, p, f, _bend, max_rounds=8)
    assert info["pairs_before"] == before["self_intersections"] and info["pairs_after"] == 0
    assert info["rounds"] >= 2
    chk = check_solid(v2, f2)
    assert chk["closed"] and chk["manifold"] and chk["outward"] and chk["self_intersections"] == 0
    assert np.allclose(v2, _bend(p2))  # every vertex is the exact image of its parameters
    assert np.array_equal(v2, v2.astype(np.float32))  # as a mesh file stores it: the count holds read back
    assert signed_volume(p2, f2) == pytest.approx(signed_volume(p, f), rel=1e-12)  # the same parametric solid
    # nothing to do: unchanged
    v3, p3, f3, info3 = refine_mapped_crossings(v2, p2, f2, _bend)
    assert info3["rounds"] == 0 and len(f3) == len(f2)
    # give_up: a round leaving more crossings than give_up x those of the input (at least 32) ends refinement
    # (the hex job's bound: 2; here 0, so the first round that leaves any ends it)
    v4, p4, f4, info4 = refine_mapped_crossings(v, p, f, _bend, max_rounds=8, give_up=0.0)
    assert info4["rounds"] == 1 and info4["pairs_after"] > 0 and "multiplied" in info4["stopped"]
    assert np.allclose(v4, _bend(p4)) and check_solid(v4, f4)["self_intersections"] == info4["pairs_after"]


def test_hex_job_refines_crossings_of_a_curved_hex20_map_in_its_parameter_box():
    # the bent slabs again, mapped by a quadratic (hex20) quarter annulus of 2 × 1 × 1 cells: the job's
    # refinement works on parameters in cell units [0, 2] × [0, 1]², split in the unit box and mapped back
    from porecad.jobs.contract import Timer
    from porecad.jobs.hex_job import _refine_crossings
    from porecad.maps.hexmesh import map_params
    cells = (2, 1, 1)
    u, v, w = np.meshgrid(*(np.linspace(0.0, 1.0, 2 * c + 1) for c in cells), indexing="ij")
    nodes = _bend(np.stack([u.ravel(), v.ravel(), w.ravel()], axis=1)).reshape(u.shape + (3,))
    pa, fa = _box((0.1, 0.2, 0.3), (0.9, 0.8, 0.49))
    for _ in range(3):
        pa, fa = split_faces(pa, fa, np.arange(len(fa)))
    pb, fb = _box((0.1, 0.2, 0.51), (0.9, 0.8, 0.7))
    p = np.concatenate([pa, pb]) * np.array([2.0, 1.0, 1.0])
    f = np.concatenate([fa, fb + len(pa)])
    x = map_params(nodes, p, "hex20")
    assert check_solid(x, f)["self_intersections"] > 0
    report = {}
    x2, p2, f2, pairs = _refine_crossings(x, p, f, nodes, cells, "hex20", Timer(), report)
    assert pairs is not None and len(pairs) == 0 and report["crossing_refinement"]["pairs_after"] == 0
    chk = check_solid(x2, f2)
    assert chk["closed"] and chk["manifold"] and chk["self_intersections"] == 0
    assert np.allclose(x2, map_params(nodes, p2, "hex20"), atol=1e-6)
    assert p2[:, 0].max() > 1.0  # back in cell units
