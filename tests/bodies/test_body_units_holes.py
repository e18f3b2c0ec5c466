"""Issue 42 items 4 and 5: a body in the wrong units is told so (and --units scales it); holes are closed
with a warning giving their count, or refused when large."""

import json

import numpy as np
import pytest
import trimesh

from porecad.bodies.units import units_finding

ARGS = ["G", "--porosity", "0.6", "-L", "5", "--voxel", "1.0", "--json"]


@pytest.fixture(scope="module")
def capsule():
    return trimesh.creation.capsule(height=100.0, radius=12.0, count=[24, 24])


def _write(tmp_path, name, v, f):
    p = tmp_path / name
    trimesh.Trimesh(v, f, process=False).export(p)
    return p


def _run(run_cli, *args):
    code, out, err = run_cli("infill", *args)
    return code, (json.loads(out) if code == 0 else None), err


def test_body_in_metres_is_told(run_cli, tmp_path, capsule):
    p = _write(tmp_path, "body_m.stl", capsule.vertices / 1000.0, capsule.faces)
    code, rep, err = _run(run_cli, p, *ARGS[:5], "--json", "-o", tmp_path / "out.stl")  # built, but told
    assert code == 0, err
    units = [w for w in rep["warning_details"] if w["code"] == "units"]
    assert units and units[0]["values"]["likely_units"] == "m", rep["warnings"]
    assert "porecad: warning:" in err and "metres" in err and "(--units m)" in err


def test_skin_refused_for_a_body_in_metres_names_its_units(one_line_error, tmp_path, capsule):
    """A skin that fills a body given in metres: the refusal says the likely unit (corpus, blob-metres)."""
    p = _write(tmp_path, "body_m.stl", capsule.vertices / 1000.0, capsule.faces)
    one_line_error("infill", p, "G", "--porosity", "0.6", "--boundary", "skin", "-o", tmp_path / "s.stl",
                   match="fills the body")
    err = one_line_error("infill", p, "G", "--porosity", "0.6", "--boundary", "skin", "-o", tmp_path / "s.stl",
                         match="probably in metres")
    assert "--units m" in err


@pytest.mark.parametrize("unit, factor", [("m", 1e-3), ("um", 1e3), ("in", 1 / 25.4)])
def test_likely_unit_named(capsule, unit, factor):
    f = units_finding(np.ptp(capsule.vertices, axis=0) * factor, 5.0 if unit != "in" else 1.0)
    assert f is not None and f.values["likely_units"] == unit, f
    assert units_finding(np.ptp(capsule.vertices, axis=0), 5.0) is None


def test_units_m_gives_the_millimetre_result(run_cli, tmp_path, capsule):
    mm = _write(tmp_path, "body.stl", capsule.vertices, capsule.faces)
    m = _write(tmp_path, "body_m.stl", capsule.vertices / 1000.0, capsule.faces)
    code, a, err = _run(run_cli, mm, *ARGS, "-o", tmp_path / "a.stl")
    assert code == 0, err
    code, b, err = _run(run_cli, m, *ARGS, "--units", "m", "-o", tmp_path / "b.stl")
    assert code == 0, err
    assert not [w for w in b["warning_details"] if w["code"] == "units"]
    assert b["triangles"] == a["triangles"]
    assert abs(b["porosity"] - a["porosity"]) < 1e-3
    m_ext = np.ptp(trimesh.load(tmp_path / "b.stl").vertices, axis=0)
    assert np.allclose(m_ext, np.ptp(trimesh.load(tmp_path / "a.stl").vertices, axis=0), atol=1e-3)


def test_small_holes_closed_with_a_warning(run_cli, tmp_path, capsule):
    keep = np.ones(len(capsule.faces), bool)
    keep[np.arange(10) * 97 + 5] = False  # ten faces apart from each other: ten holes
    p = _write(tmp_path, "holes.stl", capsule.vertices, capsule.faces[keep])
    code, rep, err = _run(run_cli, p, *ARGS, "-o", tmp_path / "out.stl")
    assert code == 0, err
    w = [w for w in rep["warning_details"] if w["code"] == "body-repaired"]
    assert w and w[0]["values"]["holes_closed"] == 10, rep["warnings"]
    assert "closed 10 holes" in err
    assert rep["closed"] and rep["manifold"]


def test_large_cut_away_refused_in_one_line(one_line_error, tmp_path, capsule):
    c = capsule.triangles_center
    p = _write(tmp_path, "cut.stl", capsule.vertices, capsule.faces[c[:, 2] < 40.0])
    one_line_error("infill", p, *ARGS, "-o", tmp_path / "out.stl", match="hole too large to close")
    assert not (tmp_path / "out.stl").exists()


# ------------------------------------------------------------------ size before work (item 3)


def test_large_output_announced_and_bounded(run_cli, tmp_path):
    args = ["tpms", "G", "--structure", "sheet", "--porosity", "0.7", "--cells", "10", "10", "10",
            "--resolution", "150", "--stream", "-o", tmp_path / "big.stl"]
    code, out, err = run_cli(*args, "--max-output", "2GB")
    assert code != 0 and "porecad: error: the mesh would be about" in err and "GB allowed" in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "big.stl").exists()
    from porecad.resources import announce_size, parse_size
    assert parse_size("2GB") == 2_000_000_000 and parse_size("1.5 GiB") == int(1.5 * 2**30)
    said = []
    assert announce_size({"stl_bytes": 2.1e10, "triangles": 4.2e8, "seconds": 480}, write=said.append)
    assert "420 M triangles" in said[0] and "21 GB" in said[0] and "8 min" in said[0]
    assert announce_size({"stl_bytes": 5e7, "triangles": 1e6, "seconds": 3}, write=said.append) is None


def test_report_summary_for_people():
    from porecad.analysis.summary import summary_html
    page = summary_html({"porosity": 0.690016, "surface_area": 13150.2, "pore_size_d50": 1.72577,
                         "strut_size_mean": 0.41, "triangles": 123456, "closed": True})
    for shown in ("69.0 %", "13,150 mm²", "pore size d50", "1.73 mm", "123,456", ">Part<", ">Pores<",
                  ">Struts and walls<", ">Mesh<"):
        assert shown in page, shown
    assert "surface_area" not in page and "0.690016" not in page
