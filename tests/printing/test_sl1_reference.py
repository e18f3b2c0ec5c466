"""porecad's .sl1 against one PrusaSlicer wrote (tests/data/prusaslicer-2.5-L.sl1, see tests/data/README.md)."""

import io
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

REFERENCE = Path(__file__).resolve().parents[1] / "data" / "prusaslicer-2.5-L.sl1"


def _ini(z: zipfile.ZipFile, name: str) -> dict:
    out = {}
    for line in z.read(name).decode().splitlines():
        if "=" in line:
            k, v = line.split("=", 1)
            out[k.strip()] = v.strip()
    return out


def _layers(z: zipfile.ZipFile, job: str) -> list:
    return sorted(n for n in z.namelist() if re.fullmatch(re.escape(job) + r"\d{5}\.png", n))


def _mask(z: zipfile.ZipFile, name: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(z.read(name)))) > 127


@pytest.fixture(scope="module")
def ours(tmp_path_factory):
    import trimesh
    from shapely.geometry import Polygon

    import porecad as pc
    d = tmp_path_factory.mktemp("sl1ref")
    trimesh.creation.extrude_polygon(Polygon([(0, 0), (10, 0), (10, 3), (3, 3), (3, 8), (0, 8)]), 2.0).export(
        d / "L.stl")
    (d / "ps.toml").write_text(  # PrusaSlicer's default SLA printer's display (prusaslicer.ini of the reference)
        'name = "PrusaSlicer default SLA"\nbuild = [120.0, 68.0, 150.0]\ndisplay_pixels_x = 2560\n'
        'display_pixels_y = 1440\ndisplay_width = 120.0\ndisplay_height = 68.0\ndisplay_orientation = "portrait"\n'
        "display_mirror_x = true\ndisplay_mirror_y = false\nlayer = 0.25\n")
    pc.slice(str(d / "L.stl"), str(d / "L.sl1"), printer=str(d / "ps.toml"), force=True)
    return zipfile.ZipFile(d / "L.sl1")


@pytest.fixture(scope="module")
def theirs():
    return zipfile.ZipFile(REFERENCE)


def test_same_files_and_config_keys(ours, theirs):
    a, b = _ini(theirs, "config.ini"), _ini(ours, "config.ini")
    assert set(b) == set(a)
    assert b["layerHeight"] == "0.25" and a["layerHeight"] == "0.25"
    assert _layers(ours, b["jobDir"]) and _layers(theirs, a["jobDir"])
    assert {"config.ini", "prusaslicer.ini"} <= set(ours.namelist())
    # every file besides the layers is one PrusaSlicer writes (the CLI writes no thumbnails; the GUI does)
    extra = set(ours.namelist()) - set(theirs.namelist()) - set(_layers(ours, b["jobDir"]))
    assert all(n.startswith("thumbnail/thumbnail") and n.endswith(".png") for n in extra), extra


def test_display_keys_and_images_alike(ours, theirs):
    a, b = _ini(theirs, "prusaslicer.ini"), _ini(ours, "prusaslicer.ini")
    for k in ("display_orientation", "display_mirror_x", "display_mirror_y", "display_pixels_x", "display_pixels_y"):
        assert b[k] == a[k], k
    for k in ("display_width", "display_height", "layer_height"):
        assert float(b[k]) == float(a[k]), k
    la, lb = _layers(theirs, "L"), _layers(ours, _ini(ours, "config.ini")["jobDir"])
    ia = Image.open(io.BytesIO(theirs.read(la[0])))
    ib = Image.open(io.BytesIO(ours.read(lb[0])))
    assert ia.size == ib.size == (1440, 2560) and ia.mode == ib.mode == "L"


def test_the_part_lands_turned_and_mirrored_alike(ours, theirs):
    """The L's mid layer, both centred on their own centroids: the same pixels within its rim."""
    la, lb = _layers(theirs, "L"), _layers(ours, _ini(ours, "config.ini")["jobDir"])
    ma, mb = _mask(theirs, la[len(la) // 2]), _mask(ours, lb[len(lb) // 2])
    assert abs(int(mb.sum()) - int(ma.sum())) <= 0.01 * ma.sum()
    shift = np.rint(np.argwhere(ma).mean(axis=0) - np.argwhere(mb).mean(axis=0)).astype(int)
    moved = np.roll(mb, tuple(shift), axis=(0, 1))
    iou = (moved & ma).sum() / (moved | ma).sum()
    assert iou > 0.97, iou
    # a mirrored or turned L does not fit: the check can fail
    for wrong in (mb[::-1], mb[:, ::-1]):
        s = np.rint(np.argwhere(ma).mean(axis=0) - np.argwhere(wrong).mean(axis=0)).astype(int)
        w = np.roll(wrong, tuple(s), axis=(0, 1))
        assert (w & ma).sum() / (w | ma).sum() < 0.8
