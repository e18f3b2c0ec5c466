"""Issue 10 (000 §6.2): the U-Net extra — Dice loss, tiny training, checkpoints (weights only), prediction.

Needs the ``seg`` extra (PyTorch + MONAI); CI installs it.
"""

import json

import numpy as np
import pytest
import torch

from porecad.errors import InputError
from porecad.imaging.challenge import load_subject
from porecad.seg import data as D
from porecad.seg.checkpoint import load_checkpoint, save_checkpoint
from porecad.seg.nets import SegUNet3D, count_parameters
from porecad.seg.predict import build_3d, predict_3d, predict_stack
from porecad.seg.optimise import dice_loss, make_loss
from porecad.seg.train import phantom_subjects, train_3d

CH = ["opp", "wat", "fat"]


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)
    torch.manual_seed(0)


@pytest.fixture(scope="module")
def subjects():
    return phantom_subjects(2, CH, seed=40, n_discs=(3,))


@pytest.fixture(scope="module")
def tiny(subjects):
    torch.set_num_threads(1)
    return train_3d(subjects, CH, iterations=30, loc_iterations=30, features=(4, 8, 16), loc_features=(4, 8),
                    crop=(24, 28, 16), augment=False, seed=1, batch=1)


def test_dice_loss_is_eq_6_2_2():
    t = torch.zeros(1, 1, 2, 2, 2)
    t[..., 0, :, :] = 1.0                     # 4 of 8 voxels
    half = torch.zeros(1, 1, 2, 2, 2)         # sigmoid(0) = 0.5 everywhere: I = 2, ΣP = 4
    assert float(dice_loss(half, t)) == pytest.approx(1 - (2 * 2 + 1) / (4 + 4 + 1))
    sure = (2 * t - 1) * 50                   # p = T exactly: E = (2·4 + 1) / (4 + 4 + 1) = 1
    assert float(dice_loss(sure, t)) == pytest.approx(0.0, abs=1e-6)
    g = torch.Generator().manual_seed(3)
    logits = torch.randn(2, 1, 4, 4, 4, generator=g)
    target = (torch.rand(2, 1, 4, 4, 4, generator=g) > 0.6).float()
    assert float(make_loss()(logits, target)) == pytest.approx(float(dice_loss(logits, target)), rel=1e-5)


def test_segmentation_network_size():
    """000 §6.2.4.2 / Table 6.2: 3 levels of 32-64-128 channels, 3 inputs: about 1.4 M parameters."""
    m = SegUNet3D(3, (32, 64, 128))
    assert 1.3e6 < count_parameters(m) < 1.45e6
    assert m(torch.zeros(1, 3, 36, 36, 28)).shape == (1, 1, 36, 36, 28)


def test_tiny_training_loss_falls(tiny):
    _, meta, hist = tiny
    for name in ("localiser", "segmenter"):
        h = hist[name]
        assert len(h) == 30
        assert np.mean(h[-5:]) < np.mean(h[:5]) - 0.02, (name, h[:5], h[-5:])
    assert meta["channels"] == CH and meta["crop"] == [24, 28, 16]


def test_augmentation_keeps_labels_binary_and_aligned(subjects):
    from porecad.seg.optimise import apply_augment as _apply, make_augment
    img, lab = subjects[0]
    c = D.centres(lab)[1]
    x, _ = D.crop(img, c, (24, 28, 16))
    y, _ = D.crop((lab == 2)[None].astype(np.float32), c, (24, 28, 16))
    aug = make_augment(5)
    changed = 0
    for _ in range(6):
        xa, ya = _apply(aug, x, y)
        assert xa.shape == x.shape and ya.shape == y.shape
        assert set(np.unique(ya)) <= {0.0, 1.0}
        changed += int(not np.array_equal(ya, y))
        # the disc stays where the water signal is high
        assert xa[1][ya[0] > 0].mean() > xa[1][ya[0] == 0].mean()
    assert changed >= 2


