"""Issue 10 (000 ch.6): `porecad phantom spine`, `porecad ivd`, `porecad seg evaluate`, bad input."""

import json

import numpy as np
import pytest

from porecad.imaging.io import read_volume, write_volume
from porecad.io import read_mesh
from porecad.jobs.ivd_job import available_methods
from porecad.mesh.validate import check_solid


@pytest.fixture(scope="module")
def spine(tmp_path_factory):
    from porecad.cli import main
    d = tmp_path_factory.mktemp("spine") / "sp"
    assert main(["phantom", "spine", "-o", str(d), "--seed", "2", "--discs", "3"]) == 0
    return d


def _closed(path):
    v, f = read_mesh(path)
    chk = check_solid(v, f)
    return chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"] and len(f) > 100


def test_phantom_spine_cli(run_json, one_line_error, tmp_path):
    out = tmp_path / "ph"
    r = run_json("phantom", "spine", "-o", out, "--discs", "4", "--seed", "5")
    assert len(r["discs"]) == 4
    for name in ("inn", "opp", "fat", "wat", "labels"):
        assert (out / r["files"][name].split("/")[-1]).exists()
    lab, geo = read_volume(out / "01_Labels.nii.gz")
    assert sorted(np.unique(lab).astype(int).tolist()) == [0, 1, 2, 3, 4]
    assert geo["spacing"] == pytest.approx([2.0, 1.25, 1.25])
    assert r["weber_contrast"]["wat"] > r["weber_contrast"]["inn"]
    one_line_error("phantom", "spine", "-o", out, match="already exists")
    assert run_json("phantom", "spine", "-o", out, "--force", "--discs", "4", "--seed", "5")["seed"] == 5
    one_line_error("phantom", "spine", "-o", tmp_path / "bad", "--discs", "0", match="--discs")


def test_ivd_classical_every_method_one_disc(spine, run_json, tmp_path):
    """Acceptance 3: a closed, manifold porous scaffold for each available method (disc 2) and a report."""
    out = tmp_path / "all"
    r = run_json("ivd", spine, "--segmenter", "classical", "--method", "all", "--discs", "2", "-o", out)
    methods = available_methods()
    assert set(r["methods"]) == set(methods) and r["skipped_methods"] == []
    assert len(r["discs"]) == 1 and r["discs"][0]["disc"] == 2
    d = r["discs"][0]
    assert _closed(d["body"]["file"])
    assert 4000 < d["body"]["volume_mm3"] < 14000  # a ~40 x 30 x 9 mm disc
    for m in methods:
        s = d["scaffolds"][m]
        assert s["closed"] and s["manifold"], m
        assert _closed(out / f"disc_02_{m}.stl"), m
        assert 0.05 < s["porosity"] < 0.95, (m, s["porosity"])
    rep = json.loads((out / "ivd_report.json").read_text(encoding="utf-8"))
    assert rep["discs"][0]["scaffolds"].keys() == d["scaffolds"].keys()
    assert "<table" in (out / "ivd_report.html").read_text(encoding="utf-8")
    assert rep["metrics"]["all"]["dice"] >= 0.8


def test_ivd_classical_tpms_every_disc(spine, run_json, run_cli, tmp_path):
    out = tmp_path / "tpms"
    r = run_json("ivd", spine, "--method", "tpms", "-o", out)
    assert [d["disc"] for d in r["discs"]] == [1, 2, 3]
    seg, geo = read_volume(out / "segmentation.nii.gz")
    assert seg.max() == 3 and geo["spacing"] == pytest.approx([2.0, 1.25, 1.25])
    for d in r["discs"]:
        assert _closed(out / f"disc_{d['disc']:02d}_tpms.stl")
        assert _closed(out / f"disc_{d['disc']:02d}_body.stl")
        # the body sits where the disc is in the image (physical mm)
        v, _ = read_mesh(out / f"disc_{d['disc']:02d}_body.stl")
        assert np.linalg.norm(v.mean(0) - np.array(d["centre_mm"])) < 3.0
    m = r["metrics"]
    assert m["all"]["dice"] >= 0.85 and len(m["discs"]) == 3
    assert 0 < m["all"]["msd"] < m["all"]["hd95"] <= m["all"]["hd"]
    code, _, err = run_cli("ivd", spine, "--method", "tpms", "-o", out)
    assert code != 0 and "already exists" in err and len(err.strip().splitlines()) == 1


def _copy_subject(src, dst):
    import shutil
    shutil.copytree(src, dst)
    return dst


def test_ivd_bad_input(spine, one_line_error, tmp_path):
    """Acceptance 5: mismatched channel geometry, wrong dimensions, corrupted files: one line, no output."""
    wat, geo = read_volume(spine / "01_wat.nii.gz")
    bad = _copy_subject(spine, tmp_path / "mismatch")
    write_volume(bad / "01_fat.nii.gz", wat, {**geo, "spacing": [2.0, 1.0, 1.25]}, force=True)
    one_line_error("ivd", bad, "-o", tmp_path / "o1", match="does not match")
    assert not (tmp_path / "o1").exists()
    flat = _copy_subject(spine, tmp_path / "flat")
    import SimpleITK as sitk
    sitk.WriteImage(sitk.GetImageFromArray(np.zeros((30, 40), np.float32)), str(flat / "01_opp.nii.gz"))
    one_line_error("ivd", flat, "-o", tmp_path / "o2", match="3-D")
    broken = _copy_subject(spine, tmp_path / "broken")
    (broken / "01_inn.nii.gz").write_bytes(b"\x1f\x8b this is not a NIfTI file" * 10)
    one_line_error("ivd", broken, "-o", tmp_path / "o3", match="not a readable image")
    one_line_error("ivd", tmp_path / "nothing", "-o", tmp_path / "o4", match="no such file")
    empty = tmp_path / "empty"
    empty.mkdir()
    one_line_error("ivd", empty, "-o", tmp_path / "o5", match="no images found")
    one_line_error("ivd", spine, "--discs", "7", "-o", tmp_path / "o6", match="discs 1..3")
    one_line_error("ivd", spine, "--segmenter", "unet", "-o", tmp_path / "o7", match="--checkpoint")
    for o in ("o2", "o3", "o4", "o5", "o7"):
        assert not (tmp_path / o).exists()


