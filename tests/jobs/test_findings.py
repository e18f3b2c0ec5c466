"""Structured warnings (porecad.findings): codes, JSON-ready values, the report's two forms."""

import json

import numpy as np
import pytest

from pathlib import Path

from porecad.findings import CODES, Finding, as_finding, codes, report_fields
from porecad.jobs.runner import common_report


def test_a_finding_has_a_stable_code_and_json_values():
    f = Finding("porosity-off", "porosity 0.62, asked 0.60", {"asked": 0.6, "achieved": np.float64(0.62),
                                                             "count": np.int64(3), "ratio": float("nan")})
    d = f.as_dict()
    assert json.loads(json.dumps(d)) == {"code": "porosity-off", "message": "porosity 0.62, asked 0.60",
                                         "values": {"asked": 0.6, "achieved": 0.62, "count": 3, "ratio": None}}
    assert str(f) == "porosity 0.62, asked 0.60"
    for bad in ("Porosity", "porosity_off", "-x", "a--b", "", "porosity-of"):
        with pytest.raises(ValueError, match="warning code"):
            Finding(bad, "m")


def test_report_fields_keep_sentences_and_details_and_drop_repeats():
    items = [Finding("islands", "2 loose pieces dropped", {"count": 2}), "a plain\n sentence",
             Finding("islands", "2 loose pieces dropped", {"count": 2})]
    out = report_fields(items)
    assert out["warnings"] == ["2 loose pieces dropped", "a plain sentence"]
    assert [d["code"] for d in out["warning_details"]] == ["islands", "note"]
    assert as_finding(out["warning_details"][0]) == Finding("islands", "2 loose pieces dropped", {"count": 2})
    assert codes(out) == ["islands", "note"] and codes({"warnings": ["x"]}) == ["note"]


def test_the_runner_gives_every_report_both_forms():
    rep = common_report({"warnings": [Finding("coverage-low", "covers 80 %", {"coverage": 0.8})]}, "tpms", 3)
    assert rep["warnings"] == ["covers 80 %"]
    assert rep["warning_details"] == [{"code": "coverage-low", "message": "covers 80 %", "values": {"coverage": 0.8}}]
    assert common_report({}, "tpms", 3)["warning_details"] == []
    # a report read back (JSON) keeps its details
    again = common_report(json.loads(json.dumps(rep)), "tpms", 3)
    assert again["warning_details"] == rep["warning_details"]


def test_every_code_is_documented_with_its_meaning():
    """docs/recipes.md lists each code of CODES (and no other), so a new code cannot ship unexplained."""
    import re
    text = (Path(__file__).resolve().parents[2] / "docs" / "recipes.md").read_text(encoding="utf-8")
    table = dict(re.findall(r"^\| `([a-z0-9-]+)` \| (.+?) \|$", text, re.M))
    assert table == CODES
