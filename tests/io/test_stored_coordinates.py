"""A solid is checked as it will be read back: float32 coordinates (issue 20: a TBSS scaffold whose slivers
crossed only after the STL rounded them)."""

import numpy as np
import pytest

from porecad.errors import MeshError
from porecad.io import read_mesh, write_mesh
from porecad.jobs.contract import Result
from porecad.jobs.outputs import validated_report
from porecad.mesh.repair import relax_self_intersections
from porecad.mesh.validate import check_solid, stored_coordinates

_TET = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _two_tets(gap):
    """Two closed tetrahedra: the second's lowest vertex ``gap`` above the first's top face (z = 1)."""
    a = np.array([[0, 0, 0], [4, 0, 1], [0, 4, 1], [0, 0, 1.0]])
    b = np.array([[1, 1, 1 + gap], [2, 1, 2], [1, 2, 2], [1, 1, 2.0]])
    return np.vstack([a, b]), np.vstack([_TET, _TET + 4])


def test_stored_coordinates_round_to_float32():
    v = np.array([[1 + 2e-8, 0.1, -3.3]])
    s = stored_coordinates(v)
    assert s.dtype == np.float64 and np.array_equal(s, v.astype(np.float32))
    assert s[0, 0] == 1.0 and not np.array_equal(s, v)
    assert np.array_equal(stored_coordinates(s), s)
    v32 = v.astype(np.float32)
    assert stored_coordinates(v32) is v32


def test_a_gap_that_float32_closes_is_found_before_writing(tmp_path):
    v, f = _two_tets(2e-8)
    chk = check_solid(v, f)
    assert chk["closed"] and chk["manifold"] and chk["outward"] and chk["self_intersections"] == 0
    # written and read back, the vertex touches the face
    write_mesh(tmp_path / "t.stl", v, f)
    v2, f2 = read_mesh(tmp_path / "t.stl")
    assert check_solid(v2, f2)["self_intersections"] > 0
    # the gate checks the stored coordinates, and does not trust a count made in float64
    with pytest.raises(MeshError, match="self-intersecting"):
        validated_report(v, f, check_intersections=True, self_intersections=0)
    with pytest.raises(MeshError, match="self-intersecting"):
        validated_report(v, f, check_intersections=True)
    # a wider gap survives rounding, and a count of exactly the stored coordinates is trusted
    v3, f3 = _two_tets(1e-3)
    rep, chk3, _ = validated_report(stored_coordinates(v3), f3, check_intersections=True, self_intersections=0)
    assert rep["self_intersections"] == 0


def test_repairs_and_results_hold_stored_coordinates():
    v, f = _two_tets(1e-3)
    v2, info = relax_self_intersections(v, f)
    assert info["pairs_after"] == 0 and np.array_equal(v2, v2.astype(np.float32))
    r = Result({}, v, f)
    assert np.array_equal(r.vertices, stored_coordinates(v)) and not np.array_equal(r.vertices, v)
    v32 = v.astype(np.float32)
    assert Result({}, v32, f).vertices is v32  # float32 kept as it is