def test_checkpoint_round_trip(tiny, tmp_path, subjects):
    nets, meta, _ = tiny
    path = save_checkpoint(tmp_path / "m.pt", "porecad-ivd-unet3d", meta, nets)
    side = json.loads((tmp_path / "m.pt.json").read_text(encoding="utf-8"))
    assert side["channels"] == CH and side["format"] == "porecad-ivd-unet3d"
    fmt, meta2, states = load_checkpoint(path)
    assert fmt == "porecad-ivd-unet3d" and meta2 == json.loads(json.dumps(meta))
    loc, segm = build_3d(meta2, states, path)
    img, _ = subjects[0]
    a, ca = predict_3d(img, meta, nets["localiser"], nets["segmenter"])
    b, cb = predict_3d(img, meta2, loc, segm)
    assert np.array_equal(a, b) and ca == cb
    with pytest.raises(Exception):
        save_checkpoint(tmp_path / "m.pt", "porecad-ivd-unet3d", meta, nets)  # exists, no force


class NotWeights:
    def __init__(self):
        self.payload = "arbitrary object"


def test_non_weight_checkpoints_refused(tmp_path, tiny):
    evil = tmp_path / "evil.pt"
    torch.save({"format": "porecad-ivd-unet3d", "version": 1, "meta": "{}", "nets": {"x": NotWeights()}}, evil)
    with pytest.raises(InputError, match="not a plain-weights checkpoint"):
        load_checkpoint(evil)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"PK\x03\x04 definitely not a zip archive" * 20)
    with pytest.raises(InputError, match="not a readable checkpoint"):
        load_checkpoint(garbage)
    foreign = tmp_path / "foreign.pt"
    torch.save({"weight": torch.zeros(3)}, foreign)
    with pytest.raises(InputError, match="not a porecad IVD checkpoint"):
        load_checkpoint(foreign)
    nets, meta, _ = tiny
    wrong = tmp_path / "wrong.pt"
    save_checkpoint(wrong, "porecad-ivd-unet3d", {**meta, "features": [8, 16, 32]}, nets)
    fmt, m, states = load_checkpoint(wrong)
    with pytest.raises(InputError, match="do not fit"):
        build_3d(m, states, wrong)


def test_predict_stack_shapes(tiny, tmp_path):
    from porecad.imaging.phantom import spine_phantom, write_phantom
    nets, meta, _ = tiny
    write_phantom(tmp_path, spine_phantom(3, seed=77))
    stack, _ = load_subject(tmp_path)
    path = save_checkpoint(tmp_path / "m.pt", "porecad-ivd-unet3d", meta, nets)
    labels, info = predict_stack(stack, path)
    assert labels.shape == stack.shape and labels.dtype == np.int16
    assert info["segmenter"] == "unet3d" and info["discs"] == int(labels.max())
    only_t2 = type(stack)({"t2": stack.channels["wat"]}, stack.geometry)
    with pytest.raises(InputError, match="needs channel"):
        predict_stack(only_t2, path)


def test_crop_and_paste_at_borders():
    vol = np.arange(5 * 6 * 7, dtype=np.float32).reshape(1, 5, 6, 7)
    patch, start = D.crop(vol, (0, 0, 0), (4, 4, 4))
    assert start == (-2, -2, -2)
    assert np.array_equal(patch[0, 2:, 2:, 2:], vol[0, :2, :2, :2]) and patch[0, 0].sum() == 0
    out = np.zeros((5, 6, 7), np.int16)
    D.paste(out, patch[0] > 0, start, 3)
    assert np.count_nonzero(out == 3) == 7  # the 2x2x2 corner minus the zero voxel at the origin
    assert D.coarse(np.ones((1, 5, 6, 7)), (1, 2, 2)).shape == (1, 5, 3, 3)


