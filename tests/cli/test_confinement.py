"""Issue 41: a shared recipe or image cannot touch files outside its own folder; no hang on any input.

Each case of the issue's independent fuzz run is reproduced here and must end
as a one-line refusal (or, for signals, a clean stop) with nothing written
outside the intended folder and no existing file changed.
"""

from __future__ import annotations

import gzip
import json
import os
import random
import re
import signal
import struct
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from porecad.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def _refused(capsys, argv, match=None) -> str:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code != 0, out
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("porecad: warning:")]
    assert len(lines) == 1 and lines[0].startswith("porecad: error:"), err
    assert "Traceback" not in err
    if match:
        assert re.search(match, lines[0]), lines[0]
    return lines[0]


def _snapshot(where: Path) -> dict:
    """Every path under ``where`` with its size and modification time (symlinks not followed)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(where, followlinks=False):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            out[str(p)] = (st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture
def shared(tmp_path, monkeypatch):
    """A recipe folder ``shared/`` with a small valid recipe, beside an ``outside/`` folder holding a file."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "shared").mkdir()
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "victim.stl").write_bytes(b"do not touch")
    assert main(["tpms", "G", "--structure", "sheet", "--threshold", "0.3", "--cells", "1", "1", "1",
                 "--cell-size", "2", "--resolution", "10", "-o", "shared/g.stl", "--recipe", "shared/g.toml"]) == 0
    (tmp_path / "shared" / "g.stl").unlink()
    return tmp_path


def _with_output(recipe_file: Path, **outputs) -> None:
    recipe = recipe_file
    text = recipe.read_text()
    text = re.sub(r"\[output\][^\[]*", "", text)
    text += "\n[output]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in outputs.items())
    recipe.write_text(text)


# ---------------------------------------------------------------------------------------------- outputs
@pytest.mark.parametrize("key,value,match", [
    ("mesh", "{outside}/victim.stl", "absolute path"),
    ("report", "/tmp/porecad-escape-test.json", "absolute path"),
    ("mesh", "../outside/victim.stl", r"leaves the recipe's folder"),
    ("mesh", "~/porecad-escape.stl", "home folder"),
    ("mesh", "link/victim.stl", "symbolic link"),
    ("recipe", "sub/../../outside/r.toml", r"leaves the recipe's folder"),
])
def test_recipe_outputs_stay_in_the_recipe_folder(shared, capsys, key, value, match):
    os.symlink(shared / "outside", shared / "shared" / "link")
    value = value.format(outside=shared / "outside")
    outputs = {"mesh": "ok.stl", key: value}
    _with_output(shared / "shared" / "g.toml", **outputs)
    home = Path.home()
    before = _snapshot(shared / "outside"), sorted(os.listdir(home)), os.path.exists("/tmp/porecad-escape-test.json")
    err = _refused(capsys, ["build", "shared/g.toml", "--force"], match)
    assert f"output.{key}" in err
    after = _snapshot(shared / "outside"), sorted(os.listdir(home)), os.path.exists("/tmp/porecad-escape-test.json")
    assert after == before
    assert not (shared / "shared" / "ok.stl").exists()  # refused before any work


def test_recipe_outputs_inside_the_folder_or_out_dir(shared, capsys):
    (shared / "shared" / "sub").mkdir()
    _with_output(shared / "shared" / "g.toml", mesh="sub/g.stl", report="g.json")
    assert main(["build", "shared/g.toml"]) == 0
    assert (shared / "shared" / "sub" / "g.stl").stat().st_size > 84
    (shared / "elsewhere" / "sub").mkdir(parents=True)
    assert main(["build", "shared/g.toml", "--out-dir", "elsewhere"]) == 0
    assert (shared / "elsewhere" / "sub" / "g.stl").stat().st_size > 84
    assert json.loads((shared / "elsewhere" / "g.json").read_text())["mesh_file"].endswith("sub/g.stl")


