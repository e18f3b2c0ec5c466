"""Image bodies (issue 3 item 2, acceptance 4): synthetic CT volumes in physical coordinates."""


import numpy as np
import pytest

import SimpleITK as sitk

from porecad.bodies.image import index_to_physical, physical_to_index, read_image
from porecad.bodies.load import load_body
from porecad.errors import InputError

CENTRE = np.array([-10.0, 30.0, 65.0])
AXES = np.array([12.0, 9.0, 15.0])
VOLUME = 4.0 / 3.0 * np.pi * AXES.prod()
SPACING = (0.5, 0.5, 1.0)


def _ct(shape, spacing, origin, direction=np.eye(3), noise=20.0, seed=0):
    """CT-like ellipsoid: ~1000 HU inside, 0 outside, a one-voxel partial-volume rim, noise."""
    geo = {"spacing": list(spacing), "origin": list(origin), "direction": np.asarray(direction).tolist()}
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1).reshape(-1, 3)
    p = index_to_physical(ijk, geo)
    r = np.sqrt((((p - CENTRE) / AXES) ** 2).sum(axis=1)).reshape(shape)
    ct = 1000.0 * np.clip((1.0 - r) * AXES.min() / min(spacing) + 0.5, 0.0, 1.0)
    ct += np.random.default_rng(seed).normal(0.0, noise, ct.shape)
    return ct, r, geo


def _image(array, geo, dtype=np.int16):
    img = sitk.GetImageFromArray(np.ascontiguousarray(np.transpose(array, (2, 1, 0))).astype(dtype))
    img.SetSpacing(tuple(geo["spacing"]))
    img.SetOrigin(tuple(geo["origin"]))
    img.SetDirection(tuple(np.asarray(geo["direction"], dtype=float).ravel()))
    return img


def _write_dicom_series(img, folder):
    """One file per slice with the geometry tags GDCM reads back."""
    folder.mkdir()
    writer = sitk.ImageFileWriter()
    writer.KeepOriginalImageUIDOn()
    direction = img.GetDirection()
    series = "1.2.826.0.1.3680043.2.1125.1.4242"
    for k in range(img.GetDepth()):
        s = img[:, :, k]
        pos = img.TransformIndexToPhysicalPoint((0, 0, k))
        tags = {"0008|0060": "CT", "0020|000e": series, "0020|000d": series + ".1",
                "0020|0032": "\\".join(f"{c:.6f}" for c in pos), "0020|0013": str(k + 1),
                "0020|0037": "\\".join(f"{c:.6f}" for c in (direction[0], direction[3], direction[6],
                                                             direction[1], direction[4], direction[7])),
                "0028|0030": f"{img.GetSpacing()[1]:.6f}\\{img.GetSpacing()[0]:.6f}",
                "0018|0050": f"{img.GetSpacing()[2]:.6f}",
                "0008|0018": f"{series}.{k + 1}"}
        for key, value in tags.items():
            s.SetMetaData(key, value)
        writer.SetFileName(str(folder / f"slice{k:03d}.dcm"))
        writer.Execute(s)


@pytest.fixture(scope="module")
def ct_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("ct")
    ct, r, geo = _ct((80, 70, 50), SPACING, (-30.0, 12.0, 40.0))
    img = _image(ct, geo)
    files = {}
    for ext in ("nrrd", "mha", "nii.gz"):
        files[ext] = d / f"ct.{ext}"
        sitk.WriteImage(img, str(files[ext]))
    _write_dicom_series(img, d / "dicom")
    files["dicom"] = d / "dicom"
    files["label"] = d / "labels.nii.gz"
    labels = np.where(r <= 1.0, 3, 0) + np.where((r > 1.0) & (r < 1.2), 1, 0)
    sitk.WriteImage(_image(labels, geo, np.uint8), str(files["label"]))
    return files


@pytest.mark.parametrize("fmt", ["nrrd", "mha", "nii.gz", "dicom"])
def test_ct_body_volume_and_position(ct_files, fmt):
    """Acceptance 4: anisotropic spacing 0.5x0.5x1.0, non-zero origin; volume within 2 %, position kept."""
    v, f, rep = load_body(ct_files[fmt], threshold=500)
    assert rep["image"]["spacing"] == pytest.approx(SPACING)
    assert abs(rep["volume"] / VOLUME - 1.0) < 0.02
    lo, hi = np.asarray(rep["bounds"][0]), np.asarray(rep["bounds"][1])
    assert np.allclose((lo + hi) / 2, CENTRE, atol=0.5)
    assert np.allclose(hi - lo, 2 * AXES, atol=1.0)