def test_seg_cli_train_predict(tmp_path, run_json, one_line_error):
    from porecad.imaging.phantom import spine_phantom, write_phantom
    ck = tmp_path / "cli.pt"
    r = run_json("seg", "train", "--phantoms", "1", "--iterations", "3", "--features", "4,8", "--threads", "1",
                 "--no-augment", "-o", ck)
    assert ck.exists() and (tmp_path / "cli.pt.json").exists() and r["model"] == "3d"
    one_line_error("seg", "train", "--phantoms", "1", "--iterations", "3", "-o", ck, match="already exists")
    sub = tmp_path / "sub"
    sub.mkdir()
    write_phantom(sub, spine_phantom(3, seed=8))
    p = run_json("seg", "predict", sub, "--checkpoint", ck, "-o", tmp_path / "pred.nii.gz", "--threads", "1")
    assert (tmp_path / "pred.nii.gz").exists() and "metrics" in p
    evil = tmp_path / "evil.pt"
    torch.save(NotWeights(), evil)
    one_line_error("seg", "predict", sub, "--checkpoint", evil, "-o", tmp_path / "x.nii.gz",
                   match="not a plain-weights checkpoint")
    assert not (tmp_path / "x.nii.gz").exists()
    one_line_error("ivd", sub, "--segmenter", "unet", "--checkpoint", evil, "-o", tmp_path / "o",
                   match="not a plain-weights checkpoint")
    one_line_error("seg", "train", "-o", tmp_path / "n.pt", match="--phantoms")
    one_line_error("seg", "train", "--phantoms", "1", "--features", "4", "-o", tmp_path / "n.pt", match="--features")


def test_2d_slices_train_and_predict(subjects, tmp_path):
    from porecad.seg.slices import build_2d, predict_2d, train_2d
    nets, meta, hist = train_2d(subjects, CH, iterations=4, features=(4, 8), augment=True, batch=2, seed=0)
    assert set(hist) == {"x", "y", "z"} and all(len(h) == 4 for h in hist.values())
    path = save_checkpoint(tmp_path / "m2.pt", "porecad-ivd-unet2d", meta, nets)
    fmt, m, states = load_checkpoint(path)
    models = build_2d(m, states, path)
    img, _ = subjects[0]
    labels, info = predict_2d(img, m, models)
    assert labels.shape == img.shape[1:] and set(info["directions"]) == {"x", "y", "z"}


def test_seg_cli_train_on_challenge_folder_and_2d(tmp_path, run_json, one_line_error):
    """`seg train DATA_DIR` reads every labelled subject of a challenge-layout folder; `--model 2d` too."""
    from porecad.imaging.phantom import spine_phantom, write_phantom
    data = tmp_path / "Training"
    for i in (1, 2):
        (data / f"{i:02d}").mkdir(parents=True)
        write_phantom(data / f"{i:02d}", spine_phantom(3, seed=20 + i), subject=f"{i:02d}")
    r = run_json("seg", "train", data, "--iterations", "2", "--features", "4,8", "--threads", "1", "-o",
                 tmp_path / "d.pt")
    assert r["subjects"] == 2 and r["meta"]["training"]["discs"] == 6
    r2 = run_json("seg", "train", data, "--model", "2d", "--iterations", "2", "--features", "4,8", "--threads", "1",
                  "-o", tmp_path / "d2.pt")
    assert r2["model"] == "2d" and set(r2["meta"]["slice_size"]) == {"x", "y", "z"}
    p = run_json("seg", "predict", data / "01", "--checkpoint", tmp_path / "d2.pt", "-o", tmp_path / "p2.nii.gz")
    assert p["segmenter"] == "unet2d" and (tmp_path / "p2.nii.gz").exists()
    (data / "02" / "02_Labels.nii.gz").unlink()
    one_line_error("seg", "train", data, "--iterations", "2", "-o", tmp_path / "e.pt", match="no label map")
    assert not (tmp_path / "e.pt").exists()
