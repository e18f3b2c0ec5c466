"""The design as an implicit 3MF (issue 56, item 4): read back with lib3mf alone, evaluated here.

The function graph is walked from lib3mf's objects of a freshly read model and evaluated by
the small numpy evaluator below, written from the node semantics of the 3MF Volumetric &
Implicit Extensions v1.0 (not from porecad's writer), and compared with porecad's own field as
the slicer evaluates it (:func:`porecad.printing.part.from_recipe`).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

lib3mf = pytest.importorskip("lib3mf")
if tuple(lib3mf.get_wrapper().GetLibraryVersion()) < (2, 5, 0):  # pragma: no cover
    pytest.skip("lib3mf 2.5 or newer needed", allow_module_level=True)

T = lib3mf.ImplicitNodeType
UNARY = {T.Sinus: np.sin, T.Cosinus: np.cos, T.Abs: np.abs, T.Sqrt: np.sqrt}
BINARY = {T.Addition: np.add, T.Subtraction: np.subtract, T.Multiplication: np.multiply,
          T.Division: np.divide, T.Min: np.minimum, T.Max: np.maximum}


@pytest.fixture(autouse=True)
def _locale_kept():
    """lib3mf's writer and reader set the C locale process-wide: porecad's writer must put it back."""
    import locale
    saved = locale.setlocale(locale.LC_ALL, None)
    yield
    now = locale.setlocale(locale.LC_ALL, None)
    locale.setlocale(locale.LC_ALL, saved)
    assert now == saved  # porecad's writer puts the locale back (the reader below does too)


def _ports(iterator) -> dict:
    out = {}
    while iterator.MoveNext():
        port = iterator.GetCurrent()
        out[port.GetIdentifier()] = port.GetReference()
    return out


def read_level_set(path):
    """``(evaluate(points) -> values, bbox_only, mesh (vertices, faces), fallback)`` of the file's level set."""
    w = lib3mf.get_wrapper()
    model = w.CreateModel()
    import locale
    saved = locale.setlocale(locale.LC_ALL, None)
    model.QueryReader("3mf").ReadFromFile(str(path))
    locale.setlocale(locale.LC_ALL, saved)
    sets = model.GetLevelSets()
    assert sets.Count() == 1
    sets.MoveNext()
    level = sets.GetCurrentLevelSet()
    fn = model.GetResourceByID(level.GetFunction().GetResourceID())  # the ImplicitFunction itself
    channel = level.GetChannelName()
    nodes = {}
    it = fn.GetNodes()
    while it.MoveNext():
        node = it.GetCurrent()
        nodes[node.GetIdentifier()] = node
    outputs = _ports(fn.GetOutputs())
    mesh = level.GetMesh()
    vertices = np.array([v.Coordinates[:] for v in mesh.GetVertices()])
    faces = np.array([t.Indices[:] for t in mesh.GetTriangleIndices()])

    def evaluate(points):
        cache = {"inputs.pos": points}

        def value(ref):
            if ref in cache:
                return cache[ref]
            ident, out = ref.split(".")
            node = nodes[ident]
            kind = node.GetNodeType()
            args = {k: value(r) for k, r in _ports(node.GetInputs()).items()}
            if kind == T.Constant:
                v = np.full(len(points), node.GetConstant())
            elif kind == T.DecomposeVector:
                v = args["A"][:, "xyz".index(out)]
            elif kind in UNARY:
                v = UNARY[kind](args["A"])
            elif kind in BINARY:
                v = BINARY[kind](args["A"], args["B"])
            else:  # pragma: no cover - a node this evaluator does not know
                raise AssertionError(f"unexpected node type {kind}")
            cache[ref] = v
            return v
        return value(outputs[channel])
    return evaluate, level.GetMeshBBoxOnly(), (vertices, faces), level.GetFallBackValue()


def cube_recipe(tmp_path, tpms="G", structure="sheet", cells=8, cell=2.5, resolution=None, **tpms_keys):
    keys = {"porosity": 0.7} if not tpms_keys else tpms_keys
    r = {"job": "tpms", "tpms": {"type": tpms, "structure": structure, "cell_size": cell, **keys},
         "domain": {"kind": "box", "cells": [cells] * 3}, "output": {"mesh": str(tmp_path / "cube.stl")}}
    if resolution is not None:
        r["sampling"] = {"resolution": resolution}
    return r


def porecad_field(recipe, points):
    """porecad's field as the slicer evaluates it: the lattice cut to its box."""
    from porecad.printing.part import from_recipe
    part = from_recipe(recipe)
    v = part.field.evaluate(points)
    if part.boxed:
        v = np.maximum(v, np.max(np.maximum(part.lo - points, points - part.hi), axis=1))
    return v, part


