"""Region 3-refinement (porecad.volmesh.refine_region): templates, conformity, box refinement, scaffold."""

import numpy as np
import pytest

from porecad.errors import InputError
from porecad.volmesh.hexshapes import (HEX_EDGES, check_hex_mesh, hex_boundary_faces, hex_corner_jacobians,
                                       hex_face_groups, hex_grid, hex_volumes)
from porecad.volmesh.refine_region import TEMPLATES, refine_box, refine_region


def _check_conforming(P, H, volume, area):
    P, H = check_hex_mesh(P, H)
    assert hex_corner_jacobians(P, H).min() > 0
    assert hex_volumes(P, H).sum() == pytest.approx(volume, rel=1e-9)
    _, counts = hex_face_groups(H)
    assert set(np.unique(counts)) <= {1, 2}
    q, _, _ = hex_boundary_faces(H)
    e = np.sort(np.concatenate([q[:, [i, (i + 1) % 4]] for i in range(4)]), axis=1)
    _, c = np.unique(e, axis=0, return_counts=True)
    assert np.all(c == 2)  # the boundary quads close up
    a = P[q]
    quad_area = 0.5 * np.linalg.norm(np.cross(a[:, 2] - a[:, 0], a[:, 3] - a[:, 1]), axis=1)
    assert quad_area.sum() == pytest.approx(area, rel=1e-9)
    return P, H


def test_template_sizes_and_validity():
    assert {k: len(t) for k, (t, _) in TEMPLATES.items()} == {"point": 4, "edge": 11, "face": 22, "full": 27}
    for t, _ in TEMPLATES.values():
        P = t.reshape(-1, 3)
        H = np.arange(len(P)).reshape(-1, 8)
        assert hex_corner_jacobians(P, H).min() > 0
        assert hex_volumes(P, H).sum() == pytest.approx(1.0)


def test_box_in_4x4x4_grid():
    P, H = hex_grid(4, 4, 4, 1.0)
    P2, H2 = refine_box(P, H, (4, 4, 4), (1, 1, 1), (3, 3, 3))
    # 8 cells × 27, 24 face neighbours × 22, 24 edge neighbours × 11, 8 corner neighbours × 4
    assert len(H2) == 8 * 27 + 24 * 22 + 24 * 11 + 8 * 4
    P2, H2 = _check_conforming(P2, H2, 64.0, 96.0)
    centre = P2[H2].mean(axis=1)
    inside = np.all((centre > 1) & (centre < 3), axis=1)
    assert inside.sum() == 216
    L = np.linalg.norm(P2[H2[:, HEX_EDGES[:, 1]]] - P2[H2[:, HEX_EDGES[:, 0]]], axis=2)
    np.testing.assert_allclose(L[inside], 1.0 / 3.0, atol=1e-12)


def test_box_on_boundary_of_sheared_grid():
    P, H = hex_grid(5, 4, 3, 2.0)
    A = np.array([[1.0, 0.3, 0.1], [0.0, 1.2, -0.2], [0.1, 0.0, 0.9]])
    Ps = P @ A.T
    P2, H2 = refine_box(Ps, H, (5, 4, 3), (0, 1, 1), (2, 3, 3))
    vol = 5 * 4 * 3 * 8.0 * np.linalg.det(A)
    q, _, _ = hex_boundary_faces(H)
    a = Ps[q]
    area = (0.5 * np.linalg.norm(np.cross(a[:, 2] - a[:, 0], a[:, 3] - a[:, 1]), axis=1)).sum()
    _check_conforming(P2, H2, vol, area)
    assert len(H2) > len(H)


def test_refine_region_point_edge_only_and_refusals():
    P, H = hex_grid(3, 3, 3, 1.0)
    node = lambda i, j, k: i + 4 * (j + 4 * k)  # noqa: E731
    # one interior vertex: the 8 hexes around it get the point template
    P2, H2 = refine_region(P, H, [node(1, 1, 1)])
    assert len(H2) == 27 - 8 + 8 * 4
    _check_conforming(P2, H2, 27.0, 54.0)
    # one edge: 4 hexes get the edge template, the 4 beyond each end the point template
    P2, H2 = refine_region(P, H, [node(1, 1, 1), node(2, 1, 1)])
    assert len(H2) == 27 - 12 + 4 * 11 + 8 * 4
    _check_conforming(P2, H2, 27.0, 54.0)
    assert refine_region(P, H, [])[1].shape == H.shape
    with pytest.raises(InputError, match="no 3-refinement template"):
        refine_region(P, H, [node(1, 1, 1), node(2, 2, 1)])  # diagonal of a face
    with pytest.raises(InputError, match="0..63"):
        refine_region(P, H, [64])
    with pytest.raises(InputError, match="range"):
        refine_box(P, H, (3, 3, 3), (1, 1, 1), (1, 2, 2))
    with pytest.raises(InputError, match="hex_grid"):
        refine_box(P, H, (3, 3, 4), (0, 0, 0), (1, 1, 1))


def test_refined_box_scaffold_is_closed_manifold():
    from porecad.maps.hexcells import hex_cells_scaffold
    from porecad.mesh.validate import check_solid
    P, H = hex_grid(4, 4, 4, 1.0)
    P2, H2 = refine_box(P, H, (4, 4, 4), (1, 1, 1), (3, 3, 3))
    r = hex_cells_scaffold(P2, H2, "P", "pore", 0.0, 10)
    rep = check_solid(r["vertices"], r["faces"], check_self_intersections=True)
    assert rep["closed"] and rep["manifold"] and rep["outward"]
    assert rep["self_intersections"] == 0
