"""Issue 53: the HTML report says what was designed, names its files relative to itself, shows no noise.

Structural checks on a small build's report (a 2×2×2 gyroid sheet, seconds):
the *Design* block (type, structure, cell size, target porosity, body,
porecad version), file names relative to the report folder, axes in mm on
the sections, no raw Python dict and no ``1e-12``-style noise in the text a
reader sees; the report's stages are announced through its progress hook.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from porecad.analysis import report as report_mod
from porecad.analysis.summary import design_rows, summary_groups
from porecad.pages import num


def _visible_text(html: str) -> str:
    """The page's text as a reader sees it (scripts, styles and tags removed)."""
    text = re.sub(r"(?s)<script.*?</script>|<style.*?</style>", " ", html)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", text))


@pytest.fixture(scope="module")
def small_report(tmp_path_factory):
    from porecad.cli.main import main
    d = tmp_path_factory.mktemp("design")
    code = main(["tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "2", "2", "2",
                 "--cell-size", "2", "--resolution", "16", "-o", str(d / "s.stl"), "--recipe", str(d / "s.toml"),
                 "--report", str(d / "rep")])
    assert code == 0
    return d


def test_report_states_the_design(small_report):
    html = (small_report / "rep" / "report.html").read_text(encoding="utf-8")
    text = _visible_text(html)
    design = text[text.index("Design"):text.index("Summary")]
    for words in ("type", "Gyroid (G)", "structure sheet", "cell size 2 mm", "target porosity 60 %",
                  "body axis-aligned box, 4 × 4 × 4 mm", "porecad version", "mesh ../s.stl",
                  "recipe ../s.toml"):
        assert words in design, words
    from porecad import __version__
    assert __version__ in design


def test_report_names_files_relative_to_itself(small_report):
    rep = small_report / "rep"
    html = (rep / "report.html").read_text(encoding="utf-8")
    assert str(small_report) not in _visible_text(html)          # no absolute path shown
    for src in re.findall(r'<img src="([^"]+)"', html):
        assert "/" not in src and (rep / src).is_file(), src
    assert "file ../s.stl" in _visible_text(html)


def test_report_text_has_no_dicts_or_noise(small_report):
    text = _visible_text((small_report / "rep" / "report.html").read_text(encoding="utf-8"))
    assert "{'" not in text and "{\"" not in text
    assert not re.search(r"\de-(1\d|[2-9]\d)\b", text), re.findall(r"\S*\de-\d\d\S*", text)


def test_tiny_values_show_as_zero():
    assert num(1e-12) == "0" and num(-3e-13) == "0" and num(None) == "–" and num(0.04213) == "0.04213"
    assert num(55771.3) == "55,770" and num(1234.5) == "1234"
    rows = dict(summary_groups({"closed_pore_volume": 2e-13, "porosity": 0.5})[0][1])
    assert rows["porosity (by mesh volume)"] == "50.0 %"
    pores = dict(summary_groups({"closed_pore_volume": 2e-13})[0][1])
    assert pores["closed pore volume"] == "0 mm³"


def test_design_rows_describe_a_graded_disc():
    from porecad.fields.sdf import LumbarDisc
    rows = dict(design_rows({"type": "G", "structure": "sheet", "cell_size": [5.0, 5.0, 5.0], "porecad_version": "9.9",
                             "grading": {"kind": "radial", "of": "porosity", "axes": "xy", "r0": 4.0, "r1": 20.0,
                                         "from": 0.8, "to": 0.6},
                             "body_volume": 10572.6, "mesh_file": "/x/out/a.stl"}, LumbarDisc(), "/x/out/rep"))
    assert rows["cell size"] == "5 mm" and rows["porecad version"] == "9.9" and rows["mesh"] == "../a.stl"
    assert "80 %" in rows["grading"] and "60 %" in rows["grading"] and "4 mm" in rows["grading"]
    assert rows["body"].startswith("analytic lumbar intervertebral disc, 45 × 32 × 10 mm")


def test_report_stages_are_announced(small_report, tmp_path):
    from porecad.io import read_mesh
    v, f = read_mesh(small_report / "s.stl")
    said = []
    report_mod.set_progress(said.append)
    try:
        report_mod.write_build_report(tmp_path / "rep", v, f, {"mesh_file": str(small_report / "s.stl"),
                                                              "type": "G", "structure": "sheet", "threshold": 0.6})
    finally:
        report_mod.set_progress(None)
    assert [s.split(":")[0] for s in said] == ["report"] * len(said) and len(said) >= 4
    assert any("pore and strut sizes" in s for s in said) and any("report.html" in s for s in said)
    rep = json.loads((tmp_path / "rep" / "report.json").read_text(encoding="utf-8"))
    assert rep["pore_size_d50"] > 0 and np.isfinite(rep["strut_size_d50"])
