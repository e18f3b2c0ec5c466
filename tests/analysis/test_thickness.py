"""Pore and strut sizes with known answers (issue 22, acceptance 1), the design domain and the skin."""

import json

import manifold3d as m3

import numpy as np
import pytest
import trimesh

from porecad.analysis.domain import BoxDomain
from porecad.analysis.pores import pore_analysis

from thickness_reference import GYROID_SHEET_060


def _mesh(solid):
    m = solid.to_mesh()
    return np.asarray(m.vert_properties)[:, :3].astype(np.float64), np.asarray(m.tri_verts).astype(np.int64)


def channel_cube(d, seg=96, skin=0.0):
    """Cube of edge 5d with six straight channels of diameter d (two per axis) and a closed sphere of diameter d.

    Every pore is d across (the polygons: d cos(π/seg)); walls between pores
    are at least d/2. With ``skin`` the cube is that much larger on every
    side and the channels stop at the skin (closed by it).
    """
    s = d / 2.0          # the 10 mm cube with 2 mm pores, scaled
    e = 10 * s
    solid = m3.Manifold.cube([e + 2 * skin] * 3).translate([-skin] * 3)
    length = e + (0.0 if skin else 4 * s)
    start = 0.0 if skin else -2 * s

    def cyl():
        return m3.Manifold.cylinder(length, s, s, seg).translate([0, 0, start])

    for x, y in ((5, 2), (5, 8)):
        solid = solid - cyl().translate([x * s, y * s, 0])
    for y, z in ((5, 2), (5, 8)):
        solid = solid - cyl().rotate([0, 90, 0]).translate([0 if skin else 0, y * s, z * s])
    for x, z in ((2, 5), (8, 5)):
        solid = solid - cyl().rotate([-90, 0, 0]).translate([x * s, 0, z * s])
    sphere = m3.Manifold.sphere(s, seg).translate([2 * s, 2 * s, 2 * s])
    solid = solid - sphere
    return _mesh(solid), sphere.volume()


@pytest.mark.parametrize("d", [0.5, 1.0, 2.0])
def test_channels_and_sphere_sizes(d):
    """Every pore is d across: mean and d50 within 2 %, the max never above d; one closed pore of the sphere's volume."""
    (v, f), sphere_volume = channel_cube(d)
    rep = pore_analysis(v, f)            # the default voxel (from the feature size)
    true = d * np.cos(np.pi / 96)        # inscribed diameter of the 96-gon channels and sphere
    assert abs(rep["pore_size_mean"] / true - 1) < 0.02
    assert abs(rep["pore_size_d50"] / true - 1) < 0.02
    assert 0.95 * true <= rep["pore_size_max"] <= true * (1 + 1e-6)
    assert rep["closed_pores"] == 1
    assert abs(rep["closed_pore_volume"] / sphere_volume - 1) < 0.03
    channels = 6 * np.pi * (d / 2) ** 2 * 5 * d
    assert abs(rep["open_pore_fraction"] - channels / (channels + sphere_volume)) < 0.01
    assert rep["percolation"] == {"x": True, "y": True, "z": True}
    assert rep["voxel"] < d / 4       # chosen from the feature size, not the box


def test_slab_and_slot():
    """A 1 mm solid slab reads 1 mm; a 1 mm gap between two blocks reads 1 mm of pore."""
    slab = m3.Manifold.cube([6, 6, 1])
    v, f = _mesh(slab)
    # a window away from the slab's rim (whose side faces bound the balls there)
    rep = pore_analysis(v, f, domain=BoxDomain([1.5, 1.5, 0], [4.5, 4.5, 1]))
    assert abs(rep["strut_size_mean"] - 1.0) < 0.02 and abs(rep["strut_size_d50"] - 1.0) < 0.02
    assert 0.99 <= rep["strut_size_max"] <= 1.0 + 1e-6
    slot = m3.Manifold.cube([6, 6, 2]) + m3.Manifold.cube([6, 6, 2]).translate([0, 0, 3])
    v, f = _mesh(slot)
    rep = pore_analysis(v, f)
    assert abs(rep["pore_size_mean"] - 1.0) < 0.02 and abs(rep["pore_size_d50"] - 1.0) < 0.02
    assert rep["pore_size_max"] <= 1.0 + 1e-6
    assert rep["closed_pores"] == 0 and rep["percolation"] == {"x": True, "y": True, "z": False}


