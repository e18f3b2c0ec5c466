"""Issue 21: the layout rules hold, the API reference builds without warnings, the README's Python runs."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

import check_layout  # noqa: E402


def test_layout_rules_hold():
    found = check_layout.check(ROOT / "src")
    assert found == {k: [] for k in found}, found


def test_layout_checker_finds_what_it_should(tmp_path):
    pkg = tmp_path / "porecad"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from .b import g\n    return g\n")
    (pkg / "b.py").write_text("from .a import f\nfrom .c import _hidden\ng = 1\n")
    (pkg / "c.py").write_text("_hidden = 1\n" + "x = 1\n" * 900)
    (pkg / "sub" / "a.py").write_text("")
    for layer in ("jobs", "cli"):
        (pkg / layer).mkdir()
        (pkg / layer / "__init__.py").write_text("")
    (pkg / "jobs" / "run.py").write_text("from ..cli import x\n")  # jobs -> cli: upward
    (pkg / "cli" / "cmd.py").write_text("from ..jobs import run\nfrom .. import a\n")  # downward: fine
    (pkg / "sub" / "d.py").write_text("def f():\n    from porecad.jobs import run\n")  # library -> jobs
    (pkg / "sub" / "e.py").write_text("raise ValueError(f'{1} use --local or `shape`')\n")
    (pkg / "cli" / "f.py").write_text("raise ValueError('use --local')\n")  # the CLI may
    (pkg / "sub" / "g.py").write_text("warns, findings = [], []\nwarns.append(f'{1} off')\nfindings += ['x']\n"
                                     "warns.append(Finding('islands', 'x'))\nother = []\nother.append('fine')\n")
    (pkg / "sub" / "h.py").write_text("def long():\n" + "    x = 1\n" * 85 + "\n\n@njit(cache=True)\ndef kernel():\n"
                                     + "    y = 1\n" * 85 + "\n\ndef short():\n" + "    z = 1\n" * 79)
    found = check_layout.check(tmp_path)
    assert found["functions over 80 lines"] == ["porecad.sub.h:1 long: 86 lines (at most 80)"]
    assert found["imports from a higher layer"] == ["porecad.jobs.run:1 imports porecad.cli",
                                                   "porecad.sub.d:2 imports porecad.jobs.run"]
    assert found["flags named in library errors"] == ["porecad.sub.e:1 names --local"]
    assert found["import cycles"] == ["porecad.a -> porecad.b"]
    assert found["private names imported across modules"] == ["porecad.b:2 imports _hidden from porecad.c"]
    assert found["modules over 600 lines"] == ["porecad.c: 901 lines (at most 600)"]
    assert found["modules sharing a file name"] == ["a.py: porecad.a, porecad.sub.a"]
    assert found["warnings as plain text"] == ["porecad.sub.g:2 adds a warning as plain text",
                                               "porecad.sub.g:3 adds a warning as plain text"]


def test_api_reference_builds_without_warnings(tmp_path):
    out = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                          str(ROOT / "docs"), str(tmp_path / "html")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    page = (tmp_path / "html" / "api.html").read_text(encoding="utf-8")
    for name in ("polygonise", "run_recipe", "RecipeError", "TisSpec"):
        assert name in page


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_readme_examples_are_short():
    """A gyroid sheet in a box and a graded gyroid in the femur: one import and at most five lines each."""
    blocks = _python_blocks((ROOT / "README.md").read_text(encoding="utf-8"))
    short = [b for b in blocks if b.strip().startswith("import porecad as pc")]
    assert len(short) >= 2
    for b in short[:2]:
        body = [ln for ln in b.strip().splitlines()[1:] if ln.strip() and not ln.strip().startswith("#")]
        assert len(body) <= 5, b
        assert sum(ln.startswith(("import", "from")) for ln in b.strip().splitlines()) == 1
    assert "femur" in short[1]


def test_vendored_viewer_script_is_the_build_of_its_sources():
    """The report and the studio share porecad/vendor/three.classic.js; it is tools/build_viewer_script.py's
    output from the three.js modules in tools/three-src, and neither page reads the other's folders."""
    import build_viewer_script
    vendored = build_viewer_script.TARGET.read_text(encoding="utf-8")
    assert vendored == build_viewer_script.classic_script()
    assert "window.THREE=" in vendored and "OrbitControls" in vendored
    src = ROOT / "src" / "porecad"
    assert "studio" not in (src / "analysis" / "viewer.py").read_text(encoding="utf-8").split('"""', 2)[2]
    assert not (src / "studio" / "static" / "vendor").exists()