def compare(tmp_path, recipe, name):
    from porecad.jobs.implicit_export import export_implicit
    out = tmp_path / f"{name}.3mf"
    report = export_implicit(recipe, out)
    evaluate, bbox_only, (v, f), fallback = read_level_set(out)
    pts = _points(v)  # 10^4 points in the evaluation mesh's box, 200 of them around it
    got = evaluate(pts)
    want, part = porecad_field(recipe, pts)
    return report, got, want, bbox_only, (v, f), fallback, part, out


@pytest.mark.parametrize("tpms, structure, keys", [
    ("G", "sheet", {"porosity": 0.7}),
    ("P", "pore", {"porosity": 0.6}),
    ("D", "rod", {"threshold": 0.3}),
    ("D", "sheet", {"porosity": 0.75}),
])
def test_field_matches_porecad(tmp_path, tpms, structure, keys):
    recipe = cube_recipe(tmp_path, tpms, structure, **keys)
    report, got, want, bbox_only, (v, f), fallback, part, _ = compare(tmp_path, recipe, f"{tpms}{structure}")
    assert np.max(np.abs(got - want)) < 1e-6
    clear = np.abs(want) > 1e-6
    assert np.array_equal(np.sign(got[clear]), np.sign(want[clear]))  # negative inside material, as porecad
    assert (want < 0).mean() > 0.1 and (want > 0).mean() > 0.1
    assert bbox_only and len(f) == 12 and fallback > 0
    np.testing.assert_allclose(v.min(axis=0), part.lo, atol=1e-6)
    np.testing.assert_allclose(v.max(axis=0), part.hi, atol=1e-6)
    assert report["type"] == tpms and report["structure"] == structure and report["domain"] == "box"


def test_per_axis_cells_and_origins(tmp_path):
    """Per-axis cell sizes, a lattice origin and a box origin (not at 0) are in the graph."""
    recipe = cube_recipe(tmp_path, "G", "sheet", cells=2, porosity=0.65)
    recipe["tpms"].update(cell_size=[2.5, 3.0, 2.0], origin=[0.3, -0.7, 1.1])
    recipe["domain"]["origin"] = [-1.0, 2.0, 0.5]
    report, got, want, *_ = compare(tmp_path, recipe, "axes")
    assert np.max(np.abs(got - want)) < 1e-6 and report["cell_size"] == [2.5, 3.0, 2.0]


def test_porosity_resolved_by_calibration(tmp_path):
    from porecad.calibration import threshold_for_porosity
    report, *_ = compare(tmp_path, cube_recipe(tmp_path), "g")
    assert report["threshold"] == pytest.approx(float(threshold_for_porosity("G", "sheet", 0.7)), abs=1e-12)


def test_linear_grading(tmp_path):
    recipe = cube_recipe(tmp_path, "G", "rod", cells=2, cell=5.0, threshold=None)
    del recipe["tpms"]["threshold"]
    recipe["grading"] = {"kind": "linear", "axis": "z", "start": 1.0, "end": 8.0, "from": -0.4, "to": 0.6}
    report, got, want, *_ = compare(tmp_path, recipe, "graded")
    assert np.max(np.abs(got - want)) < 1e-6
    assert report["threshold"]["v0"] == -0.4


def test_size_against_the_stl(tmp_path):
    """The 20 mm gyroid-sheet cube: the 3MF is < 1 % of the binary STL porecad writes for the same recipe.

    The STL is written at resolution 8 (a fifth of the default 40 samples per cell, about 1/25 of its
    triangles) to keep the test fast: the default-resolution STL is larger still (744 MB measured).
    """
    from porecad.jobs import run_recipe
    from porecad.jobs.implicit_export import export_implicit
    recipe = cube_recipe(tmp_path, resolution=8)
    report = export_implicit(recipe, tmp_path / "cube.3mf")
    run_recipe(recipe)
    stl = (tmp_path / "cube.stl").stat().st_size
    assert report["bytes"] == (tmp_path / "cube.3mf").stat().st_size
    assert report["bytes"] < 0.01 * stl, (report["bytes"], stl)


