"""Issue 51, problem 2: an image header cannot make porecad read a file outside the header's folder.

The check of a header's detached data file and the reader are one piece of
code (:mod:`porecad.io.image_header`): every way the issue's fuzz run got a
header to name another file — NRRD with CR-only line ends, a ``data file``
line after 64 KiB of comments, MetaImage ``ElementDataFile:`` (colon, also
`` : ``), a symlink beside the header — is refused, and no byte of the
outside file reaches a job or the studio. Headers with their data beside
them still read, to the voxel and to ITK's geometry.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

from porecad.cli.main import main
from porecad.errors import InputError

sitk = pytest.importorskip("SimpleITK")

#: a label-1 cube: a job that read it would succeed, so a refusal proves it was not read
SECRET = np.zeros((8, 8, 8), np.uint8)
SECRET[2:6, 2:6, 2:6] = 1
NRRD = "NRRD0004{e}type: uchar{e}dimension: 3{e}sizes: 8 8 8{e}encoding: raw{e}{pad}data file: {name}{e}{e}"
META = "ObjectType = Image{e}NDims = 3{e}DimSize = 8 8 8{e}ElementType = MET_UCHAR{e}ElementDataFile{sep}{name}{e}"


@pytest.fixture
def box(tmp_path, monkeypatch):
    """``work/`` (the job's folder, the headers) and ``outside/secret.raw`` beside it."""
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "secret.raw").write_bytes(SECRET.tobytes())
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


def _refused(capsys, header: Path) -> str:
    code = main(["infill", str(header), "G", "--label", "1", "--porosity", "0.6", "-o", "o.stl"])
    out, err = capsys.readouterr()
    assert code != 0, out
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("porecad: warning:")]
    assert len(lines) == 1 and lines[0].startswith("porecad: error:"), err
    assert "values range" not in err and "Traceback" not in err
    assert not Path("o.stl").exists()
    return lines[0]


def _hostile_headers(work: Path) -> list:
    secret = str(work.parent / "outside" / "secret.raw")
    os.symlink(secret, work / "pw.raw")
    cases = {
        "cr.nhdr": NRRD.format(e="\r", pad="", name=secret),
        "comments.nhdr": NRRD.format(e="\n", pad="#" * 79 + "\n" * 1 + ("#" * 79 + "\n") * 830, name=secret),
        "colon.mhd": META.format(e="\n", sep=": ", name=secret),
        "spaced.mha": META.format(e="\n", sep=" : ", name=secret),
        "crlf.mhd": META.format(e="\r\n", sep=":", name=secret),
        "link.nhdr": NRRD.format(e="\n", pad="", name="pw.raw"),
        "link.mhd": META.format(e="\n", sep=" = ", name="pw.raw"),
    }
    for name, text in cases.items():
        (work / name).write_text(text, newline="")
    assert len(cases["comments.nhdr"]) > 65536
    return [work / name for name in cases]


def test_the_four_readings_of_the_fuzz_run_are_refused(box, capsys):
    for header in _hostile_headers(box):
        line = _refused(capsys, header)
        assert re.search("outside (its|the header's) own folder", line), (header.name, line)


def test_no_byte_of_the_outside_file_reaches_the_reader(box):
    from porecad.bodies.image import read_image
    for header in _hostile_headers(box):
        with pytest.raises(InputError, match="outside"):
            read_image(header)


