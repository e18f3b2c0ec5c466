"""Untrusted recipes, expressions and files (issue 19): no code execution, no bombs, no echoed contents.

Known expression escapes are tried on the command line (``tpms --threshold``,
``infill --porosity``, ``tbss --tdf``, ``tbss --edit``), in recipes run by
``porecad build`` (grading expressions, TDF expressions, edit conditions)
and in TDF files: every one is refused in one line and the canary file it
tries to create never appears. Timings live in ``bench/untrusted.py``.
"""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from porecad.cli.main import main
from porecad.errors import InputError
from porecad.expressions import ExpressionError, compile_expression

CANARY = "CANARY_FILE"

#: expressions that try to run code, read files, or exhaust time and memory; {c} is the canary path
ESCAPES = [
    "().__class__.__base__.__subclasses__()",
    "[c for c in ().__class__.__base__.__subclasses__() if c.__name__ == 'catch_warnings'][0]()"
    "._module.__builtins__['__import__']('os').system('touch {c}')",
    "__import__('os').system('touch {c}')",
    "open('{c}', 'w')",
    "eval(\"open('{c}', 'w')\")",
    "exec(\"open('{c}', 'w')\")",
    "(lambda: open('{c}', 'w'))()",
    "x.__class__.__mro__[-1].__subclasses__()",
    "getattr(__builtins__, 'open')('{c}', 'w')",
    "__builtins__['open']('{c}', 'w')",
    "'{{0.__class__.__init__.__globals__}}'.format(x)",
    "f\"{{open('{c}', 'w')}}\"",
    "'%s' % open('{c}', 'w')",
    "[open('{c}', 'w') for _ in range(1)]",
    "(open('{c}', 'w') for _ in range(1))",
    "{{k: open('{c}', 'w') for k in [1]}}",
    "(y := open('{c}', 'w'))",
    "sin.__globals__",
    "sin(x).__array_interface__",
    "globals()['__builtins__']",
    "where(x > 0, open('{c}', 'w'), 0)",
    "x if open('{c}', 'w') else 0",
    "np.os.system('touch {c}')",
    "breakpoint()",
    "9**9**9",
    "'a'*10**10",
    "[0]*10**10",
    "2**2**2**2**2",
    "10**400",
    "1e999",
    "-" * 500 + "x",
    "(" * 250 + "x" + ")" * 250,
    "sin(" * 150 + "x" + ")" * 150,
    "x" + " + x" * 900,
]


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _escapes(where: Path):
    return [e.format(c=str(where / CANARY)) for e in ESCAPES]


def _refused(capsys, argv) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code != 0, argv
    assert len(err.splitlines()) == 1 and err.startswith("porecad: error:"), err
    return err


def test_at_least_twenty_escapes():
    assert len(ESCAPES) >= 20


@pytest.mark.parametrize("expr", ESCAPES, ids=[f"escape{i}" for i in range(len(ESCAPES))])
def test_escape_refused_by_the_evaluator(expr, tmp_path):
    for variables in (("x", "y", "z", "d", "dn"), ("u", "v", "w", "x", "y", "z")):
        with pytest.raises(ExpressionError) as info:
            compile_expression(expr.format(c=str(tmp_path / CANARY)), variables)
        assert "\n" not in str(info.value)
    assert not (tmp_path / CANARY).exists()


def test_escapes_on_the_command_line(sandbox, capsys):
    for expr in _escapes(sandbox):
        err = _refused(capsys, ["tpms", "G", "--threshold", expr, "-o", "a.stl"])
        assert "--threshold" in err
        _refused(capsys, ["tbss", "box", "G", "--tdf", expr, "-o", "b.stl"])
        _refused(capsys, ["tbss", "box", "G", "--edit", expr, "0.5", "-o", "c.stl"])
    assert not (sandbox / CANARY).exists()
    assert sorted(os.listdir(sandbox)) == []


def toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def test_escapes_in_recipes(sandbox, capsys):
    for k, expr in enumerate(_escapes(sandbox)):
        s = toml_string(expr)
        recipes = {
            "grading": f'job = "tpms"\nformat = 2\n[tpms]\ntype = "G"\nstructure = "sheet"\n[domain]\nkind = "box"\n'
                       f'[grading]\nkind = "expression"\nof = "porosity"\nexpr = {s}\n[output]\nmesh = "g.stl"\n',
            "tdf": f'job = "tbss"\n[body]\nkind = "box"\n[tdf]\nmethod = "function"\nexpr = {s}\n'
                   '[output]\nmesh = "t.stl"\n',
            "edit": f'job = "tbss"\n[body]\nkind = "box"\n[[tdf.edits]]\nwhere = {s}\nthreshold = 0.5\n'
                    '[output]\nmesh = "e.stl"\n',
        }
        for name, text in recipes.items():
            p = sandbox / f"{name}{k}.toml"
            p.write_text(text)
            err = _refused(capsys, ["build", str(p)])
            assert ("expr" in err or "where" in err), err
            p.unlink()
    assert not (sandbox / CANARY).exists()
    assert sorted(os.listdir(sandbox)) == []


def _tdf_file(path: Path, metadata=None):
    from porecad.io.tdf_file import TDFRecord, write_tdf
    k1 = (0.0, 0.0, 1.0, 1.0)
    ctrl = np.stack(np.meshgrid(*[np.array([0.0, 10.0])] * 3, indexing="ij"), -1)
    rec = TDFRecord(version=1, tpms_type="G", structure="sheet", periods=(1.0, 1.0, 1.0), tdf_degrees=(1, 1, 1),
                    tdf_knots=(k1, k1, k1), tdf_control=np.full((2, 2, 2), 0.4), tbss_degrees=(1, 1, 1),
                    tbss_knots=(k1, k1, k1), tbss_control=ctrl, tbss_periodic=(False, False, False),
                    metadata=metadata or {})
    return write_tdf(path, rec, force=True)


def test_escapes_in_tdf_files(sandbox, capsys):
    """Escapes in a TDF file: as numbers they are refused in one line; as metadata they are inert text."""
    from porecad.io.tdf_file import read_tdf
    good = _tdf_file(sandbox / "good.tdf").read_text().splitlines()
    at = good.index("#control points of TDF") + 1
    for k, expr in enumerate(_escapes(sandbox)):
        lines = list(good)
        lines[at] = expr
        p = sandbox / f"bad{k}.tdf"
        p.write_text("\n".join(lines) + "\n")
        _refused(capsys, ["tbss", "--from-tdf", str(p), "--resolution", "4", "-o", "x.stl"])
        p.unlink()
        one_line = " ".join(expr.split())
        if one_line == one_line.strip() and len(one_line) < 2000:
            rec = read_tdf(_tdf_file(sandbox / "meta.tdf", {"expr": one_line}))
            assert rec.metadata["expr"] == one_line  # stored and read back as text, never evaluated
            (sandbox / "meta.tdf").unlink()
    assert not (sandbox / CANARY).exists()


def test_escapes_through_the_api(tmp_path):
    import porecad as pc
    for expr in _escapes(tmp_path):
        with pytest.raises(InputError):
            pc.expression(expr)
    assert not (tmp_path / CANARY).exists()


def test_expression_language_still_works():
    x = np.array([0.0, 1.0, 2.0])
    f = compile_expression("where((x > 0.5) & (x < 1.5), 1, 0) + 0.2 < x ** 2", ("x",))
    assert f(x=x).tolist() == [0.0, 0.0, 1.0]
    assert compile_expression("0.5 + 0.3 * clip(x / 2, 0, 1)", ("x",))(x=x).tolist() == [0.5, 0.65, 0.8]
    assert compile_expression("0.2 < x < 1.5 and not x == 1", ("x",))(x=x).tolist() == [0.0, 0.0, 0.0]
    assert compile_expression("max(x, 1) - min(x, 1)", ("x",))(x=x).tolist() == [1.0, 0.0, 1.0]


@pytest.mark.parametrize("expr, phrase", [
    ("abc", "column 1: unknown name 'abc'"),
    ("sin()", "column 1: sin() takes 1 argument, got 0"),
    ("1/0", "column 1: this part evaluates to a non-finite number"),
    ("[x, y]", "column 1: lists are not allowed"),
    ("{}", "column 1: dicts are not allowed"),
    ("x if x else y", "use where(c, a, b)"),
    ("0.5 + x.real", "column 7: attribute access (.) is not allowed"),
    ("1 + 'a'", "column 5: strings are not allowed"),
    ("x +", "invalid syntax"),
    ("x ** 100", "exponent 100 is out of range"),
])
def test_expression_errors_name_the_column(expr, phrase):
    with pytest.raises(ExpressionError) as info:
        compile_expression(expr, ("x", "y", "z"))
    assert phrase in str(info.value)
    assert "\n" not in str(info.value)