def test_refusals(tmp_path):
    from porecad.errors import InputError, OutputError
    from porecad.jobs.implicit_export import export_implicit
    out = tmp_path / "x.3mf"
    export_implicit(cube_recipe(tmp_path, cells=1), out)
    with pytest.raises(OutputError):
        export_implicit(cube_recipe(tmp_path, cells=1), out)
    export_implicit(cube_recipe(tmp_path, cells=1), out, force=True)
    with pytest.raises(InputError, match="surface"):
        export_implicit(cube_recipe(tmp_path, structure="surface", threshold=0.1), tmp_path / "s.3mf")
    r = cube_recipe(tmp_path, "G", "rod", cells=1, threshold=None)
    del r["tpms"]["threshold"]
    r["grading"] = {"kind": "expression", "expr": "0.1 * x"}
    with pytest.raises(InputError, match="grading"):
        export_implicit(r, tmp_path / "e.3mf")
    with pytest.raises(InputError, match=".3mf"):
        export_implicit(cube_recipe(tmp_path, cells=1), tmp_path / "x.stl")
    assert not (tmp_path / "s.3mf").exists() and not (tmp_path / "e.3mf").exists()


def test_split_constants_round_trip(tmp_path):
    """Every constant is written as parts of 6 digits that sum back to the double (lib3mf writes 6 digits)."""
    from porecad.io.implicit_3mf import split_constant
    for c in (2 * np.pi / 2.5, 0.46412259340286255, -1e-9 / 3, 1e6 / 7, 0.0, 3.0):
        parts = split_constant(c)
        assert all(float(f"{p:.6g}") == p for p in parts)
        total = 0.0
        for p in reversed(parts):
            total = p + total
        assert abs(total - c) <= 1e-15 * max(1.0, abs(c))


def test_cli(tmp_path):
    import os

    from porecad.io.recipe import save_recipe
    recipe = cube_recipe(tmp_path, cells=1)
    recipe["output"] = {"mesh": "cube.stl"}
    save_recipe(recipe, tmp_path / "cube.toml")
    env = {**os.environ, "PORECAD_WATCH": "0"}
    run = lambda *a: subprocess.run([sys.executable, "-m", "porecad", *a], cwd=tmp_path,  # noqa: E731
                                    capture_output=True, text=True, env=env)
    ok = run("export", "cube.toml", "-o", "cube.3mf", "--implicit")
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "cube.3mf").stat().st_size > 0
    again = run("export", "cube.toml", "-o", "cube.3mf", "--implicit")
    assert again.returncode != 0 and len(again.stderr.strip().splitlines()) == 1
    bad = run("export", "missing.toml", "-o", "m.3mf", "--implicit")
    assert bad.returncode != 0 and len(bad.stderr.strip().splitlines()) == 1


def test_infill_body_is_the_evaluation_mesh(tmp_path):
    """An infill: the level set is clipped to the body's mesh (not its box), the function is the lattice."""
    import trimesh
    body = trimesh.creation.icosphere(subdivisions=2, radius=6.0)
    body.export(tmp_path / "ball.stl")
    recipe = {"job": "infill", "tpms": {"type": "G", "structure": "sheet", "cell_size": 4.0, "porosity": 0.7},
              "domain": {"kind": "mesh", "path": str(tmp_path / "ball.stl")},
              "output": {"mesh": str(tmp_path / "ball_g.stl")}}
    report, got, want, bbox_only, (v, f), fallback, part, _ = compare(tmp_path, recipe, "ball")
    assert not bbox_only and len(f) == len(body.faces) and report["domain"] == "mesh"
    from porecad.bodies import MeshBody
    inside = MeshBody(v, f, band=1.0)(_points(v)) < 0  # inside the file's mesh (the clip of the level set)
    clipped = np.where(inside, got, 1.0)  # the spec: material where the function is < 0 inside the mesh
    clear = (np.abs(want) > 1e-3) & (np.abs(got) > 1e-3)
    assert np.array_equal(np.sign(clipped[clear]), np.sign(want[clear]))
    assert (want < 0).mean() > 0.05


def _points(v):
    rng = np.random.default_rng(56)
    lo, hi = v.min(axis=0), v.max(axis=0)
    pts = lo + (hi - lo) * rng.random((10_000, 3))
    pts[:200] = lo + (hi - lo) * rng.random((200, 3)) * 1.2 - 0.1 * (hi - lo)
    return pts


def test_without_lib3mf_one_line(tmp_path, monkeypatch):
    from porecad.errors import InputError
    from porecad.jobs.implicit_export import export_implicit
    monkeypatch.setitem(sys.modules, "lib3mf", None)  # import lib3mf raises ImportError
    with pytest.raises(InputError, match=r"porecad\[3mf\]") as info:
        export_implicit(cube_recipe(tmp_path, cells=1), tmp_path / "x.3mf")
    assert "\n" not in str(info.value) and not (tmp_path / "x.3mf").exists()
