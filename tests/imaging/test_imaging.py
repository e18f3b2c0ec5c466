"""Issue 10 (000 ch.6): image I/O, the spine phantom, classical segmentation, metrics, challenge layout."""

import numpy as np
import pytest
import SimpleITK as sitk

from porecad.errors import InputError
from porecad.imaging import metrics as M
from porecad.imaging.challenge import find_subjects, load_dataset, load_subject
from porecad.imaging.classical import segment_ct_bone, segment_discs
from porecad.imaging.io import read_stack, read_volume, write_volume
from porecad.imaging.phantom import CHANNELS, spine_phantom, weber_contrast, write_phantom

ROT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def phantom():
    return spine_phantom(3, seed=0)


# ---------------------------------------------------------------- metrics (acceptance 2)

def _mask(shape, *voxels):
    m = np.zeros(shape, bool)
    for v in voxels:
        m[v] = True
    return m


def test_dice_hand_computed():
    a = np.zeros((5, 5, 3), bool)
    b = np.zeros((5, 5, 3), bool)
    a[0:2, 0:2, 1] = True          # 4 voxels
    b[1:3, 0:2, 1] = True          # 4 voxels, 2 shared
    assert M.dice(a, b) == pytest.approx(2 * 2 / (4 + 4))
    assert M.dice(a, np.zeros_like(a)) == 0.0
    assert M.dice(np.zeros_like(a), np.zeros_like(a)) == 1.0


def test_surface_distances_hand_computed():
    shape = (8, 5, 5)
    x = _mask(shape, (2, 2, 2))                          # one voxel
    y = _mask(shape, (2, 2, 2), (3, 2, 2), (4, 2, 2))    # a line of three, all boundary
    # d(X->Y) = [0]; d(Y->X) = [0, 1, 2] voxels
    assert M.hausdorff(x, y) == pytest.approx(2.0)
    assert M.hausdorff(x, y, percentile=95) == pytest.approx(1.9)  # P95 of [0, 1, 2], linear
    assert M.mean_surface_distance(x, y) == pytest.approx((0 + 0 + 1 + 2) / 4)
    assert M.dice(x, y) == pytest.approx(2 * 1 / (1 + 3))
    # anisotropic spacing: the line runs along x, 2 mm per voxel
    sp = (2.0, 1.25, 1.25)
    r = M.evaluate(x, y, sp)
    assert r["hd"] == pytest.approx(4.0)
    assert r["hd95"] == pytest.approx(3.8)
    assert r["msd"] == pytest.approx(1.5)
    # symmetric
    assert M.hausdorff(y, x, sp) == pytest.approx(4.0)


def test_separated_voxels_and_boundary():
    shape = (6, 3, 3)
    a = _mask(shape, (1, 1, 1))
    b = _mask(shape, (4, 1, 1))
    assert M.hausdorff(a, b, (2.0, 1.0, 1.0)) == pytest.approx(6.0)
    assert M.mean_surface_distance(a, b, (2.0, 1.0, 1.0)) == pytest.approx(6.0)
    cube = np.zeros((5, 5, 5), bool)
    cube[1:4, 1:4, 1:4] = True
    assert int(M.boundary(cube).sum()) == 26  # the centre voxel is interior
    assert M.hausdorff(cube, np.zeros_like(cube)) == float("inf")
    assert M.hausdorff(np.zeros_like(cube), np.zeros_like(cube)) == 0.0
    with pytest.raises(InputError):
        M.dice(cube, cube[:4])


def test_evaluate_labels_matches_instances():
    t = np.zeros((10, 10, 10), int)
    t[1:4, 1:4, 1:4] = 1
    t[6:9, 6:9, 6:9] = 2
    p = np.zeros_like(t)
    p[6:9, 6:9, 6:9] = 1   # numbered differently
    p[1:4, 1:4, 1:3] = 2   # two thirds of disc 1
    r = M.evaluate_labels(t, p)
    assert r["discs"][0]["pred"] == 2 and r["discs"][0]["dice"] == pytest.approx(2 * 18 / (27 + 18))
    assert r["discs"][1]["pred"] == 1 and r["discs"][1]["dice"] == 1.0
    assert r["all"]["dice"] == pytest.approx(2 * 45 / (54 + 45))


# ---------------------------------------------------------------- phantom

