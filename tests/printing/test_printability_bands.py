"""Issue 52: walls, channels and closed pores judged a band of layers at a time, at the printer's resolution."""

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from porecad.findings import codes
from porecad.printing import banded
from porecad.printing import printability as pr


def _blobs():
    f = ndimage.gaussian_filter(np.random.default_rng(1).normal(size=(60, 50, 40)), 2.5)
    solid = f > 0.0
    solid[:2] = solid[-2:] = False
    solid[:, :2] = solid[:, -2:] = False
    solid[:, :, :2] = solid[:, :, -2:] = False
    return solid


@pytest.mark.parametrize("radius", [0.15, 0.2])
def test_the_bands_find_what_the_whole_model_finds(monkeypatch, radius):
    """The same pieces, voxels and widths with one band or many (every seam inside a thin piece)."""
    solid = _blobs()
    results = []
    for window in (10**8, 40 * 50 * 12, 40 * 50 * 3):
        monkeypatch.setattr(banded, "WINDOW_VOXELS", window)
        out = banded.judge(iter(solid), solid.shape, 0.1, radius, radius)
        results.append([(len(out[k]), int(out[k][:, 0].sum()), round(float(out[k][:, 5].max(initial=0)), 6))
                        for k in ("thin-wall", "narrow-channel", "void")])
    assert results[0] == results[1] == results[2]
    assert results[0][0][0] > 5 and results[0][2][0] == 1  # thin walls found, the void in one open piece


def test_a_closed_pore_is_found_across_bands(monkeypatch):
    solid = np.zeros((40, 20, 20), bool)
    solid[3:37, 3:17, 3:17] = True
    solid[10:30, 8:12, 8:12] = False  # a cavity spanning several bands
    monkeypatch.setattr(banded, "WINDOW_VOXELS", 20 * 20 * 12)
    out = banded.judge(iter(solid), solid.shape, 0.1, 0.0, 0.0)
    closed = out["void"][out["void"][:, 6] == 0]
    assert len(closed) == 1 and closed[0, 0] == 20 * 4 * 4
    assert closed[0, 1:4] == pytest.approx([19.5, 9.5, 9.5])


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    """A 100 mm bar with one 0.2 mm fin on top (x = 30) and one 0.25 mm slot through it (x = 70)."""
    d = tmp_path_factory.mktemp("bar")
    body = trimesh.creation.box((100, 10, 4))
    body.apply_translation((50, 5, 2))
    fin = trimesh.creation.box((0.2, 8, 4.5))
    fin.apply_translation((30, 5, 6))
    slot = trimesh.creation.box((0.25, 6, 20))
    slot.apply_translation((70, 5, 2))
    part = trimesh.boolean.difference([trimesh.boolean.union([body, fin]), slot])
    assert part.is_watertight
    part.export(d / "bar.stl")
    (d / "printer.toml").write_text('name = "limits 0.3"\nbuild = [200, 200, 100]\npixel = 0.05\nlayer = 0.05\n'
                                    "min_feature = 0.3\nmin_channel = 0.3\n")
    return d


def test_a_100_mm_part_at_50_microns_finds_its_wall_and_channel(bar):
    import porecad as pc
    r = pc.slice(str(bar / "bar.stl"), str(bar / "bar.zip"), printer=str(bar / "printer.toml"), force=True)
    found = codes(r)
    assert "thin-wall" in found and "narrow-channel" in found and "check-coarse" not in found
    (wall,), (channel,) = r["checks"]["thin-wall"], r["checks"]["narrow-channel"]
    assert wall["at"][0] == pytest.approx(30.0, abs=0.2) and wall["at"][2] > 4.0  # on the fin, above the bar
    assert channel["at"][0] == pytest.approx(70.0, abs=0.2)
    assert wall["thickness"] == pytest.approx(0.2, abs=0.1) and channel["thickness"] == pytest.approx(0.25, abs=0.1)
    assert r["checks"]["voxel"] == pytest.approx(0.1)


def test_a_check_that_cannot_run_finely_enough_says_so(bar, monkeypatch):
    import porecad as pc
    monkeypatch.setattr(pr, "MAX_CHECK_VOXELS", 1_000_000)
    r = pc.slice(str(bar / "bar.stl"), str(bar / "coarse.zip"), printer=str(bar / "printer.toml"), pixel=0.1,
                 layer=0.1, force=True)
    assert "check-coarse" in codes(r)
    assert r["checks"]["voxel"] > 0.1