def test_ivd_scaffolds_keep_to_max_memory(spine, one_line_error, tmp_path):
    """Issue 51: every disc's scaffold is sized before work against --max-memory, as any job's is."""
    one_line_error("ivd", spine, "--discs", "1", "--method", "tpms", "-o", tmp_path / "m", "--max-memory", "50MB",
                   match="memory limit")


def test_seg_evaluate_cli(spine, run_json, one_line_error, tmp_path):
    lab, geo = read_volume(spine / "01_Labels.nii.gz")
    pred = lab.copy()
    pred[pred == 3] = 0
    write_volume(tmp_path / "pred.nii.gz", pred, geo)
    r = run_json("seg", "evaluate", spine / "01_Labels.nii.gz", tmp_path / "pred.nii.gz")
    n = [np.count_nonzero(lab == i) for i in (1, 2, 3)]
    assert r["all"]["dice"] == pytest.approx(2 * (n[0] + n[1]) / (sum(n) + n[0] + n[1]))
    assert [d["dice"] for d in r["discs"]] == [1.0, 1.0, 0.0]
    write_volume(tmp_path / "other.nii.gz", pred, {**geo, "origin": [0.0, 0.0, 9.0]})
    one_line_error("seg", "evaluate", spine / "01_Labels.nii.gz", tmp_path / "other.nii.gz", match="origin")


def test_segmentation_commands_without_extra(spine, one_line_error, monkeypatch, tmp_path):
    """Acceptance 4: without porecad[seg] the segmentation commands say how to install it."""
    import porecad.seg as segpkg

    def missing():
        raise ImportError("No module named 'torch'")

    monkeypatch.setattr(segpkg, "_import_torch", missing)
    hint = "pip install 'porecad[seg]'"
    one_line_error("seg", "train", "--phantoms", "1", "-o", tmp_path / "m.pt", match=hint)
    one_line_error("seg", "predict", spine, "--checkpoint", tmp_path / "m.pt", "-o", tmp_path / "p.nii.gz",
                   match=hint)
    (tmp_path / "m.pt").write_bytes(b"x")
    one_line_error("ivd", spine, "--segmenter", "unet", "--checkpoint", tmp_path / "m.pt", "-o", tmp_path / "o",
                   match=hint)
    assert not (tmp_path / "o").exists()


def test_seg_classical_cli(spine, run_json, one_line_error, tmp_path):
    r = run_json("seg", "classical", spine, "-o", tmp_path / "c.nii.gz")
    assert r["discs"] == 3 and r["metrics"]["all"]["dice"] >= 0.85
    lab, geo = read_volume(tmp_path / "c.nii.gz")
    assert lab.max() == 3
    # CT bone on one image
    ct = np.full((30, 30, 30), -50.0)
    ct[5:15, 5:15, 5:15] = 800.0
    ct[20:28, 20:28, 20:28] = 600.0
    write_volume(tmp_path / "ct.nii.gz", ct, {"spacing": [1.0, 1.0, 1.0], "origin": [0.0, 0.0, 0.0],
                                              "direction": np.eye(3).tolist()})
    r = run_json("seg", "classical", tmp_path / "ct.nii.gz", "--ct-bone", "--threshold", "300", "-o",
                 tmp_path / "bone.nii.gz")
    assert r["components"] == 2 and r["volumes_mm3"] == [1000.0, 512.0]
    one_line_error("seg", "classical", spine, "--ct-bone", "-o", tmp_path / "x.nii.gz", match="one CT image")


def test_ivd_unet_segmenter_plumbing(spine, run_json, monkeypatch, tmp_path):
    """`--segmenter unet` hands the stack and checkpoint to the U-Net predictor and builds from its labels
    (the predictor is replaced by one returning disc 3 of the ground truth; training is tested in test_seg)."""
    import porecad.seg.predict as pred

    seen = {}

    def fake_predict(stack, checkpoint, log=None):
        seen["checkpoint"] = str(checkpoint)
        seen["channels"] = stack.names
        return (stack.labels == 3).astype(np.int16), {"segmenter": "unet3d", "discs": 1}

    monkeypatch.setattr(pred, "predict_stack", fake_predict)
    ck = tmp_path / "m.pt"
    ck.write_bytes(b"unused")
    r = run_json("ivd", spine, "--segmenter", "unet", "--checkpoint", ck, "--method", "tpms", "-o", tmp_path / "o")
    assert seen == {"checkpoint": str(ck), "channels": ["opp", "wat", "fat", "inn"]}
    assert r["segmentation"]["segmenter"] == "unet3d" and len(r["discs"]) == 1
    assert _closed(tmp_path / "o" / "disc_01_tpms.stl")
    assert r["metrics"]["discs"][2]["dice"] == 1.0 and r["metrics"]["discs"][0]["dice"] == 0.0