def test_phantom_deterministic_and_shaped(phantom):
    again = spine_phantom(3, seed=0)
    for c in CHANNELS:
        assert np.array_equal(phantom["channels"][c], again["channels"][c])
    assert np.array_equal(phantom["labels"], again["labels"])
    other = spine_phantom(3, seed=1)
    assert not np.array_equal(phantom["channels"]["wat"], other["channels"]["wat"])
    assert phantom["geometry"]["spacing"] == [2.0, 1.25, 1.25]
    assert set(phantom["channels"]) == {"inn", "opp", "fat", "wat"}
    for c in CHANNELS:
        assert phantom["channels"][c].shape == phantom["labels"].shape
        assert phantom["channels"][c].dtype == np.float32
    labels = phantom["labels"]
    assert sorted(np.unique(labels).tolist()) == [0, 1, 2, 3]
    # discs numbered from the superior (high k) end, each a single flat piece
    kc = [np.argwhere(labels == i)[:, 2].mean() for i in (1, 2, 3)]
    assert kc[0] > kc[1] > kc[2]
    from scipy import ndimage
    for i in (1, 2, 3):
        idx = np.argwhere(labels == i)
        ext = (idx.max(0) - idx.min(0) + 1) * np.array([2.0, 1.25, 1.25])
        assert ndimage.label(labels == i)[1] == 1
        assert ext[2] < 0.6 * min(ext[0], ext[1])  # flat along the spine
        assert 25 < ext[0] < 55 and 20 < ext[1] < 45


def test_phantom_contrasts(phantom):
    """Disc bright on water/opp/in-phase, dark on fat; marrow bright on fat (000 Table 6.1 pattern)."""
    ch, lab = phantom["channels"], phantom["labels"]
    disc = lab > 0
    for c in ("wat", "opp", "inn"):
        assert ch[c][disc].mean() > ch[c][~disc].mean()
    assert ch["fat"][disc].mean() < ch["fat"][~disc].mean()
    w = {c: weber_contrast(ch[c], disc) for c in CHANNELS}
    assert w["wat"] > w["inn"] and w["opp"] > w["inn"]   # opp and wat carry the most contrast
    # vertebral marrow (just above disc 2) is brighter than the disc on fat and darker on water
    idx = np.argwhere(lab == 2)
    i, j = (int(v) for v in idx[:, :2].mean(0))
    k_top = idx[:, 2].max() + 6
    assert ch["fat"][i, j, k_top] > 3 * ch["fat"][i, j, int(idx[:, 2].mean())]
    assert ch["wat"][i, j, k_top] < ch["wat"][i, j, int(idx[:, 2].mean())]


def test_phantom_bad_parameters():
    for kw in ({"n_discs": 0}, {"n_discs": 2.5}, {"spacing": (2, 0, 1)}, {"noise": -1}):
        with pytest.raises(InputError):
            spine_phantom(**{"n_discs": 3, **kw})


# ---------------------------------------------------------------- classical segmentation

@pytest.mark.parametrize("seed,n", [(0, 3), (1, 3), (3, 4)])
def test_classical_finds_every_disc(seed, n):
    ph = spine_phantom(n, seed=seed)
    labels, info = segment_discs(ph["channels"], ph["geometry"]["spacing"])
    assert info["discs"] == n
    r = M.evaluate_labels(ph["labels"], labels, ph["geometry"]["spacing"])
    assert r["all"]["dice"] >= 0.9
    # each disc matched to its own instance, in the same (superior-first) order
    assert [d["pred"] for d in r["discs"]] == list(range(1, n + 1))
    assert min(d["dice"] for d in r["discs"]) >= 0.88


def test_classical_single_channel_and_errors(phantom):
    labels, info = segment_discs({"t2": phantom["channels"]["wat"]}, phantom["geometry"]["spacing"])
    assert info["discs"] == 3 and info["score"] == "t2"
    with pytest.raises(InputError, match="water-like"):
        segment_discs({"a": phantom["channels"]["fat"], "b": phantom["channels"]["fat"]}, (2, 1.25, 1.25))
    with pytest.raises(InputError):
        segment_discs({"wat": np.zeros((20, 20, 20), np.float32)}, (1, 1, 1))


def test_ct_bone():
    rng = np.random.default_rng(0)
    ct = rng.normal(40, 20, (40, 40, 30))
    ct[5:15, 5:15, 5:25] = 900      # bone block 1 (2000 voxels)
    ct[8:12, 8:12, 10:20] = 300     # marrow-like hole, filled by the pipeline
    ct[25:35, 20:30, 5:15] = 700    # bone block 2
    ct[30, 5, 25] = 1200            # a speck
    labels, info = segment_ct_bone(ct, (1.0, 1.0, 1.0), threshold=500, min_volume_mm3=50)
    assert info["components"] == 2
    assert np.count_nonzero(labels == 1) == 2000 and np.count_nonzero(labels == 2) == 1000
    with pytest.raises(InputError):
        segment_ct_bone(ct, (1, 1, 1), threshold=5000)


# ---------------------------------------------------------------- I/O and the challenge layout