def test_saved_recipe_keeps_outputs_beside_itself(tmp_path, monkeypatch):
    """A recipe saved in another folder than its mesh reruns beside itself (a shared copy writes nowhere else)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "recipes").mkdir()
    assert main(["tpms", "P", "--threshold", "0.3", "--cells", "1", "1", "1", "--resolution", "8",
                 "-o", "out/p.stl", "--recipe", "recipes/p.toml"]) == 0
    assert 'mesh = "p.stl"' in (tmp_path / "recipes" / "p.toml").read_text()
    assert main(["build", "recipes/p.toml"]) == 0
    assert (tmp_path / "recipes" / "p.stl").exists()


def test_force_replaces_only_regular_files(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    os.mkfifo(tmp_path / "pipe.stl")
    os.symlink("/dev/null", tmp_path / "null.stl")
    for target in ("pipe.stl", "null.stl"):
        _refused(capsys, ["tpms", "P", "--threshold", "0.3", "--cells", "1", "1", "1", "--resolution", "8",
                          "-o", target, "--force"], "not a regular file")
    assert (tmp_path / "pipe.stl").is_fifo()
    assert os.readlink(tmp_path / "null.stl") == "/dev/null"


@pytest.mark.parametrize("name,match", [
    ("a\x00b.stl", "NUL"),
    ("x" * 300 + ".stl", "bytes long"),
    ("\udcff.stl", "cannot be encoded"),
])
def test_odd_output_names_refused_in_one_line(tmp_path, monkeypatch, capsys, name, match):
    monkeypatch.chdir(tmp_path)
    _refused(capsys, ["tpms", "P", "--threshold", "0.3", "--cells", "1", "1", "1", "--resolution", "8",
                      "-o", name, "--recipe", "r.toml"], match)
    assert os.listdir(tmp_path) == []


def test_output_set_is_all_or_nothing_when_the_report_fails(tmp_path, monkeypatch):
    """When the last output (the report) fails, the mesh and the recipe written before it go too."""
    from porecad.errors import OutputError
    from porecad.jobs import run_recipe, runner

    def broken(*args, **kwargs):
        raise OutputError("disk full (simulated)")

    monkeypatch.setattr(runner, "write_report_output", broken)
    recipe = {"job": "tpms", "tpms": {"type": "P", "threshold": 0.3}, "domain": {"cells": [1, 1, 1]},
              "sampling": {"resolution": 8},
              "output": {"mesh": str(tmp_path / "m.stl"), "recipe": str(tmp_path / "m.toml"),
                         "report": str(tmp_path / "m.json")}}
    with pytest.raises(OutputError):
        run_recipe(recipe)
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------------------------- inputs
def _meta_header(path: Path, data_file: str, dims=(8, 8, 8)) -> Path:
    path.write_text("ObjectType = Image\nNDims = 3\nDimSize = " + " ".join(map(str, dims)) +
                    "\nElementType = MET_UCHAR\nElementSpacing = 1 1 1\nElementDataFile = " + data_file + "\n")
    return path


def _nrrd_header(path: Path, data_file: str) -> Path:
    path.write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n"
                    f"data file: {data_file}\n\n")
    return path


def test_image_headers_read_only_beside_themselves(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    (tmp_path / "outside.raw").write_bytes(b"\x01" * 512)
    os.mkfifo(tmp_path / "sub" / "fifo.raw")
    os.symlink("/dev/zero", tmp_path / "sub" / "zero.raw")
    (tmp_path / "sub" / "small.raw").write_bytes(b"\x00" * 4096)
    cases = [
        (_meta_header(tmp_path / "sub" / "a.mha", "/etc/passwd"), "outside its own folder"),
        (_meta_header(tmp_path / "sub" / "b.mhd", "../outside.raw"), "outside its own folder"),
        (_meta_header(tmp_path / "sub" / "c.mha", "zero.raw", (1024, 1024, 1024)), "system file"),
        (_meta_header(tmp_path / "sub" / "c2.mha", "small.raw", (1024, 1024, 1024)), "announces"),
        (_meta_header(tmp_path / "sub" / "d.mha", "zero.raw"), "system file"),
        (_meta_header(tmp_path / "sub" / "e.mhd", "fifo.raw"), "FIFO"),
        (_meta_header(tmp_path / "sub" / "f.mhd", "LIST"), "list or pattern"),
        (_nrrd_header(tmp_path / "sub" / "g.nhdr", "/etc/passwd"), "outside its own folder"),
        (_nrrd_header(tmp_path / "sub" / "h.nhdr", "../../outside.raw"), "outside its own folder"),
    ]
    for header, match in cases:
        t = time.perf_counter()
        _refused(capsys, ["infill", header, "G", "--label", "1", "--porosity", "0.6", "-o", "o.stl"], match)
        assert time.perf_counter() - t < 30  # a hang guard, not a speed goal (bench/untrusted.py times it)
    assert not (tmp_path / "o.stl").exists()


def test_image_header_with_its_data_beside_it_still_reads(tmp_path):
    from porecad.bodies.image import read_image
    data = np.zeros((8, 8, 8), np.uint8)
    data[2:6, 2:6, 2:6] = 1
    (tmp_path / "v.raw").write_bytes(data.tobytes())
    _meta_header(tmp_path / "v.mhd", "v.raw")
    arr, geo = read_image(tmp_path / "v.mhd")
    assert arr.shape == (8, 8, 8) and arr.sum() == 64


def test_studio_refuses_a_header_with_a_detached_data_file(tmp_path):
    from porecad.errors import InputError
    from porecad.studio.session import Session
    s = Session(root=tmp_path)
    (tmp_path / "x.raw").write_bytes(b"\x00" * 512)
    header = _meta_header(tmp_path / "x.mha", "x.raw").read_bytes()
    with pytest.raises(InputError, match="self-contained"):
        s.save_upload("x.mha", [header])
    assert "x.mha" not in s.uploads
    header = _nrrd_header(tmp_path / "y.nrrd", "y.raw").read_bytes()
    with pytest.raises(InputError, match="self-contained"):
        s.save_upload("y.nrrd", [header])


@pytest.mark.parametrize("kind", ["fifo", "zero", "dir", "proc"])
@pytest.mark.parametrize("suffix,cmd", [
    (".stl", ["infill", "{p}", "G", "--porosity", "0.6", "-o", "o.stl"]),
    (".3mf", ["analyze", "{p}"]),
    (".json", ["vessel", "{p}", "-o", "o.stl"]),
    (".toml", ["build", "{p}"]),
])
def test_readers_refuse_special_files(tmp_path, monkeypatch, capsys, kind, suffix, cmd):
    monkeypatch.chdir(tmp_path)
    p = tmp_path / f"special{suffix}"
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "zero":
        os.symlink("/dev/zero", p)
    elif kind == "dir":
        p.mkdir()
    else:
        os.symlink("/proc/self/mem", p)
    _refused(capsys, [a.format(p=p) for a in cmd])
    assert not (tmp_path / "o.stl").exists()


def test_grading_points_file_from_proc_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    import trimesh
    os.symlink("/proc/self/mem", tmp_path / "p.csv")
    trimesh.creation.box((10, 10, 10)).export(tmp_path / "box.stl")
    _refused(capsys, ["infill", "box.stl", "G", "--porosity-points", "p.csv", "-o", "o.stl"], "system file")


def _nested_3mf(path: Path, levels: int = 10, fan: int = 10) -> Path:
    """A 3MF whose components nest ``levels`` deep, ``fan`` each: fan**levels placements of a 12-triangle box."""
    verts = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for z in (0, 1) for y in (0, 1) for x in (0, 1))
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in
                   [(0, 2, 1), (1, 2, 3), (4, 5, 6), (5, 7, 6), (0, 1, 4), (1, 5, 4), (2, 6, 3), (3, 6, 7),
                    (0, 4, 2), (2, 4, 6), (1, 3, 5), (3, 7, 5)])
    objs = [f'<object id="1" type="model"><mesh><vertices>{verts}</vertices><triangles>{tris}</triangles>'
            '</mesh></object>']
    for level in range(2, levels + 2):
        comps = "".join(f'<component objectid="{level - 1}" transform="1 0 0 0 1 0 0 0 1 {i} 0 0"/>'
                        for i in range(fan))
        objs.append(f'<object id="{level}" type="model"><components>{comps}</components></object>')
    model = ('<?xml version="1.0" encoding="UTF-8"?><model unit="millimeter" '
             'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02"><resources>' + "".join(objs) +
             f'</resources><build><item objectid="{levels + 1}"/></build></model>')
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("[Content_Types].xml", '<?xml version="1.0"?><Types xmlns="http://schemas.openxmlformats.org/'
                    'package/2006/content-types"><Default Extension="model" ContentType="application/'
                    'vnd.ms-package.3dmanufacturing-3dmodel+xml"/></Types>')
        zf.writestr("3D/3dmodel.model", model)
    return path


def test_nested_3mf_components_counted_before_placing(tmp_path, capsys):
    p = _nested_3mf(tmp_path / "nest.3mf")
    _refused(capsys, ["analyze", p], r"10,000,000,000 times")
    from porecad.io import read_mesh
    v, f = read_mesh(_nested_3mf(tmp_path / "small.3mf", levels=2, fan=3))
    assert len(f) == 9 * 12


def _nifti(path: Path, dims, pixdim=(1.0, 1.0, 1.0), data: bytes = b"") -> Path:
    hdr = bytearray(348)
    struct.pack_into("<i", hdr, 0, 348)
    struct.pack_into("<8h", hdr, 40, 3, *dims, 1, 1, 1, 1)
    struct.pack_into("<h", hdr, 70, 2)      # datatype uint8
    struct.pack_into("<h", hdr, 72, 8)      # bitpix
    struct.pack_into("<8f", hdr, 76, 1.0, *pixdim, 1, 1, 1, 1)
    struct.pack_into("<f", hdr, 108, 352.0)
    hdr[344:348] = b"n+1\x00"
    raw = bytes(hdr) + b"\x00" * 4 + data
    path.write_bytes(gzip.compress(raw, 1) if path.name.endswith(".gz") else raw)
    return path


def test_image_voxel_count_bounded_before_reading(tmp_path, capsys):
    p = _nifti(tmp_path / "big.nii.gz", (1024, 1024, 1024), data=b"\x00" * (1 << 20))
    _refused(capsys, ["infill", p, "G", "--label", "1", "--porosity", "0.6", "-o", tmp_path / "o.stl"], "voxels")


@pytest.mark.parametrize("pixdim", [(float("nan"), 1, 1), (float("inf"), 1, 1), (0.0, 1, 1)])
def test_nifti_bad_spacing_refused(tmp_path, capsys, pixdim):
    data = np.zeros((8, 8, 8), np.uint8)
    data[2:6, 2:6, 2:6] = 1
    p = _nifti(tmp_path / "s.nii", (8, 8, 8), pixdim, data.tobytes())
    _refused(capsys, ["infill", p, "G", "--label", "1", "--porosity", "0.6", "-o", tmp_path / "o.stl"], "spacing")


def test_compressed_vtp_honest_gigabyte_refused(tmp_path, capsys):
    """A VTP block that honestly inflates to 1 GiB is a bomb for a centreline: refused from its header."""
    import zlib
    block = 1 << 26
    comp = zlib.compress(b"\x00" * block, 9)
    nb = 16
    header = np.array([nb, block, block] + [len(comp)] * nb, "<u8").tobytes()
    import base64
    payload = base64.b64encode(header).decode() + base64.b64encode(comp * nb).decode()
    xml = ('<?xml version="1.0"?><VTKFile type="PolyData" version="1.0" header_type="UInt64" '
           'compressor="vtkZLibDataCompressor"><PolyData><Piece NumberOfPoints="2" NumberOfLines="1"><Points>'
           f'<DataArray type="Float32" NumberOfComponents="3" format="binary">{payload}</DataArray></Points>'
           '</Piece></PolyData></VTKFile>')
    p = tmp_path / "bomb.vtp"
    p.write_text(xml)
    _refused(capsys, ["vessel", p, "--voxel", "0.5", "-o", tmp_path / "o.stl"], "decompression bomb")


# ---------------------------------------------------------------------------------------------- recipes
def test_recipe_number_past_the_digit_limit(tmp_path, capsys):
    p = tmp_path / "r.toml"
    p.write_text("job = \"tpms\"\nformat = 1" + "0" * 4400 + "\n")
    _refused(capsys, ["build", p], "too long")


@pytest.mark.parametrize("params,match", [
    ({"tbss": {"periods": ["x"]}}, "params.tbss"),
    ({"tbss": {"periods": [[1]] * 16}}, "params.tbss"),
    ({"tbss": {"fits": [[]]}}, "params.tbss"),
    ({"tis": {"tets": 1e6}}, "params.tis.tets"),
    ({"arbf": {"tets": 1e6}}, "params.arbf.tets"),
])
def test_ivd_nested_parameters_checked_up_front(tmp_path, capsys, params, match):
    import tomli_w
    (tmp_path / "img.nii.gz").write_bytes(b"not read before the parameters are checked")
    r = {"job": "ivd", "input": {"path": "img.nii.gz"}, "methods": ["all"], "params": params,
         "output": {"dir": "out"}}
    (tmp_path / "ivd.toml").write_text(tomli_w.dumps(r))
    _refused(capsys, ["build", tmp_path / "ivd.toml"], re.escape(match))
    assert not (tmp_path / "out").exists()


def test_tbss_edit_threshold_bounded(tmp_path, capsys):
    from porecad.jobs.runner import parse
    from porecad.errors import RecipeError
    with pytest.raises(RecipeError, match="threshold"):
        parse({"job": "tbss", "tdf": {"file": __file__, "edits": [{"where": "w > 0.75", "threshold": 1e308}]}})


# ---------------------------------------------------------------------------------------------- signals
def _porecad(args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    return subprocess.Popen([sys.executable, "-m", "porecad", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


JOB = ["tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "2", "2", "2", "--resolution", "24",
       "-o", "out.stl", "--recipe", "out.toml", "--report", "rep.json"]


def test_signals_stop_at_once_and_leave_all_outputs_or_none(tmp_path):
    """SIGINT / SIGTERM at 20 times across a job with mesh, recipe and report: all three complete, or none."""
    import trimesh
    full = tmp_path / "full"
    full.mkdir()
    # a first run fills numba's cache (on a fresh clone it compiles for a minute): the signals are spread over
    # the time of a run that loads its kernels, as every later run here does
    warm = _porecad([*JOB, "--force"], full)
    warm.communicate(timeout=600)
    assert warm.returncode == 0
    t0 = time.perf_counter()
    proc = _porecad([*JOB, "--force"], full)
    proc.communicate(timeout=300)
    span = time.perf_counter() - t0
    assert proc.returncode == 0
    triangles = json.loads((full / "rep.json").read_text())["triangles"]
    rng = random.Random(41)
    stops = []
    for i in range(20):
        work = tmp_path / f"run{i}"
        work.mkdir()
        sig = signal.SIGINT if i % 2 else signal.SIGTERM
        proc = _porecad(JOB, work)
        time.sleep(rng.uniform(0.3, span * 1.1))  # from 0.3 s: before that it is Python's own start-up
        proc.send_signal(sig)
        t = time.perf_counter()
        _, err = proc.communicate(timeout=60)  # a hang guard; the stop latency is reported, not asserted
        stops.append(time.perf_counter() - t)
        names = sorted(os.listdir(work))
        assert names in ([], ["out.stl", "out.toml", "rep.json"]), (names, err)
        if names:
            mesh = trimesh.load(work / "out.stl")
            assert len(mesh.faces) == triangles and mesh.is_watertight
            assert json.loads((work / "rep.json").read_text())["triangles"] == triangles
            assert "job = \"tpms\"" in (work / "out.toml").read_text()
        if proc.returncode in (130, 143):
            word = "interrupted" if sig == signal.SIGINT else "terminated"
            last = err.decode().strip().splitlines()[-1]
            assert last == f"porecad: {word}; nothing written" if not names else \
                last.startswith(f"porecad: {word}; wrote ") and last.count(str(work)) == 3, last
        elif proc.returncode == -sig and not err:
            # before the interpreter was up (nothing ran) or while it shut down after the job (all three files
            # complete, checked above): Python's own default handling, no traceback
            pass
        else:
            assert proc.returncode == 0 and names, err
    print(f"stop latency: max {max(stops):.2f} s, median {sorted(stops)[10]:.2f} s over 20 signals")


def test_bad_porosity_expression_names_porosity(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    err = _refused(capsys, ["tpms", "G", "--porosity", "0.5 + zz", "--cells", "1", "1", "1", "-o", "x.stl"])
    assert err.startswith("porecad: error: --porosity:"), err
    err = _refused(capsys, ["tpms", "G", "--threshold", "0.5 + zz", "--cells", "1", "1", "1", "-o", "x.stl"])
    assert err.startswith("porecad: error: --threshold:"), err


def test_dicom_file_with_a_damaged_series_id(tmp_path, capsys):
    """A fuzz mutant (seed 4141, kept in tests/data): one slice of a series whose series UID ends in a byte
    that is not UTF-8 crashed ITK's series lookup with a TypeError; now a one-line refusal."""
    import shutil
    import SimpleITK as sitk
    series = tmp_path / "ball_dcm"
    series.mkdir()
    for k in range(16):
        sl = sitk.GetImageFromArray(np.zeros((16, 16), np.int16))
        sl.SetSpacing((0.5, 0.5))
        for tag, val in (("0020|000e", "1.2.826.0.1.3680043.2.1125.1"), ("0020|0013", str(k + 1)),
                         ("0020|0032", f"0\\0\\{0.5 * k}"), ("0020|0037", "1\\0\\0\\0\\1\\0"),
                         ("0018|0050", "0.5"), ("0008|0060", "CT"), ("0020|000d", "1.2.826.0.1.3680043.2.1125.2"),
                         ("0008|0018", f"1.2.826.0.1.3680043.2.1125.3.{k + 1}")):
            sl.SetMetaData(tag, val)
        w = sitk.ImageFileWriter()
        w.KeepOriginalImageUIDOn()
        w.SetFileName(str(series / f"s{k:03d}.dcm"))
        w.Execute(sl)
    shutil.copy(ROOT / "tests" / "data" / "dicom-damaged-series-uid.dcm", series / "s007.dcm")
    err = _refused(capsys, ["infill", series / "s007.dcm", "G", "--label", "1", "--threshold", "0",
                            "-o", tmp_path / "o.stl"])
    assert "series" in err, err
