"""Issue 21: every job reruns from its recipe (`--recipe` then `porecad build`), identically.

Each of the eight jobs is built small from the command line with
``--recipe``, rerun with ``porecad build RECIPE --force``; the mesh (vertices
and faces) and the report apart from timings must be the same. Also: format-1
recipes keep working, unknown keys are refused by name, paths are relative to
the recipe file, and the recipe file is never overwritten.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import tomllib
import trimesh

from porecad.io import read_mesh


def _strip(obj):
    """A report without timings (any key ending in ``_s`` or named ``timings``) or paths of temp files."""
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k not in ("timings", "time_s") and not k.endswith("_s")}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def _ball(path, radius=6.0):
    trimesh.creation.icosphere(subdivisions=3, radius=radius).export(path)
    return path


def _tube(path):
    path.write_text(json.dumps({"points": [[0, 0, 0], [0, 0, 2], [0, 0, 4]], "radii": [0.6, 0.6, 0.6],
                                "edges": [[0, 1], [1, 2]]}))
    return path


JOBS = {
    "tpms": lambda d: ["tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "1", "1", "1",
                       "--resolution", "20"],
    "infill": lambda d: ["infill", _ball(d / "ball.stl"), "G", "--porosity", "0.6", "-L", "4", "--voxel", "0.5"],
    "tbss": lambda d: ["tbss", "box", "G", "--periods", "1", "1", "1", "--resolution", "8", "--tdf-grid", "10",
                       "--tdf-control", "4"],
    "hex": lambda d: ["hex", "frustum", "P", "--grid", "2", "2", "2", "--threshold", "0", "--resolution", "8"],
    "tis": lambda d: ["tis", "--regular-tet", "--type", "P", "--relative-threshold", "0.2", "--resolution", "16"],
    "arbf": lambda d: ["arbf", "--mesh", "tet", "--resolution", "10"],
    "vessel": lambda d: ["vessel", _tube(d / "tube.json"), "--voxel", "0.2"],
}


@pytest.mark.parametrize("job", sorted(JOBS))
def test_cli_recipe_then_build_gives_the_same_mesh_and_report(run_cli, tmp_path, job):
    work = tmp_path / "work"
    work.mkdir()
    mesh, recipe = work / "out.stl", work / "out.toml"
    code, out, err = run_cli(*JOBS[job](work), "-o", mesh, "--recipe", recipe, "--json")
    assert code == 0, err
    first = json.loads(out)
    v1, f1 = read_mesh(mesh)
    text = recipe.read_text()
    data = tomllib.loads(text)
    assert data["job"] == job and data["format"] == 2 and data["porecad_version"] == first["porecad_version"]
    assert "recipe" not in data.get("output", {})  # a rerun never rewrites its own recipe
    assert not any(os.path.isabs(str(v)) for v in data.get("output", {}).values())  # portable
    code, out, err = run_cli("build", recipe, "--force", "--json")
    assert code == 0, err
    second = json.loads(out)
    v2, f2 = read_mesh(mesh)
    assert np.array_equal(f1, f2) and np.array_equal(v1, v2)
    assert _strip(first) == _strip(second)
    assert recipe.read_text() == text
    assert first["job"] == job and first["closed"] and first["manifold"]


def test_ivd_recipe_then_build(run_cli, tmp_path):
    spine = tmp_path / "spine"
    assert run_cli("phantom", "spine", "-o", spine, "--discs", "1", "--seed", "3")[0] == 0
    out, recipe = tmp_path / "discs", tmp_path / "ivd.toml"
    code, o, err = run_cli("ivd", spine, "--method", "tpms", "-o", out, "--recipe", recipe, "--json")
    assert code == 0, err
    first = json.loads(o)
    mesh1 = read_mesh(out / "disc_01_tpms.stl")
    code, o, err = run_cli("build", recipe, "--force", "--json")
    assert code == 0, err
    second = json.loads(o)
    mesh2 = read_mesh(out / "disc_01_tpms.stl")
    assert np.array_equal(mesh1[1], mesh2[1]) and np.array_equal(mesh1[0], mesh2[0])
    assert _strip(first) == _strip(second)
    code, o, err = run_cli("build", recipe, "--json")  # without --force: the outputs exist
    assert code != 0 and "already exists" in err


def test_recipe_paths_are_relative_to_the_recipe_file(run_cli, tmp_path, monkeypatch):
    d = tmp_path / "design"
    d.mkdir()
    _ball(d / "ball.stl")
    monkeypatch.chdir(d)
    code, _, err = run_cli("infill", "ball.stl", "P", "--porosity", "0.6", "-L", "4", "--voxel", "0.6",
                           "-o", "a.stl", "--recipe", "a.toml")
    assert code == 0, err
    data = tomllib.loads((d / "a.toml").read_text())
    assert data["domain"]["path"] == "ball.stl" and data["output"]["mesh"] == "a.stl"
    monkeypatch.chdir(tmp_path)  # run it from elsewhere: paths still resolve against the recipe
    code, out, err = run_cli("build", d / "a.toml", "--force", "--json")
    assert code == 0, err
    assert json.loads(out)["mesh_file"] == str(d / "a.stl")


def test_format_1_recipe_still_runs(run_cli, tmp_path):
    (tmp_path / "v1.toml").write_text(
        'job = "tpms"\nformat = 1\n[tpms]\ntype = "P"\nstructure = "pore"\nthreshold = 0.0\ncell_size = 1.0\n'
        '[domain]\nkind = "box"\ncells = [1, 1, 1]\n[sampling]\nresolution = 30\n[output]\nmesh = "v1.stl"\n')
    code, out, err = run_cli("build", tmp_path / "v1.toml", "--json")
    assert code == 0, err
    rep = json.loads(out)
    assert abs(rep["porosity"] - 0.5) < 0.01 and (tmp_path / "v1.stl").exists()


@pytest.mark.parametrize("text, match", [
    ('job = "tpms"\n[tpms]\ntype = "P"\nthreshold = 0.0\ncell_sise = 2.0\n', "tpms.cell_sise"),
    ('job = "tpms"\ncolour = "red"\n[tpms]\ntype = "P"\nthreshold = 0.0\n', "colour"),
    ('job = "tis"\n[tis]\nrelative = 0.2\n[mesh]\nresolution = 4611686018427387904\n', "mesh.resolution"),
    ('job = "printer"\n', "unknown job"),
    ('job = "tpms"\nformat = 99\n[tpms]\ntype = "P"\nthreshold = 0.0\n', "newer"),
    ('job = "vessel"\n[input]\npath = "/nonexistent.json"\n', "no such file"),
])
def test_bad_recipes_are_refused_by_key(one_line_error, tmp_path, text, match):
    (tmp_path / "r.toml").write_text(text)
    one_line_error("build", tmp_path / "r.toml", match=match)


def test_output_equal_to_input_or_to_another_output_is_refused(one_line_error, tmp_path):
    ball = _ball(tmp_path / "ball.stl")
    one_line_error("infill", ball, "P", "--porosity", "0.6", "-o", ball, "--force", match="input")
    one_line_error("tpms", "P", "--threshold", "0", "-o", tmp_path / "x.stl", "--report", tmp_path / "x.stl",
                   match="two different files")
    assert ball.stat().st_size > 0 and not (tmp_path / "x.stl").exists()