def test_a_header_longer_than_the_bound_is_refused_not_cut(box, capsys):
    from porecad.io.image_header import MAX_HEADER
    pad = ("#" * 99 + "\n") * (MAX_HEADER // 100 + 1)
    (box / "long.nhdr").write_text(NRRD.format(e="\n", pad=pad, name="/x/secret.raw"))
    assert "longer than" in _refused(capsys, box / "long.nhdr")


def test_lists_and_patterns_are_refused(box, capsys):
    (box / "a.raw").write_bytes(SECRET.tobytes())
    for name, text in {"l.nhdr": NRRD.format(e="\n", pad="", name="LIST\na.raw"),
                       "p.nhdr": NRRD.format(e="\n", pad="", name="a%d.raw 1 1 1"),
                       "l.mhd": META.format(e="\n", sep=" = ", name="LIST 2D"),
                       "p.mhd": META.format(e="\n", sep=" = ", name="a%d.raw 1 1 1")}.items():
        (box / name).write_text(text)
        assert "list or pattern" in _refused(capsys, box / name)


def test_an_analyze_pair_is_not_read(box, capsys):
    """ITK reads ``x.hdr`` with the ``x.img`` beside it (a symlink followed): porecad reads no such format."""
    sitk.WriteImage(sitk.GetImageFromArray(SECRET), str(box / "n.nii"))
    head = bytearray((box / "n.nii").read_bytes()[:348])
    head[344:348] = b"ni1\x00"
    (box / "x.hdr").write_bytes(bytes(head))
    os.symlink(box.parent / "outside" / "secret.raw", box / "x.img")
    from porecad.bodies.image import read_image
    with pytest.raises(InputError, match="not an image file porecad reads"):
        read_image(box / "x.hdr")


# ------------------------------------------------------------------------------------ legitimate files
def test_detached_headers_beside_their_data_still_read(box):
    from porecad.bodies.image import read_image
    data = np.arange(6 * 7 * 8, dtype="<i2").reshape(8, 7, 6)  # [k, j, i]
    (box / "v.raw").write_bytes(data.tobytes())
    (box / "v.nhdr").write_text("NRRD0004\r\ntype: short\r\ndimension: 3\r\nsizes: 6 7 8\r\nendian: little\r\n"
                                "encoding: raw\r\nspacings: 0.5 1 2\r\ndata file: ./v.raw\r\n")
    (box / "v.mhd").write_text("NDims = 3\nDimSize = 6 7 8\nElementType = MET_SHORT\nElementSpacing = 0.5 1 2\n"
                               "ElementDataFile : v.raw\n")
    os.symlink("v.raw", box / "alias.raw")  # a link to a file in the same folder is fine
    (box / "alias.mhd").write_text((box / "v.mhd").read_text().replace("v.raw", "alias.raw"))
    want = np.transpose(data, (2, 1, 0))
    for name in ("v.nhdr", "v.mhd", "alias.mhd"):
        arr, geo = read_image(box / name)
        assert np.array_equal(arr, want), name
        assert geo["spacing"] == [0.5, 1.0, 2.0], name


@pytest.mark.parametrize("name,compress", [("a.mha", False), ("b.mha", True), ("c.mhd", False),
                                           ("d.mhd", True), ("e.nrrd", False), ("f.nrrd", True),
                                           ("g.nhdr", False), ("h.nhdr", True)])
def test_files_written_by_itk_read_as_itk_reads_them(tmp_path, name, compress):
    from porecad.bodies.image import read_image
    rng = np.random.default_rng(3)
    arr = rng.integers(-500, 1500, size=(5, 4, 3)).astype(np.int16)  # [k, j, i]
    img = sitk.GetImageFromArray(arr)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    img.SetDirection(q.ravel().tolist())
    img.SetSpacing((0.3, 0.7, 1.9))
    img.SetOrigin((-4.0, 12.5, 3.25))
    sitk.WriteImage(img, str(tmp_path / name), compress)
    ref = sitk.ReadImage(str(tmp_path / name))
    got, geo = read_image(tmp_path / name)
    assert np.array_equal(got, np.transpose(sitk.GetArrayFromImage(ref), (2, 1, 0)))
    assert np.allclose(geo["spacing"], ref.GetSpacing())
    assert np.allclose(geo["origin"], ref.GetOrigin())
    assert np.allclose(np.ravel(geo["direction"]), ref.GetDirection())


@pytest.mark.parametrize("space", ["right-anterior-superior", "LAS", "left-posterior-superior", "scanner-xyz"])
def test_nrrd_spaces_map_to_lps_as_itk_does(tmp_path, space):
    from porecad.bodies.image import read_image
    (tmp_path / "v.raw").write_bytes(bytes(range(24)))
    (tmp_path / "v.nhdr").write_text(
        f"NRRD0005\n# c\ntype: uint8\ndimension: 3\nspace: {space}\nsizes: 2 3 4\nkinds: domain space domain\n"
        "space directions: (0,0,0.5) (0.7, 0, 0) (0,0.9,0)\nencoding: raw\nspace origin: (1,2,3)\n"
        "key:=value\ndata file: v.raw\n")
    ref = sitk.ReadImage(str(tmp_path / "v.nhdr"))
    got, geo = read_image(tmp_path / "v.nhdr")
    assert np.array_equal(got, np.transpose(sitk.GetArrayFromImage(ref), (2, 1, 0)))
    assert np.allclose(geo["spacing"], ref.GetSpacing())
    assert np.allclose(geo["origin"], ref.GetOrigin())
    assert np.allclose(np.ravel(geo["direction"]), ref.GetDirection())


# ------------------------------------------------------------------------------------------- the studio
def test_studio_uploads_are_self_contained(box):
    from porecad.studio.design import FieldError
    from porecad.studio.session import Session
    s = Session(root=box)
    secret = str(box.parent / "outside" / "secret.raw")
    uploads = {"cr.nrrd": NRRD.format(e="\r", pad="", name=secret),
               "colon.mha": META.format(e="\n", sep=": ", name=secret),
               "beside.mha": META.format(e="\n", sep=" = ", name="x.raw")}
    for name, text in uploads.items():
        with pytest.raises(InputError, match="self-contained"):
            s.save_upload(name, [text.encode()])
        assert name not in s.uploads
        assert not (s.inputs / name).exists()
        # the infill preview reads only uploads: the refused file is not one
        with pytest.raises(FieldError, match="upload it first"):
            s.body_bounds({"body": name, "body_label": 1})
    # a self-contained image is accepted and previewed
    sitk.WriteImage(sitk.GetImageFromArray(np.pad(SECRET, 2)), str(box / "ok.nrrd"))
    s.save_upload("ok.nrrd", [(box / "ok.nrrd").read_bytes()])
    lo, hi = s.body_bounds({"body": "ok.nrrd", "body_label": 1})
    assert np.all(np.asarray(hi) > np.asarray(lo))


def test_a_hostile_header_inside_the_studio_folder_is_still_refused_by_the_reader(box):
    """Belt and braces: had such a file reached ``inputs/``, the preview's reader would refuse it."""
    from porecad.bodies import load_body
    from porecad.studio.session import Session
    s = Session(root=box)
    secret = str(box.parent / "outside" / "secret.raw")
    (s.inputs / "cr.nrrd").write_text(NRRD.format(e="\r", pad="", name=secret), newline="")
    with pytest.raises(InputError, match="outside"):
        load_body(s.inputs / "cr.nrrd", label=1.0, check_intersections=False)


def test_compressed_voxels_are_inflated_only_as_far_as_the_header_announces(box, capsys):
    import gzip
    import time
    from porecad.bodies.image import read_image
    bomb = gzip.compress(bytes(64 << 20), 9)  # 64 MiB of zeros in ~64 KiB
    head = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: gzip\n"
    (box / "b.nrrd").write_bytes(head.encode() + b"\n" + bomb)
    t = time.perf_counter()
    arr, _ = read_image(box / "b.nrrd")
    assert arr.shape == (8, 8, 8) and not arr.any()
    assert time.perf_counter() - t < 2
    (box / "s.nrrd").write_bytes(head.encode() + b"byte skip: 1000000000\n\n" + bomb)
    with pytest.raises(InputError, match="byte skip"):
        read_image(box / "s.nrrd")
