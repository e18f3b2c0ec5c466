"""Corpus bodies that took minutes (issue 37, "a no within a minute"): bounded work, early one-line refusals.

The thin branching tube (``y-tube-thin``): its slanted facets filled the distance bins of their whole bounding
boxes, and the porosity calibration sampled signed distances where inside/outside is all it needs. The tube
and the plates: ``tbss --fit auto`` untangled fits folded through the body, then repaired the mapped
scaffold's crossings for minutes; ``hex`` untangled a folded cube map for 90 s and then failed on an
inverted hexahedron without saying what would help.
"""

import numpy as np
import pytest

from porecad import datasets
from porecad.bodies import MeshBody
from porecad.bodies import body_porosity as bp
from porecad.bodies import distance_kernels as K
from porecad.fields.tpms import TPMSField
from porecad.lattice.plan import LatticePlan
from porecad.mesh.polygonise import Grid
from porecad.solids import StructureField
from porecad.splines.meshfit import fit_tbss_to_mesh


@pytest.fixture(scope="module")
def thin_tube():
    return datasets.body("y-tube-thin")


def test_distance_bins_of_slanted_facets_are_few_and_the_distances_exact(thin_tube):
    v, f = thin_tube
    body = MeshBody(v, f, band=0.08)
    start, items = K.bin_triangles_xyz(body.vertices, body.faces, body._lo3, body._cell3, body._nb3)
    assert len(body._xyz_items) < 0.1 * len(items)  # 166 k against 7.7 M bounding-box entries
    rng = np.random.default_rng(0)
    lo, hi = body.bounds
    p = rng.uniform(lo - 0.3, hi + 0.3, (100_000, 3))
    near = p[np.argsort(np.abs(body(p)))[:20_000]]  # the samples nearest the surface, where it matters
    everywhere = np.ones(int(np.prod(body._nb3)), dtype=bool)  # no bin skipped
    ref = K.clamped_distance_points(body.vertices, body.faces, near, body._lo3, body._cell3, body._nb3, start, items,
                                    everywhere, body.band)
    assert np.any(ref < body.band)
    np.testing.assert_array_equal(body.distance(near), ref)


def _plan(v, f, skin=0.0, h=0.04):
    body = MeshBody(v, f, band=skin + 2 * h)
    lo, hi = body.bounds
    cell = np.full(3, float(np.ptp(v, axis=0).max()) / 12)
    material = StructureField(TPMSField("G", cell), "pore", 0.3)
    # what the calibration samples read (body, material, domain_volume, cell_size, grid, boundary, body_info)
    return LatticePlan(type="G", structure="pore", cell_size=cell, grid=Grid.from_box(lo, hi, spacing=h),
                       field=material, body=body, threshold_info={}, domain_volume=body.volume, domain_area=0.0,
                       closed=True, boundary="skin" if skin else "cut", body_info={"skin": skin}, material=material,
                       origin=np.zeros(3), cells_pending=False, context=None)


def test_a_thin_bodys_calibration_is_bounded_and_needs_no_distances(thin_tube, monkeypatch):
    plan = _plan(*thin_tube)

    def no_distances(*args):
        raise AssertionError("a cut body's calibration samples only inside/outside")

    monkeypatch.setattr(plan.body, "sample_grid", no_distances)
    samples = bp.BodySamples(plan)
    assert samples.grid_points <= bp.MAX_GRID
    assert bp.MIN_SAMPLES < samples.n_inside <= 2 * bp.TARGET_INSIDE
    c, info = bp.fit_uniform(samples, 0.6)
    assert bp.achieved(samples, c) == pytest.approx(0.6, abs=1e-3)


def test_a_skin_calibration_measures_depth_at_the_inside_samples_only():
    v, f = datasets.body("blob-4k")
    skin = 0.05 * float(np.ptp(v, axis=0).min())
    plan = _plan(v, f, skin=skin, h=0.02 * float(np.ptp(v, axis=0).min()))
    samples = bp.BodySamples(plan, target_inside=40_000)
    xs, ys, zs = bp.sample_axes(*plan.body.bounds, plan.cell_size, plan.domain_volume, 40_000,
                                min_spacing=0.5 * float(np.min(plan.grid.spacing)))
    d = plan.body.sample_grid(xs, ys, zs)  # the signed distances on the same samples
    assert samples.n_inside == int(np.sum(d < 0))
    assert 0 < samples.core.mean() < 1
    assert int(samples.core.sum()) == int(np.sum(d < -skin))


def test_tbss_auto_takes_the_hex_fit_where_the_radial_fit_folds_through_the_body():
    v, f = datasets.body("plate-2cell")
    tb, info = fit_tbss_to_mesh(v, f, n_ctrl=(6, 6, 6))
    assert info["method"] == "hex" and "radial fit folds" in info["radial_refused"]
    assert info["min_scaled_jacobian"] > 0 and not info["untangled"]


def test_tbss_auto_refuses_a_body_both_fits_fold_through(one_line_error, tmp_path):
    body, out = tmp_path / "y-tube.stl", tmp_path / "out.stl"
    from porecad.io import write_mesh
    write_mesh(str(body), *datasets.body("y-tube"))
    err = one_line_error("tbss", body, "G", "--structure", "sheet", "--porosity-range", "0.6", "0.6",
                         "--periods", "4", "4", "4", "--resolution", "8", "--body-control", "6", "-o", out,
                         match="--fit")
    assert "radial fit folds" in err and "hex fit folds" in err
    assert not out.exists()


@pytest.mark.parametrize("element", ["hex8", "hex20"])
def test_hex_refuses_a_folded_cube_map_naming_what_may_help(one_line_error, tmp_path, element):
    body, out = tmp_path / "plate.stl", tmp_path / "out.stl"
    from porecad.io import write_mesh
    write_mesh(str(body), *datasets.body("plate-2cell"))
    err = one_line_error("hex", body, "P", "--grid", "3", "3", "3", "--element", element, "--porosity", "0.6",
                         "--resolution", "8", "--untangle-limit", "0.2", "-o", out, match="cube map folds")
    assert "--untangle-limit" in err and "--corners" in err
    assert not out.exists()