@pytest.mark.parametrize("suffix", [".nii.gz", ".nii", ".mha", ".nrrd"])
def test_volume_round_trip(tmp_path, suffix):
    arr = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    geo = {"spacing": [2.0, 1.25, 0.5], "origin": [1.0, -2.0, 3.0], "direction": ROT.tolist()}
    p = write_volume(tmp_path / f"v{suffix}", arr, geo)
    back, g = read_volume(p)
    assert np.array_equal(back, arr)
    assert np.allclose(g["spacing"], geo["spacing"]) and np.allclose(g["origin"], geo["origin"])
    assert np.allclose(g["direction"], ROT)


def _write_dicom_series(arr, geo, folder):
    folder.mkdir()
    img = sitk.GetImageFromArray(np.ascontiguousarray(np.transpose(arr, (2, 1, 0))).astype(np.int16))
    img.SetSpacing(geo["spacing"])
    img.SetOrigin(geo["origin"])
    writer = sitk.ImageFileWriter()
    writer.KeepOriginalImageUIDOn()
    series = "1.2.826.0.1.3680043.2.1125.1.77"
    for k in range(img.GetDepth()):
        s = img[:, :, k]
        pos = img.TransformIndexToPhysicalPoint((0, 0, k))
        tags = {"0008|0060": "MR", "0020|000e": series, "0020|000d": series + ".1",
                "0020|0032": "\\".join(f"{c:.6f}" for c in pos), "0020|0013": str(k + 1),
                "0020|0037": "1\\0\\0\\0\\1\\0", "0028|0030": f"{geo['spacing'][1]:.6f}\\{geo['spacing'][0]:.6f}",
                "0018|0050": f"{geo['spacing'][2]:.6f}", "0008|0018": f"{series}.{k + 1}"}
        for key, value in tags.items():
            s.SetMetaData(key, value)
        writer.SetFileName(str(folder / f"slice{k:03d}.dcm"))
        writer.Execute(s)


def test_stack_from_dicom_channel_folders(tmp_path, phantom):
    """A subject folder with one DICOM series per channel subfolder."""
    geo = {"spacing": [2.0, 1.25, 1.25], "origin": [0.0, 0.0, 0.0]}
    subject = tmp_path / "s1"
    subject.mkdir()
    for c in ("wat", "fat"):
        _write_dicom_series(np.round(phantom["channels"][c]), geo, subject / c)
    stack, _ = load_subject(subject)
    assert stack.names == ["wat", "fat"]
    assert np.allclose(stack.geometry["spacing"], geo["spacing"])
    assert np.array_equal(stack.channels["wat"], np.round(phantom["channels"]["wat"]).astype(np.float32))


def test_challenge_layout(tmp_path):
    root = tmp_path / "Training"
    for i, seed in ((1, 0), (2, 1)):
        (root / f"{i:02d}").mkdir(parents=True)
        write_phantom(root / f"{i:02d}", spine_phantom(3, seed=seed), subject=f"{i:02d}")
    subjects = find_subjects(root)
    assert [s.name for s in subjects] == ["01", "02"]
    data = load_dataset(root)
    stack, sid = data[1]
    assert sid == "02"
    assert stack.names == ["opp", "wat", "fat", "inn"]  # 000 §6.2.7's channel order first
    assert stack.labels is not None and stack.labels.max() == 3
    assert stack.array(["opp", "wat", "fat"]).shape == (3,) + stack.shape
    only, _ = load_subject(subjects[0], channels=["wat", "opp"])
    assert only.names == ["wat", "opp"]
    with pytest.raises(InputError, match="not found"):
        load_subject(subjects[0], channels=["t2"])


def test_stack_geometry_mismatch(tmp_path):
    arr = np.ones((6, 6, 6), np.float32)
    base = {"spacing": [2.0, 1.25, 1.25], "origin": [0.0, 0.0, 0.0], "direction": np.eye(3).tolist()}
    a = write_volume(tmp_path / "a.nii.gz", arr, base)
    cases = {"spacing": {**base, "spacing": [2.0, 1.0, 1.25]}, "origin": {**base, "origin": [0.0, 5.0, 0.0]},
             "direction": {**base, "direction": ROT.tolist()}}
    for what, geo in cases.items():
        b = write_volume(tmp_path / f"b_{what}.nii.gz", arr, geo)
        with pytest.raises(InputError, match=what):
            read_stack({"wat": a, "fat": b})
    c = write_volume(tmp_path / "c.nii.gz", np.ones((6, 6, 7), np.float32), base)
    with pytest.raises(InputError, match="size"):
        read_stack({"wat": a, "fat": c})
    with pytest.raises(InputError, match="label map"):
        read_stack({"wat": a}, labels=c)
