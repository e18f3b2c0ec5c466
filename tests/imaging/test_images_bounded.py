"""Images in bounded time (issue 20, item 5): the CT-like phantom, vessels from a contrast CT, image bodies.

Small volumes only (the full 157 × 393 × 34 volume is timed by ``bench/images.py``).
"""

import numpy as np
import pytest

from porecad import datasets

SMALL = (79, 197, 17)  # half the voxels per axis of the volume, same field of view


def _spacing(shape):
    return [s * n / m for s, n, m in zip(datasets.CT_SPACING, datasets.CT_SHAPE, shape)]


@pytest.fixture(scope="module")
def small_ct():
    return datasets.ct_volume(shape=SMALL, spacing=_spacing(SMALL), seed=0)


@pytest.fixture(scope="module")
def small_vessel():
    return datasets.ct_volume(shape=SMALL, spacing=_spacing(SMALL), seed=0, bone=False)


def test_ct_volume_holds_a_bone_and_a_vessel_apart(small_ct):
    ct, bone, vessel = small_ct["ct"], small_ct["bone"], small_ct["vessel"]
    assert ct.shape == SMALL and ct.dtype == np.int16
    assert np.allclose(small_ct["geometry"]["spacing"], _spacing(SMALL))
    assert ct.min() <= -900 and ct.max() >= 700                        # air and cortical bone (partial volume)
    assert bone.sum() > 1000 and vessel.sum() > 1000 and not (bone & vessel).any()
    from scipy import ndimage
    gap = ndimage.distance_transform_edt(~bone, sampling=_spacing(SMALL))[vessel].min()
    assert gap > 5.0                                                     # mm between bone and lumen
    # the lumen is contrast (about 330 HU) over muscle (about 45 HU)
    inner = ndimage.binary_erosion(vessel, iterations=1)
    assert 250 < np.median(ct[inner]) < 400
    # deterministic, the seed matters
    again = datasets.ct_volume(shape=SMALL, spacing=_spacing(SMALL), seed=0)
    assert np.array_equal(again["ct"], ct)
    assert not np.array_equal(datasets.ct_volume(shape=SMALL, spacing=_spacing(SMALL), seed=1)["ct"], ct)


def test_ct_volume_refuses_bad_sizes():
    from porecad.errors import InputError
    with pytest.raises(InputError):
        datasets.ct_volume(shape=(4, 100, 10))
    with pytest.raises(InputError):
        datasets.ct_volume(spacing=(0.9, -1.0, 1.5))


def test_contrast_ct_threshold_is_between_tissue_and_lumen(small_vessel):
    """Otsu alone splits air from the patient in a CT; the lumen threshold lies between muscle and contrast."""
    from scipy import ndimage
    from skimage.filters import threshold_otsu

    from porecad.vessels.skeleton import default_threshold, is_ct
    s = ndimage.gaussian_filter(small_vessel["ct"].astype(np.float32), 1.0)
    assert is_ct(s) and threshold_otsu(s) < -200
    t = default_threshold(s)
    assert 120 < t < 260                      # halfway between about 45 HU and 330 HU
    # a 0/1 segmentation is not a CT: Otsu's split, refined to the half level
    mask = small_vessel["vessel"].astype(np.float32)
    assert not is_ct(mask) and 0.3 < default_threshold(ndimage.gaussian_filter(mask, 1.0)) < 0.7


def test_vessel_centreline_of_a_contrast_ct(small_vessel):
    """The tree of the contrast CT: valid (no self-intersection), trunk and legs found, radii of the phantom."""
    from porecad.vessels.skeleton import array_centreline
    g, info = array_centreline(small_vessel["ct"].astype(np.float32), small_vessel["geometry"])
    g.validate()
    assert info["foreground_voxels"] == pytest.approx(small_vessel["vessel"].sum(), rel=0.25)
    assert len(g.branches()) >= 3 and np.sum(g.degrees() >= 3) >= 1
    trunk_r = small_vessel["branches"][0][1].max()
    assert g.radii.max() == pytest.approx(trunk_r, rel=0.2)
    # the centreline runs inside the lumen
    idx = np.rint((g.points - np.asarray(small_vessel["geometry"]["origin"])) / _spacing(SMALL)).astype(int)
    idx = np.clip(idx, 0, np.array(SMALL) - 1)
    assert small_vessel["vessel"][tuple(idx.T)].mean() > 0.95


def test_vessel_job_on_a_contrast_ct_reports_its_stages(tmp_path, small_vessel):
    """The job on the CT file: closed lumen near the phantom's volume; progress names the up-front estimate."""
    from porecad.imaging.io import write_volume
    from porecad.jobs import run_recipe
    path = write_volume(tmp_path / "v.nii.gz", small_vessel["ct"], small_vessel["geometry"])
    stages = []
    rep = run_recipe({"job": "vessel", "input": {"kind": "image", "path": str(path)}, "voxel": 1.0,
                      "fit": "tube"}, progress=lambda s, d, t: stages.append(s))
    assert rep["closed"] and rep["manifold"] and rep["branches"] >= 3
    phantom = small_vessel["vessel"].sum() * np.prod(_spacing(SMALL))
    assert rep["volume"] == pytest.approx(phantom, rel=0.2)
    assert "centreline" in stages and any(s.startswith("field ~") for s in stages)
    assert rep["field_estimate_s"] > 0


def test_ct_bone_infill_drops_the_vessel_and_holds_porosity(tmp_path, small_ct):
    """``--body-threshold 300``: the bone (the largest piece; the lumen at 330 HU is another), porosity held."""
    from porecad.imaging.io import write_volume
    from porecad.jobs import run_recipe
    path = write_volume(tmp_path / "ct.nii.gz", small_ct["ct"], small_ct["geometry"])
    stages = []
    rep = run_recipe({"job": "infill", "tpms": {"type": "G", "structure": "pore", "porosity": 0.7, "cell_size": 6.0},
                      "domain": {"kind": "mesh", "path": str(path), "threshold": 300},
                      "sampling": {"voxel": 0.6}}, progress=lambda s, d, t: stages.append(s))
    assert rep["closed"] and rep["manifold"]
    assert rep["body"]["image"]["components_removed"] >= 1
    assert abs(rep["porosity"] - 0.7) < 0.01
    bone = small_ct["bone"].sum() * np.prod(_spacing(SMALL))
    # half resolution (3 mm slices): the surface at 300 HU takes in partial-volume voxels (+16 % measured)
    assert rep["body_volume"] == pytest.approx(bone, rel=0.2)
    assert "body surface" in stages and any(s.startswith("mesh ~") for s in stages)
    assert rep["estimate"]["seconds"] > 0
