"""Slices for printers (issue 40): slices equal the solid, printability with known answers, orientation, bad input.

Areas are measured from the written files with Pillow and shapely and compared with trimesh sections of a
fine mesh of the same design, not with the slicer's own numbers.
"""

from __future__ import annotations

import functools
import io
import json
import re
import zipfile

import numpy as np
import pytest
import trimesh
from defusedxml import ElementTree
from PIL import Image
from shapely.geometry import MultiPoint, Polygon

from porecad.cli.main import main
from porecad.fields.base import FunctionField
from porecad.printing import Part, Printer, slice_to
from porecad.printing.formats import read_cli_ascii
from section_reference import section_area


def png_areas(path):
    with zipfile.ZipFile(path) as z:
        man = json.loads(z.read("manifest.json"))
        p = man["pixel_size"]
        names = sorted(n for n in z.namelist() if n.startswith("layers/"))
        areas = [np.asarray(Image.open(io.BytesIO(z.read(n))), dtype=float).sum() / 255 * p * p for n in names]
    return man, areas


def svg_layers(path):
    """``[(z, shapely geometry)]`` of a layered SVG: each path even-odd from its M ... Z rings."""
    root = ElementTree.parse(str(path)).getroot()
    out = []
    for g in root.iter("{http://www.w3.org/2000/svg}g"):
        geom = Polygon()
        for p in g.iter("{http://www.w3.org/2000/svg}path"):
            rings = [np.array([[float(v) for v in pt.split(",")] for pt in re.findall(r"[-\d.]+,[-\d.]+", r)])
                     for r in p.get("d").split("Z") if r.strip()]
            geom = geom.union(functools.reduce(lambda a, b: a.symmetric_difference(b), [Polygon(r) for r in rings]))
        out.append((float(g.get("data-z")), geom))
    return out


@pytest.fixture(scope="module")
def gyroid(tmp_path_factory):
    """A gyroid sheet box (2 x 2 x 1 cells of 2 mm) sliced to PNG, SVG and CLI, and a fine mesh of it."""
    from porecad.lattice.plan import plan_lattice
    from porecad.jobs.runner import parse
    from porecad.mesh.polygonise import polygonise
    from porecad.printing import from_source
    d = tmp_path_factory.mktemp("gyroid")
    recipe = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": 2.0},
              "domain": {"kind": "box", "cells": [2, 2, 1]}, "sampling": {"resolution": 60}}
    plan = plan_lattice(parse(recipe, d)[1])
    res = polygonise(plan.field.sample_grid, plan.grid, caps=True)
    mesh = trimesh.Trimesh(res.vertices, res.faces)
    part = from_source(recipe, d)
    printer = Printer(min_feature=0.1, min_channel=0.1)
    reports = {ext: slice_to(part, d / f"g.{ext}", printer, pixel=0.02, layer=0.1, check=False)
               for ext in ("zip", "svg", "cli")}
    return d, mesh, reports


def test_png_layers_equal_the_mesh_sections(gyroid):
    d, mesh, reports = gyroid
    man, areas = png_areas(d / "g.zip")
    assert man["layer_count"] == 20 and man["image_width"] == 200 and man["pixel_size"] == 0.02
    errs = []
    for k, a in enumerate(areas):
        ref = section_area(mesh, man["origin"][2] + (k + 0.5) * man["layer_height"])
        if ref > 1.0:
            errs.append(abs(a - ref) / ref)
    assert len(errs) == 20 and max(errs) < 0.01, max(errs)


def test_svg_and_cli_contours(gyroid):
    d, mesh, reports = gyroid
    layers = svg_layers(d / "g.svg")
    assert len(layers) == 20
    man = reports["svg"]["manifest"]
    for z, geom in layers[::4]:  # data-z: the layer's top on the plate; its section is at its middle
        ref = section_area(mesh, z - man["layer_height"] / 2 - man["plate"]["offset"][2])
        assert abs(geom.area - ref) / ref < 0.005
    cli = read_cli_ascii((d / "g.cli").read_text())
    assert len(cli) == 20
    for (z, geom), (zc, lines) in zip(layers[::5], cli[::5]):
        assert abs(z - zc) < 1e-6
        outer = [p for direction, p in lines if direction == 1]
        assert len(outer) == len(getattr(geom, "geoms", [geom]))
        # every CLI vertex lies on the SVG's boundary within one pixel (0.02 mm)
        pts = np.vstack([p for _, p in lines])
        assert geom.boundary.hausdorff_distance(MultiPoint(pts)) < 0.02


