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


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def test_escapes_in_recipes(sandbox, capsys):
    for k, expr in enumerate(_escapes(sandbox)):
        s = _toml_string(expr)
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