def test_gyroid_sheet_wall_thickness(tmp_path, run_json):
    """G sheet (porosity 0.6, cell 1 mm) against the independent reference: mean, d50 within 2 %, max within 5 %."""
    from porecad.io import read_mesh
    out = tmp_path / "g.stl"
    run_json("tpms", "G", "--structure", "sheet", "--threshold", str(GYROID_SHEET_060["threshold"]),
             "--cells", "3", "3", "3", "--cell-size", "1", "--resolution", "30", "-o", out)
    v, f = read_mesh(out)
    # the central cell as a window: the lattice around it is measured as it is
    rep = pore_analysis(v, f, domain=BoxDomain([1, 1, 1], [2, 2, 2]))
    assert abs(rep["strut_size_mean"] / GYROID_SHEET_060["mean"] - 1) < 0.02
    assert abs(rep["strut_size_d50"] / GYROID_SHEET_060["d50"] - 1) < 0.02
    assert abs(rep["strut_size_max"] / GYROID_SHEET_060["max"] - 1) < 0.05
    assert rep["closed_pores"] == 0 and rep["open_pore_fraction"] == 1.0
    assert abs(rep["porosity_voxel"] - 0.6) < 0.02


def test_porespy_side_by_side():
    """On the same voxel image PoreSpy's local thickness counts voxels (biased low); the exact one is right."""
    porespy = pytest.importorskip("porespy")
    (v, f), _ = channel_cube(2.0)
    rep = pore_analysis(v, f, keep_fields=True)
    fields = rep["_fields"]
    void = fields["domain"] & ~fields["solid"]
    lt = porespy.filters.local_thickness(void, method="dt")
    theirs = float(np.mean(2.0 * lt[void] * fields["spacing"]))
    true = 2.0 * np.cos(np.pi / 96)
    assert abs(rep["pore_size_mean"] / true - 1) < 0.02
    assert abs(rep["pore_size_mean"] - true) < abs(theirs - true)


def test_body_domain_excludes_the_air():
    """A body smaller than the box: porosity, sizes and connectivity only inside it."""
    # a 10 mm ball of lattice (channels through a ball body): the air around the ball is no pore
    (v, f), _ = channel_cube(2.0)
    body = m3.Manifold.sphere(4.5, 96).translate([5, 5, 5])
    cut = m3.Manifold(m3.Mesh(vert_properties=v.astype(np.float32), tri_verts=f.astype(np.uint32))) ^ body
    cv, cf = _mesh(cut)
    bv, bf = _mesh(body)
    box = pore_analysis(cv, cf)
    dom = pore_analysis(cv, cf, domain=(bv, bf))
    mesh_porosity = 1 - trimesh.Trimesh(cv, cf).volume / body.volume()
    assert abs(dom["porosity_voxel"] - mesh_porosity) < 0.01
    assert box["porosity_voxel"] > mesh_porosity + 0.2          # the bounding box counts the air
    assert box["pore_size_max"] > 2.5 and dom["pore_size_max"] <= 2.0
    assert dom["domain"] == "body mesh"


def test_skin_closes_pores():
    """Channels closed by a 1 mm skin are told apart from the sphere the lattice closes itself."""
    (v, f), sphere_volume = channel_cube(2.0, skin=1.0)
    body = m3.Manifold.cube([12, 12, 12]).translate([-1, -1, -1])
    rep = pore_analysis(v, f, domain=_mesh(body), skin=1.0)
    assert rep["closed_pores"] == 7 and rep["open_pore_fraction"] == 0.0
    assert rep["closed_by_skin"] == 6 and rep["closed_in_lattice"] == 1
    assert abs(rep["closed_in_lattice_volume"] / sphere_volume - 1) < 0.05
    channels = 6 * np.pi * 10.0
    assert abs(rep["lattice_open_pore_fraction"] - channels / (channels + sphere_volume)) < 0.01
    assert rep["lattice_percolation"] == {"x": True, "y": True, "z": True}
    assert abs(rep["pore_size_d50"] / (2 * np.cos(np.pi / 96)) - 1) < 0.02


