"""Issue 22: each job's report measures inside its design domain, never in the air of a bounding box.

The domain surfaces of mapped and meshed domains (:mod:`porecad.maps.domain_surface`)
are checked closed and outward with known volumes (a polygonal annulus,
exact for linear interpolation of its sampled boundary; unions of cubes;
a cube of six tets); then a TBSS and a TIS job write report directories whose
voxel porosity, measured inside the domain, agrees with the mesh porosity.
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import trimesh

from porecad.maps.domain_surface import (cell_union_surface, mapped_box_surface, tet_mesh_surface)
from porecad.mesh.validate import check_solid, signed_volume


def _closed(v, f):
    chk = check_solid(v, f, check_self_intersections=False)
    return chk["closed"] and chk["manifold"] and chk["outward"]


def test_mapped_box_surface_of_an_affine_map():
    A = np.array([[2.0, 0.3, 0.0], [0.0, 1.0, 0.2], [0.1, 0.0, 0.5]])
    v, f = mapped_box_surface(lambda p: p @ A.T + 1.0, [0, 0, 0], [1, 2, 3], (4, 5, 6))
    assert _closed(v, f)
    assert signed_volume(v, f) == pytest.approx(6.0 * np.linalg.det(A), rel=1e-12)


def test_mapped_box_surface_periodic_annulus():
    """(r, θ, z) ↦ cylinder shell; θ periodic: the polygonal annulus area n/2·sin(2π/n)·(R² − r²) times h."""
    n = 24

    def ring(p):
        r, t, z = p[:, 0], p[:, 1], p[:, 2]
        return np.stack([r * np.cos(t), r * np.sin(t), z], axis=1)

    v, f = mapped_box_surface(ring, [1.0, 0.0, 0.0], [2.0, 2 * np.pi, 3.0], (3, n + 1, 2),
                              periodic=(False, True, False))
    assert _closed(v, f)
    expected = n / 2 * np.sin(2 * np.pi / n) * (2.0 ** 2 - 1.0 ** 2) * 3.0
    assert signed_volume(v, f) == pytest.approx(expected, rel=1e-12)


def test_mapped_box_surface_refuses_bad_sampling():
    from porecad.errors import InputError
    with pytest.raises(InputError, match="samples per axis"):
        mapped_box_surface(lambda p: p, [0, 0, 0], [1, 1, 1], (1, 2, 2))


def test_cell_union_surface_of_an_l_shape():
    kept = np.zeros((1, 2, 2), bool)
    kept[0, 0, 0] = kept[0, 0, 1] = kept[0, 1, 0] = True
    v, f = cell_union_surface(kept, (1, 0, 0), (0.0, 0.0, 0.0), 2.0)
    assert _closed(v, f)
    assert signed_volume(v, f) == pytest.approx(3 * 8.0)
    assert v[:, 0].min() == pytest.approx(2.0) and v[:, 0].max() == pytest.approx(6.0)


def test_tet_mesh_surface_of_a_kuhn_cube():
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=np.float64) * 1.5
    tets = []
    for perm in itertools.permutations(range(3)):
        path, idx = [0], 0
        for a in perm:
            idx += 1 << a
            path.append(idx)
        p = corners[path]
        if np.linalg.det(p[1:] - p[0]) < 0:
            path[2], path[3] = path[3], path[2]
        tets.append(path)
    v, f = tet_mesh_surface(corners, np.array(tets))
    assert _closed(v, f)
    assert signed_volume(v, f) == pytest.approx(1.5 ** 3)


@pytest.mark.parametrize("args, kind", [
    (["tbss", "box", "G", "--periods", "1", "1", "1", "--resolution", "8", "--tdf-grid", "10",
      "--tdf-control", "4"], "body mesh"),
    (["tis", "--regular-tet", "--type", "P", "--relative-threshold", "0.2", "--resolution", "16"], "body mesh"),
    (["tis", "BALL", "--type", "P", "--relative-threshold", "0.2", "--resolution", "8", "--tets", "200"],
     "body mesh"),
])
def test_job_report_measures_inside_its_domain(run_cli, tmp_path, args, kind):
    """The voxel porosity inside the job's domain agrees with the mesh porosity (bounding box: it would not)."""
    rep_dir = tmp_path / "rep"
    if "BALL" in args:  # a TIS cut to a body: the domain is the body inside the tets
        trimesh.creation.icosphere(subdivisions=3, radius=6.0).export(tmp_path / "ball.stl")
        args = [str(tmp_path / "ball.stl") if a == "BALL" else a for a in args]
    code, _, err = run_cli(*args, "-o", tmp_path / "s.stl", "--report", rep_dir)
    assert code == 0, err
    rep = json.loads((rep_dir / "report.json").read_text(encoding="utf-8"))
    assert rep["domain"] == kind
    assert abs(rep["porosity_voxel"] - rep["build"]["porosity"]) < 0.01
    # porosity against the domain's own volume, as the build measured it
    assert rep["porosity"] == pytest.approx(rep["build"]["porosity"], abs=1e-6)