def _box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return lambda x, y, z: np.maximum(np.maximum(np.maximum(lo[0] - x, x - hi[0]), np.maximum(lo[1] - y, y - hi[1])),
                                      np.maximum(lo[2] - z, z - hi[2]))


def known_part(clean=False):
    """A 10 x 10 x 3 mm block; unless clean: a 0.25 mm wall on it, a closed 0.8 mm cavity, a 0.5 mm hole through
    it and a block floating from z = 4.5."""
    base = _box([0, 0, 0], [10, 10, 3])
    if clean:
        return Part(np.zeros(3), np.array([10.0, 10, 3]), field=FunctionField(base))
    wall = _box([2, 2, 3], [2.25, 8, 5])
    floating = _box([6, 3, 4.5], [8, 5, 5.5])

    def f(x, y, z):
        cavity = 0.8 - np.sqrt((x - 7) ** 2 + (y - 7) ** 2 + (z - 1.5) ** 2)
        hole = 0.25 - np.sqrt((x - 5) ** 2 + (y - 2) ** 2) + 0 * z
        block = np.maximum(np.maximum(base(x, y, z), cavity), hole)
        return np.minimum(np.minimum(block, wall(x, y, z)), floating(x, y, z))
    return Part(np.zeros(3), np.array([10.0, 10, 5.5]), field=FunctionField(f))


def test_printability_known_answers(tmp_path):
    printer = Printer(min_feature=0.6, min_channel=1.0)
    r = slice_to(known_part(), tmp_path / "k.zip", printer, pixel=0.05, layer=0.1)
    found = {w.code: w.values for w in r["warnings"]}
    assert {"thin-wall", "closed-pore", "mid-air-start", "narrow-channel"} <= set(found)
    assert all(found[c]["count"] == 1 for c in ("thin-wall", "closed-pore", "mid-air-start", "narrow-channel"))
    assert abs(found["mid-air-start"]["z"][0] - 4.5) <= 0.1
    assert np.allclose(found["mid-air-start"]["at"][0], [7.0, 4.0], atol=0.1)
    assert np.allclose(found["thin-wall"]["at"][0][:2], [2.125, 5.0], atol=0.3)
    assert np.allclose(found["closed-pore"]["at"][0], [7.0, 7.0, 1.5], atol=0.2)
    assert np.allclose(found["narrow-channel"]["at"][0][:2], [5.0, 2.0], atol=0.2)
    assert r["overhangs"]["unsupported_area"] > 2.0  # the floating block's underside (4 mm²) and the cavity's roof
    clean = slice_to(known_part(clean=True), tmp_path / "c.zip", printer, pixel=0.05, layer=0.1)
    assert clean["warnings"] == [] and clean["overhangs"]["unsupported_area"] == 0.0
    assert clean["layers"] == 30 and clean["print_time_s"] == 30 * printer.layer_time


def test_a_check_coarser_than_the_limits_says_so(tmp_path, monkeypatch):
    """Issue 52: a wall and channel check the model's size bound makes coarser than the limits need carries the
    check-coarse caveat (never a silent "none found"); at the needed voxel it carries none."""
    import porecad.printing.printability as pr
    printer = Printer(min_feature=0.6, min_channel=1.0)
    fine = slice_to(known_part(clean=True), tmp_path / "f.zip", printer, pixel=0.05, layer=0.1)
    assert "check-coarse" not in {w.code for w in fine["warnings"]} and fine["checks"]["voxel"] <= 0.2 + 1e-9
    monkeypatch.setattr(pr, "MAX_CHECK_VOXELS", 20_000)
    coarse = slice_to(known_part(clean=True), tmp_path / "c.zip", printer, pixel=0.05, layer=0.1)
    found = {w.code: w.values for w in coarse["warnings"]}
    assert found["check-coarse"]["voxel"] == coarse["checks"]["voxel"] > 0.2
    assert found["check-coarse"]["needed"] == pytest.approx(0.2) and found["check-coarse"]["limit"] == 0.6


def l_bracket():
    """An L: a post 2 x 4 x 10 mm with a cantilever 8 mm long at its top (its underside needs supports)."""
    outline = Polygon([(0, 0), (2, 0), (2, 8), (8, 8), (8, 10), (0, 10)])  # in (x, z)
    m = trimesh.creation.extrude_polygon(outline, 4.0)  # (x, outline z, 0..4)
    m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))  # outline's second axis -> z
    m.apply_translation(-m.bounds[0])
    return m


