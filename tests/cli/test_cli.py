"""CLI contract: demo, tpms, analyze, build; bad input gives one line and no partial file."""

import json
import subprocess
import sys

import pytest


def test_version_console_script():
    out = subprocess.run([sys.executable, "-m", "porecad.cli", "--version"], capture_output=True, text=True, encoding="utf-8")
    assert out.returncode == 0 and "0." in out.stdout


def test_list_json(run_cli):
    code, out, _ = run_cli("tpms", "--list", "--json")
    types = json.loads(out)
    assert code == 0 and len(types) >= 13 and all("name" in t for t in types)


# `porecad demo` (STL, recipe, JSON report, HTML report opened in a browser): tests/analysis/test_report_viewer.py


def test_recipe_rebuilds_the_same_mesh(run_cli, tmp_path):
    out1 = tmp_path / "a.stl"
    code, out, err = run_cli("tpms", "G", "--structure", "sheet", "--porosity", 0.6, "--cells", 2, 1, 1,
                             "--resolution", 20, "-o", out1, "--recipe", tmp_path / "a.toml", "--json")
    assert code == 0, err
    first = json.loads(out)
    first_bytes = out1.read_bytes()
    code, out, err = run_cli("build", tmp_path / "a.toml", "--force", "--json")
    assert code == 0, err
    assert json.loads(out)["triangles"] == first["triangles"]
    assert out1.read_bytes()[84:] == first_bytes[84:]


def test_analyze_reports_contract_keys(run_cli, tmp_path):
    out1 = tmp_path / "p.ply"
    code, _, err = run_cli("tpms", "P", "--structure", "rod", "--threshold", 0.3, "--resolution", 20, "-o", out1)
    assert code == 0, err
    code, out, _ = run_cli("analyze", out1, "--json")
    r = json.loads(out)
    for key in ("porosity", "volume", "surface_area", "triangles", "closed", "manifold"):
        assert key in r
    assert r["self_intersections"] == 0


BAD = [
    (["tpms", "Q", "--structure", "pore", "--threshold", 0], "unknown TPMS type"),
    (["tpms", "P", "--structure", "foam", "--threshold", 0], "unknown structure"),
    (["tpms", "P", "--structure", "pore", "--threshold", 1.5], "valid range"),
    (["tpms", "P", "--structure", "pore", "--porosity", 1.2], "porosity"),
    (["tpms", "G", "--structure", "sheet", "--porosity", 0.99], "valid range"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--cell-size", 0], "cell size"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--cell-size", -1], "cell size"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--cells", 0, 1, 1], "cell counts"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--cells", 4000, 4000, 4000, "--resolution", 100],
     "too large"),
    (["tpms", "P", "--structure", "pore"], "--threshold"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--porosity", 0.5], "either"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--resolution", 1], "resolution"),
    (["tpms", "P", "--structure", "pore", "--threshold", 0, "--cells", 1, 1], "cells"),
    (["analyze", "/nonexistent/mesh.stl", "--json"], "no such file"),
    (["build", "/nonexistent/recipe.toml"], "no such recipe"),
    (["frobnicate"], "No such command"),
]


@pytest.mark.parametrize("args,needle", BAD)
def test_bad_input_one_line_error(run_cli, args, needle):
    code, out, err = run_cli(*args)
    assert code != 0
    assert len(err.strip().splitlines()) == 1 and needle.lower() in err.lower()
    assert "Traceback" not in err and out == ""


def test_garbage_mesh_for_analyze(run_cli, tmp_path):
    bad = tmp_path / "garbage.stl"
    bad.write_bytes(b"\x00\x01 this is not a mesh" * 10)
    code, out, err = run_cli("analyze", bad, "--json")
    assert code != 0 and len(err.strip().splitlines()) == 1 and out == ""


def test_existing_output_needs_force_and_unwritable_output(run_cli, tmp_path):
    target = tmp_path / "x.stl"
    target.write_bytes(b"keep me")
    args = ["tpms", "P", "--structure", "pore", "--threshold", 0, "--resolution", 12]
    code, _, err = run_cli(*args, "-o", target)
    assert code != 0 and "exists" in err and target.read_bytes() == b"keep me"
    code, _, err = run_cli(*args, "-o", target, "--force")
    assert code == 0 and target.stat().st_size > 84
    code, _, err = run_cli(*args, "-o", tmp_path / "missing_dir" / "y.stl")
    assert code != 0 and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "missing_dir").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.stl"]


def test_subprocess_bad_input_has_no_traceback(tmp_path):
    out = subprocess.run([sys.executable, "-m", "porecad.cli", "tpms", "P", "--structure", "pore",
                          "--threshold", "9"], capture_output=True, text=True, encoding="utf-8")
    assert out.returncode != 0 and "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_build_report_directory(run_cli, tmp_path):
    """Every build command's --report DIR: the full analysis, the HTML and the p-C curve of the design."""
    d = tmp_path / "rep"
    code, out, err = run_cli("tpms", "G", "--structure", "sheet", "--porosity", 0.6, "--cells", 2, 2, 2,
                             "--resolution", 16, "--report", d, "--json")
    assert code == 0, err
    r = json.loads(out)
    assert r["report_dir"] == str(d)
    for name in ("report.json", "report.html", "porosity_threshold.png", "pore_sizes.png", "preview.png"):
        assert (d / name).stat().st_size > 0, name
    full = json.loads((d / "report.json").read_text(encoding="utf-8"))
    assert full["build"]["type"] == "G" and full["open_pore_fraction"] > 0.99
    assert abs(full["porosity"] - r["porosity"]) < 0.05  # bounding box = the cells' box here
    # a second run refuses to overwrite the directory's files, before doing any work
    code, out, err = run_cli("tpms", "G", "--structure", "sheet", "--porosity", 0.6, "--report", d)
    assert code != 0 and "already exists" in err
    # a .json path still gives a plain JSON report
    j = tmp_path / "r.json"
    code, out, err = run_cli("tpms", "G", "--structure", "sheet", "--porosity", 0.6, "--resolution", 12,
                             "--report", j)
    assert code == 0 and json.loads(j.read_text(encoding="utf-8"))["type"] == "G"


def test_build_report_has_analytic_curvature(run_cli, tmp_path):
    """Issue 8 acceptance 2: a TPMS build's report carries curvature from the field (P surface: symmetric, K <= 0)."""
    d = tmp_path / "rep"
    code, out, err = run_cli("tpms", "P", "--structure", "pore", "--threshold", 0, "--cells", 2, 2, 2,
                             "--resolution", 24, "--report", d)
    assert code == 0, err
    full = json.loads((d / "report.json").read_text(encoding="utf-8"))
    h, k = full["mean_curvature_analytic"], full["gaussian_curvature_analytic"]
    assert abs(h["mean"]) < 0.03 and abs(h["max"] + h["min"]) < 0.1 and 0.9 < h["max"] < 1.29
    assert k["max"] <= 1e-9 and full["curvature_analytic_vertices"] > 1000
    assert "mean curvature analytic" in (d / "report.html").read_text(encoding="utf-8")
