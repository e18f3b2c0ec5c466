"""The body corpus (porecad.datasets) and what the methods of issue 20 do on it (small bodies only)."""

import numpy as np
import pytest

from porecad import datasets
from porecad.errors import InputError
from porecad.mesh.validate import check_solid


def _solid(v, f):
    r = check_solid(v, f, check_self_intersections=True)
    assert r["closed"] and r["manifold"] and r["outward"], r
    assert r["self_intersections"] == 0
    return r


def test_star_blob_is_a_closed_star_shaped_body_with_the_asked_triangle_count():
    from porecad.splines.meshfit_radial import star_shaped
    v, f = datasets.star_blob(2000, seed=3)
    assert len(f) == 2000
    r = _solid(v, f)
    assert r["euler"] == 2
    assert star_shaped(v, f, centre=(0.0, 0.0, 0.0), rays=24)
    # deterministic, and the seed matters
    v2, f2 = datasets.star_blob(2000, seed=3)
    assert np.array_equal(v, v2) and np.array_equal(f, f2)
    assert not np.allclose(v, datasets.star_blob(2000, seed=4)[0])


def test_generated_bodies_are_closed_with_their_genus():
    from porecad.splines.meshfit_radial import star_shaped
    bone = datasets.curved_bone(3000)
    assert _solid(*bone)["euler"] == 2
    assert not star_shaped(*bone)  # the case the radial TBSS fit cannot take
    assert _solid(*datasets.torus_body(1500))["euler"] == 0  # genus 1
    limbs = datasets.limbed_body(3000)
    assert _solid(*limbs)["euler"] == 2
    # limbs thinner than a twelfth of the largest extent: the body's volume is far below its box's
    ext = np.ptp(limbs[0], axis=0)
    assert check_solid(*limbs, check_self_intersections=False)["volume"] < 0.2 * np.prod(ext)
    for n in (1500, 6000):
        assert abs(len(datasets.curved_bone(n)[1]) - n) < 0.35 * n


def test_bunny_is_closed_and_about_150_mm():
    v, f = datasets.bunny()
    r = _solid(v, f)
    assert r["euler"] == 2 and len(f) == 3674
    assert 140 < np.ptp(v, axis=0).max() < 160
    assert "Stanford" in datasets.BUNNY_NOTE


def test_segmented_volume_has_staircase_noise_and_a_mesh():
    mask, sp = datasets.segmented_volume(shape=(40, 30, 50), spacing=(0.88, 0.88, 1.5))
    assert mask.shape == (40, 30, 50) and mask.dtype == np.uint8 and np.allclose(sp, [0.88, 0.88, 1.5])
    assert 0.02 < mask.mean() < 0.5
    assert not mask[0].any() and not mask[:, :, -1].any()  # clear of the image's border
    v, f = datasets.segmented_body(shape=(40, 30, 50))
    r = _solid(v, f)
    # the staircase mesh holds about the mask's voxel volume
    assert r["volume"] == pytest.approx(mask.sum() * np.prod(sp), rel=0.1)


def test_bad_requests_are_refused():
    with pytest.raises(InputError):
        datasets.star_blob(10)
    with pytest.raises(InputError):
        datasets.curved_bone(10**9)
    with pytest.raises(InputError):
        datasets.body("teapot")
    with pytest.raises(InputError):
        datasets.segmented_volume(shape=(4, 4, 4))