def test_orientation_removes_the_cantilever_support(tmp_path):
    m = l_bracket()
    assert m.is_watertight and m.volume > 0
    part = Part(m.bounds[0], m.bounds[1], mesh=m)
    printer = Printer()
    plain = slice_to(part, tmp_path / "plain.zip", printer, pixel=0.1, layer=0.2, check=True)
    assert plain["overhangs"]["unsupported_area"] == pytest.approx(6 * 4, rel=1e-6)
    r = slice_to(part, tmp_path / "auto.zip", printer, pixel=0.1, layer=0.2, orient="auto")
    ranking = r["orientation"]["ranking"]
    assert len(ranking) == 26 and ranking[0]["unsupported_area"] == 0.0 and ranking[0]["height"] == pytest.approx(4)
    assert r["overhangs"]["unsupported_area"] == 0.0 and r["height"] == pytest.approx(4, abs=0.2)
    assert not [w for w in r["warnings"] if w.code in ("mid-air-start", "unsupported-overhang")]


def test_orientations_are_ranked_as_each_rotated_copy_would_be():
    """Ranking projects one mesh on each direction; judging a rotated copy (trimesh) gives the same figures."""
    from porecad.printing.part import directions, rotation_to_z
    from porecad.printing.slicing import rank_orientations
    m = l_bracket()
    printer, layer = Printer(), 0.2
    ranking = rank_orientations(m.vertices, m.faces, printer, layer)
    assert len(ranking) == 26
    limit = np.sin(np.radians(printer.max_overhang)) - 1e-9
    for r in ranking:
        d = np.asarray(r["direction"])
        c = m.copy()
        c.apply_transform(np.block([[rotation_to_z(d), np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]))
        nz = c.face_normals[:, 2]
        above = c.triangles_center[:, 2] > c.bounds[0][2] + layer
        unsupported = c.area_faces[(nz < -1e-9) & above & (-nz > limit)].sum()
        assert r["unsupported_area"] == pytest.approx(unsupported, abs=1e-5)
        assert r["height"] == pytest.approx(np.ptp(c.vertices[:, 2]), abs=1e-5)
    assert sorted(tuple(r["direction"]) for r in ranking) == sorted(tuple(np.round(d, 6)) for d in directions())


def test_mesh_file_route_and_the_cli(tmp_path, capsys):
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=3.0)
    sphere.export(tmp_path / "s.stl")
    assert main(["slice", str(tmp_path / "s.stl"), "-o", str(tmp_path / "s.zip"), "--pixel", "0.05",
                 "--layer", "0.2", "--json", "--no-check"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["route"] == "mesh" and report["layers"] == 30
    man, areas = png_areas(tmp_path / "s.zip")
    for k in (5, 15, 25):
        z = man["origin"][2] + (k + 0.5) * man["layer_height"]
        assert abs(areas[k] - section_area(sphere, z)) / section_area(sphere, z) < 0.01


@pytest.mark.parametrize("args, message", [
    (["--pixel", "0"], "pixel"), (["--pixel", "-1"], "pixel"), (["--layer", "1e308"], "layer height"),
    (["--layer", "0"], "layer height"), (["--pixel", "nan"], "pixel"),
])
def test_bad_sizes_are_one_line_errors(tmp_path, capsys, args, message):
    trimesh.creation.box([2, 2, 2]).export(tmp_path / "b.stl")
    assert main(["slice", str(tmp_path / "b.stl"), "-o", str(tmp_path / "b.zip"), *args]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("porecad: error:") and message in err[0]
    assert not (tmp_path / "b.zip").exists()


def test_profiles_are_untrusted_and_the_build_area_is_enforced(tmp_path, capsys):
    trimesh.creation.box([30, 2, 2]).export(tmp_path / "b.stl")
    (tmp_path / "bad.toml").write_text('pixel = 0.05\nlaser_power = 9000\n')
    (tmp_path / "small.toml").write_text('build = [20.0, 20.0, 20.0]\npixel = 0.1\nlayer = 0.1\n')
    (tmp_path / "worse.toml").write_text('build = [1e400, 1, 1]\n')
    for prof, words in (("bad.toml", "unknown key 'laser_power'"), ("small.toml", "larger than the printer's build"),
                        ("worse.toml", "build[0]"), ("missing.toml", "not found")):
        assert main(["slice", str(tmp_path / "b.stl"), "-o", str(tmp_path / "b.zip"),
                     "--printer", str(tmp_path / prof)]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
    assert not (tmp_path / "b.zip").exists()


def test_strict_refuses_and_writes_nothing(tmp_path, capsys):
    m = l_bracket()
    m.export(tmp_path / "l.stl")
    out = tmp_path / "l.svg"
    assert main(["slice", str(tmp_path / "l.stl"), "-o", str(out), "--pixel", "0.1", "--layer", "0.2",
                 "--strict"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not printable" in err[0] and not out.exists()
    assert main(["slice", str(tmp_path / "l.stl"), "-o", str(out), "--pixel", "0.1", "--layer", "0.2",
                 "--strict", "--orient", "auto"]) == 0
    assert out.exists()
    assert main(["slice", str(tmp_path / "l.stl"), "-o", str(out)]) != 0  # no overwrite without --force
    assert "exists" in capsys.readouterr().err


def test_island_kernel_matches_scipy_labels():
    from scipy import ndimage

    from porecad.printing._kernels import new_islands
    rng = np.random.default_rng(1)
    for _ in range(10):
        a = ndimage.binary_opening(rng.random((60, 70)) < 0.55)
        b = ndimage.binary_opening(rng.random((60, 70)) < 0.5)
        lab, n = ndimage.label(a, structure=np.ones((3, 3)))
        free = [i for i in range(1, n + 1) if not (b & (lab == i)).any()]
        counts, rows, cols = new_islands(a, b)
        assert sorted(counts.tolist()) == sorted(int((lab == i).sum()) for i in free)
        centres = [ndimage.center_of_mass(lab == i) for i in free]
        assert all(any(np.allclose(c, (y, x)) for c in centres) for y, x in zip(rows, cols))


def test_docs_worked_example_runs(tmp_path, monkeypatch, capsys):
    """Every fenced block of docs/printing.md: the profile is written, the commands and the Python run."""
    import shlex
    from pathlib import Path
    text = (Path(__file__).resolve().parents[2] / "docs" / "printing.md").read_text(encoding="utf-8")
    text = text.split("\n## The design as an implicit 3MF")[0]  # that section's examples: tests/docs and tests/io
    blocks = re.findall(r"```(\w+)\n(.*?)```", text, flags=re.S)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "slm.toml").write_text(next(b for lang, b in blocks if lang == "toml"))
    for name, body in re.findall(r"<!-- example: file (\S+) -->\n```\w*\n(.*?)```", text, flags=re.S):
        (tmp_path / name).write_text(body)  # the profiles the later commands read
    for lang, block in blocks:
        if lang == "bash":
            for line in block.strip().splitlines():
                assert main(shlex.split(line.split("  #")[0])[1:]) == 0, line
        elif lang == "python":
            exec(compile(block, "printing.md", "exec"), {"__name__": "__docs__"})  # safe: our own docs
    out = capsys.readouterr().out
    assert "50 field" in out
    with zipfile.ZipFile(tmp_path / "cube.zip") as z:
        assert json.loads(z.read("manifest.json"))["layer_count"] == 50
    assert read_cli_ascii((tmp_path / "cube.cli").read_text())[0][1]
    assert "[264, 209] 0.019 0.024" in out  # non-square pixels
    for name, size in (("cube-sl1", (1440, 2560)), ("cube-landscape.sl1", (2560, 1440))):  # whole canvases
        with zipfile.ZipFile(tmp_path / name) as z:
            assert Image.open(io.BytesIO(z.read("porecad00000.png"))).size == size
    with zipfile.ZipFile(tmp_path / "cube-saturn") as z:  # the preset's format: a .uvj
        assert json.loads(z.read("config.json"))["Properties"]["Size"]["X"] == 264


def test_turned_lattice_samples_its_own_grid():
    """A face-direction turn of a boxed lattice samples the lattice's grid: equal to point evaluation."""
    from porecad.fields.base import Field
    from porecad.fields.tpms import TPMSField
    from porecad.printing.part import Rotated, directions, rotation_to_z
    f = TPMSField("G", np.array([2.0, 2.0, 2.0]))
    xs, ys, zs = np.linspace(-3, 3, 7), np.linspace(-2, 4, 5), np.linspace(-1, 2, 4)
    for d in directions()[:6]:
        r = Rotated(f, rotation_to_z(d), np.array([-1.0, -1, -1]), np.array([1.5, 2, 2.5]), True)
        assert np.abs(r.sample_grid(xs, ys, zs) - Field.sample_grid(r, xs, ys, zs)).max() < 1e-5


def test_binary_cli_and_an_interrupted_slice_leaves_nothing(tmp_path):
    import struct
    part = known_part(clean=True)
    slice_to(part, tmp_path / "b.clib", Printer(), pixel=0.1, layer=0.5, check=False)
    data = (tmp_path / "b.clib").read_bytes()
    head, body = data.split(b"$$HEADEREND\n", 1)
    assert b"$$BINARY" in head and b"$$LAYERS/6" in head
    cmd, z = struct.unpack_from("<Hf", body, 0)
    assert cmd == 127 and z == 500.0  # the first layer's top on the plate, in µm
    cmd, _, direction, n = struct.unpack_from("<Hiii", body, 6)
    pts = np.frombuffer(body, dtype="<f4", count=2 * n, offset=20).reshape(n, 2) / 1000
    assert cmd == 130 and direction == 1 and Polygon(pts).area == pytest.approx(100.0, rel=1e-3)
    assert np.allclose(pts.min(axis=0), [55, 29], atol=1e-3)  # centred in the 120 x 68 mm build area

    def stop(stage, done, total):
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        slice_to(known_part(), tmp_path / "i.zip", Printer(), pixel=0.05, layer=0.05, check=False, progress=stop)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.clib"]


def test_a_mapped_job_is_sliced_from_its_mesh(tmp_path):
    """A tis recipe (a TPMS mapped over tets) goes the mesh route: its layers hold the mesh's volume."""
    from porecad.printing import from_source
    rec = {"job": "tis", "domain": {"kind": "regular-tet"}, "tis": {"type": "P", "relative": 0.3},
           "mesh": {"resolution": 12}}
    part = from_source(rec, tmp_path)
    assert part.route == "mesh" and part.mesh.is_watertight
    r = slice_to(part, tmp_path / "t.zip", Printer(), pixel=0.02, layer=0.05, check=False)
    _, areas = png_areas(tmp_path / "t.zip")
    assert sum(areas) * 0.05 == pytest.approx(part.mesh.volume, rel=0.01)
    assert r["route"] == "mesh" and r["layers"] == 163


def test_layer_bands_on_dask_workers_write_the_same_file(tmp_path):
    from porecad.printing import from_source
    rec = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": 2.0},
           "domain": {"kind": "box", "cells": [2, 2, 1]}, "sampling": {"resolution": 20}}
    part = from_source(rec, tmp_path)
    a = slice_to(part, tmp_path / "t.zip", Printer(), pixel=0.05, layer=0.05, check=False)
    b = slice_to(part, tmp_path / "d.zip", Printer(), pixel=0.05, layer=0.05, check=False, scheduler="local:2")
    assert a["layer_area"] == b["layer_area"] and a["mid_air_starts"] == b["mid_air_starts"]
    with zipfile.ZipFile(tmp_path / "t.zip") as z1, zipfile.ZipFile(tmp_path / "d.zip") as z2:
        names = [n for n in z1.namelist() if n.startswith("layers/")]
        assert len(names) == 40 and all(z1.read(n) == z2.read(n) for n in names)


def test_the_mesh_as_printed(tmp_path, capsys):
    """--mesh writes the part turned like its slices: the L bracket's own triangles, a lattice meshed."""
    l_bracket().export(tmp_path / "l.stl")
    assert main(["slice", str(tmp_path / "l.stl"), "-o", str(tmp_path / "l.zip"), "--pixel", "0.1", "--layer", "0.2",
                 "--orient", "auto", "--mesh", str(tmp_path / "l-printed.stl"), "--no-check"]) == 0
    capsys.readouterr()
    m = trimesh.load(tmp_path / "l-printed.stl")
    assert m.is_watertight and m.volume == pytest.approx(128.0) and np.ptp(m.bounds[:, 2]) == pytest.approx(4.0)
    recipe = tmp_path / "g.toml"
    recipe.write_text('job = "tpms"\n[tpms]\ntype = "G"\nstructure = "sheet"\nporosity = 0.7\ncell_size = 2.0\n'
                      '[domain]\nkind = "box"\ncells = [2, 1, 1]\n')
    assert main(["slice", str(recipe), "-o", str(tmp_path / "g.zip"), "--pixel", "0.05", "--layer", "0.05",
                 "--orient", "1,0,0", "--mesh", str(tmp_path / "g.stl"), "--no-check", "--json"]) == 0
    g = trimesh.load(tmp_path / "g.stl")
    assert g.is_watertight and np.ptp(g.bounds[:, 2]) == pytest.approx(4.0, abs=0.05)  # the x side is now z
    assert json.loads(capsys.readouterr().out)["layers"] == 80