def test_label_body(ct_files):
    v, f, rep = load_body(ct_files["label"], label=3)
    assert abs(rep["volume"] / VOLUME - 1.0) < 0.02
    assert np.allclose((v.min(0) + v.max(0)) / 2, CENTRE, atol=0.5)
    # label 1 is the shell around it: a hollow body, larger outside, no 3 inside
    v1, f1, rep1 = load_body(ct_files["label"], label=1)
    shell = 4.0 / 3.0 * np.pi * AXES.prod() * (1.2 ** 3 - 1.0)
    assert abs(rep1["volume"] / shell - 1.0) < 0.05


@pytest.mark.parametrize("direction", [
    [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],       # rotated 90° about z
    [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],       # mirrored (det -1)
    [[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]],       # oblique
])
def test_direction_matrix(tmp_path, direction):
    """A non-axis-aligned image: the body lands where the ellipsoid is in physical space, outward."""
    origin = CENTRE - np.asarray(direction) @ (np.array([40, 35, 25]) * np.array(SPACING))
    ct, _, geo = _ct((80, 70, 50), SPACING, origin, direction)
    p = tmp_path / "ct.mha"
    sitk.WriteImage(_image(ct, geo), str(p))
    arr, geo2 = read_image(p)
    assert np.allclose(geo2["direction"], direction)
    v, f, rep = load_body(p, threshold=500)
    assert rep["volume"] > 0  # outward after the mapping (faces flipped for det < 0)
    assert abs(rep["volume"] / VOLUME - 1.0) < 0.02
    assert np.allclose((v.min(0) + v.max(0)) / 2, CENTRE, atol=0.6)
    assert np.allclose(physical_to_index(index_to_physical([[1.5, 2.0, 3.0]], geo2), geo2), [[1.5, 2.0, 3.0]])


def test_largest_component_kept(tmp_path):
    ct, _, geo = _ct((80, 70, 50), SPACING, (-30.0, 12.0, 40.0), noise=0.0)
    ct[2:4, 2:4, 2:4] = 1000.0  # a speck far from the body
    p = tmp_path / "speck.nrrd"
    sitk.WriteImage(_image(ct, geo), str(p))
    v, f, rep = load_body(p, threshold=500)
    assert rep["image"]["components_removed"] == 1
    assert abs(rep["volume"] / VOLUME - 1.0) < 0.02
    v, f, rep = load_body(p, threshold=500, keep_all=True)
    assert rep["image"]["components_removed"] == 0
    assert rep["volume"] > VOLUME * 0.98 + 0.5 ** 2 * 1.0 * 8 * 0.5


def test_infill_image_body_cli(ct_files, run_json, tmp_path):
    out = tmp_path / "ct_scaffold.stl"
    rep = run_json("infill", ct_files["dicom"], "G", "--body-threshold", "500", "--porosity", "0.7",
                   "-L", "4", "--voxel", "0.4", "-o", out)
    assert out.exists() and rep["closed"] and rep["manifold"]
    assert abs(rep["body_volume"] / VOLUME - 1.0) < 0.02
    assert abs(rep["porosity"] - 0.7) < 0.02
    assert rep["body"]["image"]["rule"] == "intensity >= 500"


@pytest.mark.parametrize("args, message", [
    (["--porosity", "0.7"], "exactly one of a label value or an intensity threshold"),
    (["--porosity", "0.7", "--body-threshold", "5000"], "no voxel has intensity >= 5000"),
    (["--porosity", "0.7", "--label", "20000"], "no voxel has label 20000"),
])
def test_image_body_errors(ct_files, run_cli, tmp_path, args, message):
    out = tmp_path / "x.stl"
    code, _, err = run_cli("infill", ct_files["nrrd"], "G", *args, "-o", out)
    assert code == 2 and message in err and "Traceback" not in err
    assert not out.exists()


def test_unreadable_image(tmp_path, run_cli):
    p = tmp_path / "broken.nii.gz"
    p.write_bytes(b"not an image at all" * 10)
    code, _, err = run_cli("infill", p, "G", "--porosity", "0.7", "--label", "1", "-o", tmp_path / "x.stl")
    assert code == 2 and "not a readable image" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(InputError, match="label or intensity threshold applies to image bodies only"):
        load_body(tmp_path / "a.stl", label=1)
