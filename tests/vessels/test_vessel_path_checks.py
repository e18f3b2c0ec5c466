"""Issue 55, item 2: the ``path-not-tube`` check on phantom variants — a radius jump is judged against the
radii beside it along the path (not the path's median), a gradual taper and a stenosis are no jump, a wider
chamber and spine or a shortcut are never written silently."""

import numpy as np
import pytest

from porecad.vessels.arch_phantom import arch_phantom
from porecad.vessels.tube_path import RADIUS_JUMP, not_tube_findings, radius_pieces, wide_nodes

R = 6.0


def _profile(*parts):
    """Radii along a path of 1 mm steps from ``(length mm, radius at its start, radius at its end)`` parts."""
    r = np.concatenate([np.linspace(a, b, int(n)) for n, a, b in parts])
    return r, np.arange(len(r), dtype=float)


def test_radius_jump_is_judged_against_the_radii_beside_it():
    # a 2x taper over 40 radii: no cut at all
    r, s = _profile((240, 6.0, 3.0))
    assert len(radius_pieces(r, s)[1]) == 1 and not wide_nodes(r, s).any()
    # a stenosis to 0.4 r and back within two radii: the vessel on either side is no bump
    r, s = _profile((60, 6, 6), (8, 6, 2.4), (8, 2.4, 6), (60, 6, 6))
    assert len(radius_pieces(r, s)[1]) == 3 and not wide_nodes(r, s).any()
    # a chamber in the middle: wide, the vessel beside it not
    r, s = _profile((40, 6, 6), (4, 6, 13), (30, 13, 13), (4, 13, 6), (40, 6, 6))
    w = wide_nodes(r, s)
    assert w[50:70].all() and not w[:35].any() and not w[-35:].any()
    # a seed in a chamber: the end piece wider than its one neighbour
    r, s = _profile((30, 13, 13), (4, 13, 6), (60, 6, 6))
    w = wide_nodes(r, s)
    assert w[:25].all() and not w[40:].any()
    # most of the path in the chamber: the path's median would be the chamber's radius, the neighbours still tell
    r, s = _profile((20, 6, 6), (4, 6, 14), (120, 14, 14), (4, 14, 6), (20, 6, 6))
    assert np.median(r) > 13 and wide_nodes(r, s)[40:120].all()
    # a stenosis at the path's start (the seed in it) does not make the vessel after it a bump
    r, s = _profile((40, 6, 6), (6, 6, 2.5), (20, 2.5, 2.5), (6, 2.5, 6), (60, 6, 6))
    assert not wide_nodes(r, s).any()
    assert RADIUS_JUMP == 2.0


VARIANTS = {
    "taper": dict(taper=0.5),                                       # 6 mm at the root to 3 mm at the end
    "stenosis": dict(stenosis=0.6),                                 # 6 mm narrowed to 2.4 mm
    "bright-large": dict(chamber_hu=450.0, bone_hu=600.0, chamber_scale=3.0, bone_scale=2.2),
}


def _seed_path(ph, S):
    """The seed path between ``S`` on ``ph``, radii from the image (LPS), and its findings."""
    from porecad.vessels.ct_segment import Volume, guide_by_image
    from porecad.vessels.seed_path import seed_centreline
    vol = Volume(ph.array, ph.geometry)
    g, _ = seed_centreline(S, vol)
    guide_by_image(g, vol, "lps")
    return g, not_tube_findings(g, g.tube_map.tubeness(g.points))


@pytest.fixture(scope="module")
def variant_paths():
    """Per variant, built when first asked for: the phantom, the seed path from its two ends, its findings."""
    cache = {}

    def get(name):
        if name not in cache:
            ph = arch_phantom(R, seed=3, **VARIANTS[name])
            cache[name] = (ph, *_seed_path(ph, ph.ends))
        return cache[name]
    return get


@pytest.mark.parametrize("name", list(VARIANTS))
def test_variants_follow_the_vessel_without_false_warnings(variant_paths, name):
    ph, g, found = variant_paths(name)
    d = ph.distance(g.points)                         # the path's nodes against the true surface
    true_r = ph.axis[1]
    assert d.max() < -0.25 * true_r.min(), d.max()    # every node inside the true vessel
    assert not found, [f.message for f in found]
    assert g.radii.max() <= 1.5 * true_r.max()
    if name == "taper":                               # the 2x taper is measured, not flattened
        assert g.radii.max() / g.radii.min() > 1.6


def test_a_shortcut_is_never_silent():
    """Seeds that invite a shortcut: a larger, brighter chamber and spine and the descending aorta narrowed to
    0.2 r (the path through the chamber and the spine is cheaper than through the stenosis) — the path leaves
    the vessel, and a ``path-not-tube`` finding says where; at 0.3 r the path keeps to the vessel, no finding."""
    kw = dict(chamber_hu=450.0, bone_hu=600.0, chamber_scale=3.0, bone_scale=2.2)
    ph = arch_phantom(R, seed=3, stenosis=0.8, **kw)
    g, found = _seed_path(ph, ph.ends)
    assert (ph.distance(g.points) > 0).sum() > 10                    # the shortcut taken
    assert found and {f.code for f in found} == {"path-not-tube"}
    at = np.array([f.values["at"] for f in found])
    assert ph.distance(at).max() > R and "add a seed" in found[0].message   # in the chamber / spine
    ph = arch_phantom(R, seed=3, stenosis=0.7, **kw)
    g, found = _seed_path(ph, ph.ends)
    assert ph.distance(g.points).max() < 0 and not found


def test_chamber_seed_names_the_seed_to_move():
    from porecad.vessels.local_fields import tube_distance
    ph = arch_phantom(R, seed=3, chamber_scale=3.0, chamber_hu=450.0)
    S = np.stack([ph.ends[0], ph.chamber[0].mean(0)])   # the second seed in the (larger) chamber
    g, found = _seed_path(ph, S)
    assert [f.code for f in found] == ["path-not-tube"], [f.message for f in found]
    f = found[0]
    assert f.values["seed"] == 2 and "move seed 2" in f.message
    assert tube_distance(np.array([f.values["at"]]), *ph.chamber)[0] < 0


def test_a_branch_seed_narrower_than_the_vessel_is_no_false_warning():
    """Three seeds on the CT phantom (issue 39): the vessel's ends and its branch of 0.4 r — the vessel is
    judged at its own scale, the branch at the branch's: no finding, every node inside the vessel."""
    from porecad.vessels.ct_phantom import ct_phantom
    ph = ct_phantom((48, 48, 32), (1.0, 1.0, 1.5), seed=4)
    S = np.stack([ph.main[0][0] + [1, 1, 0], ph.main[0][-1] + [-1, 0.5, 0], ph.branch[0][-1]])
    g, found = _seed_path(ph, S)
    assert len(g.branches()) == 3 and not found, [f.message for f in found]
    assert ph.distance(g.points).max() < 0