# ------------------------------------------------------------------------------------ bombs (Acceptance 3)
class _RawDeflate:
    def flush(self):
        return b""


def zip_bomb_3mf(path: Path, size: int = 11 << 30, block: int = 1 << 24) -> Path:
    """A 3MF whose model part inflates to ``size`` bytes of zeros, written in about 10 MB without inflating.

    One deflate block of ``block`` zeros is compressed once and repeated (a full
    flush makes the blocks independent); the zip directory declares the true
    sizes (the CRC is left 0: the reader must refuse before reading a byte).
    """
    import zlib
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    one = c.compress(bytes(block)) + c.flush(zlib.Z_FULL_FLUSH)
    end = c.flush(zlib.Z_FINISH)
    n = size // block
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("[Content_Types].xml", "<Types/>")
        info = zipfile.ZipInfo("3D/3dmodel.model")
        info.compress_type = zipfile.ZIP_DEFLATED
        with zf.open(info, "w", force_zip64=True) as w:
            w._compressor = _RawDeflate()
            for _ in range(n):
                w._fileobj.write(one)
            w._fileobj.write(end)
            w._compress_size = n * len(one) + len(end)
            w._file_size = n * block
            w._crc = 0
    return path


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
 <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
 <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
 <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
 <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian"><PolyData><Piece NumberOfPoints="1">
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">&lol9;</DataArray></Points>
</Piece></PolyData></VTKFile>
"""


def test_zip_bomb_3mf_refused(sandbox, capsys):
    bomb = zip_bomb_3mf(sandbox / "bomb.3mf")
    assert bomb.stat().st_size < 20 << 20
    with zipfile.ZipFile(bomb) as zf:
        assert zf.getinfo("3D/3dmodel.model").file_size > 10 << 30
    err = _refused(capsys, ["analyze", str(bomb), "--json"])
    assert "inflates to" in err
    _refused(capsys, ["infill", str(bomb), "G", "--threshold", "0", "-o", "out.stl"])
    assert sorted(os.listdir(sandbox)) == ["bomb.3mf"]


def test_billion_laughs_refused(sandbox, capsys):
    vtp = sandbox / "laughs.vtp"
    vtp.write_text(BILLION_LAUGHS)
    err = _refused(capsys, ["vessel", str(vtp), "--voxel", "0.2", "-o", "out.stl"])
    assert "document type" in err and "lol" not in err
    vtu = sandbox / "laughs.vtu"
    vtu.write_text(BILLION_LAUGHS.replace("PolyData", "UnstructuredGrid"))
    _refused(capsys, ["tis", str(vtu), "--relative-threshold", "0.3", "-o", "out.stl"])
    model = BILLION_LAUGHS.replace("<VTKFile", "<model").split("<model")[0] + "<model>&lol9;</model>"
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("3D/3dmodel.model", model)
    (sandbox / "laughs.3mf").write_bytes(buf.getvalue())
    _refused(capsys, ["analyze", str(sandbox / "laughs.3mf")])


def test_compressed_vtp_block_bomb_refused(sandbox, capsys):
    """A zlib block in a VTP that inflates far beyond its declared size is refused without inflating it."""
    import base64
    import zlib
    src = Path(__file__).parents[1] / "data" / "vessel-y-binary-zlib.vtp"
    text = src.read_text()
    head = np.array([1, 64, 64, 0], "<u4")
    blob = zlib.compress(bytes(64 << 20), 9)
    head[3] = len(blob)
    bomb = base64.b64encode(head.tobytes()).decode() + base64.b64encode(blob).decode()
    start = text.index('format="binary"')
    a = text.index(">", start) + 1
    b = text.index("</DataArray>", a)
    (sandbox / "bomb.vtp").write_text(text[:a] + bomb + text[b:])
    err = _refused(capsys, ["vessel", str(sandbox / "bomb.vtp"), "--voxel", "0.2", "-o", "out.stl"])
    assert "inflates beyond" in err


# ------------------------------------------------------------------------------- outputs (Acceptance 4, 6)
def _stamp(paths):
    return {str(p): (p.read_bytes(), p.stat().st_mtime_ns) for p in paths}


def test_outputs_clash_input_and_read_only(sandbox, capsys):
    from porecad.io import write_mesh
    v = np.array([[x, y, z] for z in (0, 10) for y in (0, 10) for x in (0, 10)], float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
                  [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    body = write_mesh(sandbox / "body.stl", v, f)
    x = sandbox / "x.stl"
    x.write_bytes(b"precious")
    before = _stamp([body, x])
    tpms = ["tpms", "G", "--threshold", "0.5", "--cells", "1", "1", "1", "--cell-size", "2"]
    for argv in (tpms + ["-o", "x.stl", "--report", "x.stl", "--force"],
                 tpms + ["-o", "x.stl", "--recipe", "x.stl", "--force"],
                 ["infill", str(body), "G", "--threshold", "0", "-o", str(body), "--force"],
                 ["vessel", str(Path(__file__).parents[1] / "data" / "vessel-y-reference.json"), "--voxel", "0.2", "-o", "x.stl",
                  "--report", "x.stl", "--force"]):
        err = _refused(capsys, argv)
        assert "also output" in err or "input of this job" in err, err
    ro = sandbox / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        err = _refused(capsys, tpms + ["-o", str(ro / "y.stl")])
        assert "not writable" in err
        _refused(capsys, ["phantom", "spine", "-o", str(ro / "ph")])
        assert os.listdir(ro) == []
    finally:
        ro.chmod(0o755)
    assert _stamp([body, x]) == before
    assert sorted(os.listdir(sandbox)) == ["body.stl", "ro", "x.stl"]


def test_every_command_refuses_to_overwrite(sandbox, capsys):
    """Existing outputs of phantom, seg classical, seg predict, seg train and ivd are kept without --force."""
    assert main(["phantom", "spine", "-o", "ph", "--discs", "1"]) == 0
    capsys.readouterr()
    ph = sorted((sandbox / "ph").iterdir())
    before = _stamp(ph)
    _refused(capsys, ["phantom", "spine", "-o", "ph", "--discs", "1"])
    assert _stamp(ph) == before
    for name in ("seg.nii.gz", "w.pt", "pred.nii.gz"):
        (sandbox / name).write_bytes(b"precious")
    (sandbox / "discs").mkdir()
    (sandbox / "discs" / "segmentation.nii.gz").write_bytes(b"precious")
    keep = _stamp([sandbox / n for n in ("seg.nii.gz", "w.pt", "pred.nii.gz", "discs/segmentation.nii.gz")])
    for argv in (["seg", "classical", "ph", "-o", "seg.nii.gz"],
                 ["seg", "train", "--phantoms", "1", "--iterations", "1", "-o", "w.pt"],
                 ["seg", "predict", "ph", "--checkpoint", "w.pt", "-o", "pred.nii.gz"],
                 ["ivd", "ph", "-o", "discs"]):
        err = _refused(capsys, argv)
        assert "already exists" in err, err
    assert _stamp([sandbox / n for n in ("seg.nii.gz", "w.pt", "pred.nii.gz", "discs/segmentation.nii.gz")]) == keep


def test_pickle_checkpoint_runs_nothing(sandbox, capsys):
    torch = pytest.importorskip("torch")
    canary = sandbox / CANARY

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {canary}",))

    torch.save({"format": "porecad-ivd-unet3d", "version": 1, "meta": "{}", "nets": {"x": Evil()}},
               sandbox / "evil.pt")
    assert main(["phantom", "spine", "-o", "ph", "--discs", "1"]) == 0
    capsys.readouterr()
    _refused(capsys, ["seg", "predict", "ph", "--checkpoint", "evil.pt", "-o", "pred.nii.gz"])
    _refused(capsys, ["ivd", "ph", "--segmenter", "unet", "--checkpoint", "evil.pt", "-o", "discs"])
    assert not canary.exists()


# ------------------------------------------------------------------------------ contents never echoed (6)
SECRET = "s3cr3t-PASSWORD-line"


def _secret_files(where: Path) -> dict:
    files = {
        "points.csv": f"x,y,z,porosity\n0,0,0,0.5\n{SECRET}:x:0:0:root:/root:/bin/bash\n",
        "body.obj": f"v 0 0 0\nv 1 0 0\nv 0 1 0\nv {SECRET} 0 1\nf 1 2 3\nf 1 2 4\n",
        "body.off": f"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n{SECRET}\n3 0 1 2\n3 0 1 3\n",
        "body.stl": f"solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 {SECRET}\n",
        "tree.swc": f"1 1 0 0 0 1 -1\n2 3 0 0 {SECRET} 1 1\n",
        "tree.json": f'{{"points": [[0, 0, "{SECRET}"]], "radii": [1], "edges": []}}',
        "tree.vtp": f'<VTKFile type="PolyData"><PolyData><Piece NumberOfPoints="{SECRET}"></Piece></PolyData>'
                    '</VTKFile>',
        "mesh.msh": f"$MeshFormat\n{SECRET}\n$EndMeshFormat\n",
        "scaffold.tdf": f"{SECRET}\n",
        "recipe_with_points.toml": 'job = "tpms"\n[tpms]\ntype = "G"\nstructure = "sheet"\n[domain]\nkind = "box"\n'
                                   '[grading]\nkind = "points"\nfile = "points.csv"\n',
    }
    for name, text in files.items():
        (where / name).write_text(text)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("3D/3dmodel.model", f'<model unit="{SECRET}"><resources><object id="1"><mesh><vertices>'
                    f'<vertex x="0" y="0" z="{SECRET}"/></vertices></mesh></object></resources></model>')
    (where / "body.3mf").write_bytes(buf.getvalue())
    return files


def test_error_messages_never_quote_input_files(sandbox, capsys):
    from porecad.io import write_mesh
    _secret_files(sandbox)
    v = np.array([[x, y, z] for z in (0, 10) for y in (0, 10) for x in (0, 10)], float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
                  [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    write_mesh(sandbox / "good.stl", v, f)
    json_path = str(sandbox / "tree.json")
    cases = [["infill", "good.stl", "G", "--porosity-points", "points.csv", "-o", "o.stl"],
             ["build", "recipe_with_points.toml"]]
    cases += [["analyze", name] for name in ("body.obj", "body.off", "body.stl", "body.3mf")]
    cases += [["vessel", name, "-o", "o.stl"] for name in ("tree.swc", json_path, "tree.vtp")]
    cases += [["tis", "mesh.msh", "--relative-threshold", "0.3", "-o", "o.stl"],
              ["tbss", "--from-tdf", "scaffold.tdf", "-o", "o.stl"]]
    for argv in cases:
        err = _refused(capsys, argv)
        assert SECRET not in err, (argv, err)
        assert "/bin/bash" not in err, (argv, err)


def test_truncated_images_refused(sandbox, capsys):
    sitk = pytest.importorskip("SimpleITK")
    z, y, x = np.mgrid[0:16, 0:16, 0:16]
    ball = (((x - 7.5) ** 2 + (y - 7.5) ** 2 + (z - 7.5) ** 2) < 36).astype(np.int16)
    for name, compress in (("ball.nii", False), ("ball.nii.gz", True), ("ball.mha", False), ("ball.nrrd", False)):
        sitk.WriteImage(sitk.GetImageFromArray(ball), str(sandbox / name), compress)
        data = (sandbox / name).read_bytes()
        (sandbox / f"cut_{name}").write_bytes(data[: len(data) * 2 // 3])
        err = _refused(capsys, ["infill", f"cut_{name}", "G", "--label", "1", "--threshold", "0", "-o", "o.stl"])
        assert "truncated" in err or "not a readable image" in err, err
    assert main(["infill", "ball.nii", "G", "--label", "1", "-L", "3", "--threshold", "0", "-o", "o.stl"]) == 0
    capsys.readouterr()
    img = sitk.GetImageFromArray(ball)
    img.SetSpacing((1e30, 1.0, 1.0))
    sitk.WriteImage(img, str(sandbox / "huge.nii"))
    err = _refused(capsys, ["infill", "huge.nii", "G", "--label", "1", "--threshold", "0", "-o", "o2.stl"])
    assert "spacings" in err


def test_recipe_nesting_and_big_numbers_refused(sandbox, capsys):
    (sandbox / "deep.toml").write_text('job = "tpms"\nx = ' + "[" * 40 + "]" * 40 + "\n")
    _refused(capsys, ["build", "deep.toml"])
    (sandbox / "big.toml").write_text('job = "tpms"\n[tpms]\ntype = "G"\ncell_size = 1e308\n[domain]\nkind = "box"\n')
    _refused(capsys, ["build", "big.toml"])