def test_analyze_domain_cli(tmp_path, run_json, one_line_error):
    (v, f), _ = channel_cube(2.0)
    body = m3.Manifold.sphere(4.5, 64).translate([5, 5, 5])
    cut = m3.Manifold(m3.Mesh(vert_properties=v.astype(np.float32), tri_verts=f.astype(np.uint32))) ^ body
    cv, cf = _mesh(cut)
    mesh, dom = tmp_path / "cut.stl", tmp_path / "body.stl"
    trimesh.Trimesh(cv, cf).export(mesh)
    trimesh.Trimesh(*_mesh(body)).export(dom)
    rep = run_json("analyze", mesh, "--domain", dom)
    assert rep["domain"] == "body mesh" and abs(rep["porosity_voxel"] - rep["porosity"]) < 0.01
    assert rep["pore_size_max"] <= 2.0
    one_line_error("analyze", mesh, "--domain", tmp_path / "missing.stl", match="missing.stl")


@pytest.fixture(scope="module")
def femur_lattice_max(tmp_path_factory):
    """Largest pore of the G pore lattice at threshold C (cell 8 mm, sampled at 1 mm) in the middle of a 3x3x3 block.

    The window spans two cells from half a cell inside the block, so every
    pore ball (radius < 4 mm) has a periodic copy wholly inside it.

    The infill calibrates its threshold on the body (and, for ``skin``, on
    the body less its shell), so the lattice is built at the infill's own C.
    """
    from porecad.cli import main
    from porecad.io import read_mesh
    cache = {}

    def largest(threshold: float) -> float:
        if threshold not in cache:
            out = tmp_path_factory.mktemp("lattice") / "g.stl"
            assert main(["tpms", "G", "--structure", "pore", "--threshold", repr(float(threshold)),
                         "--cells", "3", "3", "3", "--cell-size", "8", "--voxel", "1.0", "-o", str(out)]) in (0, None)
            v, f = read_mesh(out)
            lo = v.min(axis=0)
            cache[threshold] = pore_analysis(v, f, domain=BoxDomain(lo + 4, lo + 20), spacing=0.4)["pore_size_max"]
        return cache[threshold]

    return largest


@pytest.mark.parametrize("boundary", ["cut", "skin"])
def test_femur_infill_on_its_body(tmp_path, femur_path, femur_lattice_max, boundary):
    """Acceptance 2 through the API: voxel and mesh porosity agree within a point, no pore beyond the lattice's."""
    from porecad.cli import main
    from porecad.io import read_mesh
    from porecad.mesh.validate import signed_volume
    out = tmp_path / "infill.stl"
    assert main(["infill", str(femur_path), "G", "--porosity", "0.7", "--cell-size", "8", "--voxel", "1.0",
                 "--boundary", boundary, "--skin", "1.5", "-o", str(out), "--report", str(tmp_path / "r.json")]) in (0, None)
    threshold = json.loads((tmp_path / "r.json").read_text())["threshold"]
    v, f = read_mesh(out)
    body = read_mesh(femur_path)
    rep = pore_analysis(v, f, domain=body, skin=1.5 if boundary == "skin" else None, spacing=0.4, max_blocks=4,
                        keep_fields=True)
    mesh_porosity = 1.0 - signed_volume(v, f) / signed_volume(*body)
    assert abs(rep["porosity_voxel"] - mesh_porosity) < 0.01
    # the femur's grid samples the lattice at another phase (8 samples per cell): maxima within the 5 %
    # the issue allows a maximum (measured +2.1 % cut, +2.7 % skin); the air around the body read 35 mm
    assert rep["pore_size_max"] <= femur_lattice_max(threshold) * 1.05
    fields = rep["_fields"]
    assert not fields["pore"][~fields["domain"]].any() and not fields["strut"][~fields["domain"]].any()
    if boundary == "cut":
        assert rep["open_pore_fraction"] > 0.99
    else:
        assert rep["open_pore_fraction"] < 0.01 and rep["closed_by_skin"] >= 1
        assert rep["lattice_open_pore_fraction"] > 0.99
