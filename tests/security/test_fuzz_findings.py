"""Issue 51, acceptance 2: what the fuzz run (tools/fuzz.py, tools/fuzz_hostile.py and hand-made extreme values)
found, each as the smallest case that reproduces it: a one-line refusal, never an internal error (exit 70)."""

from __future__ import annotations

import pytest

RECIPE = """job = "tpms"
[tpms]
type = "G"
structure = "sheet"
cell_size = 2.0
porosity = 0.6
[domain]
kind = "box"
cells = [1, 1, 1]
[sampling]
resolution = 8
"""


def _refused(code, err):
    lines = err.strip().splitlines()
    assert code not in (0, 70), err
    assert len(lines) == 1 and lines[0].startswith("porecad: error:"), err
    assert "internal error" not in err and "Traceback" not in err, err


@pytest.mark.parametrize("voxel", ["1e-308", "1e-320"])
def test_slice_mesh_voxel_tiny_is_refused(run_cli, tmp_path, voxel):
    """``slice RECIPE --mesh m.stl --mesh-voxel 1e-308``: the sample count overflowed (inf) and the size
    estimate raised OverflowError (exit 70); now refused before any mesh is made, nothing written."""
    recipe = tmp_path / "r.toml"
    recipe.write_text(RECIPE)
    code, _, err = run_cli("slice", recipe, "-o", tmp_path / "s.zip", "--mesh", tmp_path / "m.stl",
                           "--mesh-voxel", voxel, "--no-check")
    _refused(code, err)
    assert not (tmp_path / "m.stl").exists() and not (tmp_path / "s.zip").exists()


def test_polygonise_voxel_tiny_is_refused():
    """The library call the slice goes through: a voxel whose sample count overflows is a ResourceError."""
    import porecad as pc
    from porecad.errors import ResourceError
    with pytest.raises(ResourceError):
        pc.polygonise(pc.sphere(1.0), voxel=1e-308)


def test_unknown_tpms_type_message_is_bounded(run_cli, tmp_path):
    """A recipe's 100,000-character TPMS type was echoed whole into the one-line refusal (100 KB of stderr)."""
    recipe = tmp_path / "r.toml"
    recipe.write_text(RECIPE.replace('type = "G"', 'type = "' + "G" * 100_000 + '"'))
    code, _, err = run_cli("build", recipe)
    _refused(code, err)
    assert "unknown TPMS type" in err and len(err) < 1000, len(err)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -1.0, 1e308])
def test_studio_min_feature_out_of_range_is_a_field_error(value):
    """The studio's 'Printer minimum feature' (not a recipe key) reached the preview unchecked: nan or inf went
    into the preview's state and every poll of it was a server error (500, a traceback in the log). Now the design
    is refused with the field named, before any preview."""
    pytest.importorskip("starlette")
    from porecad.studio.design import FieldError, recipe_of
    with pytest.raises(FieldError) as info:
        recipe_of({"job": "tis", "min_feature": value})
    assert info.value.field == "min_feature"
    recipe_of({"job": "tis", "min_feature": 0.2})  # within its limits: accepted


def test_grid_spacing_too_small_is_refused():
    """A spacing whose sample count overflows (1e-308 mm) became a 2-sample grid (the count cast from inf), so a
    vessel at ``voxel = 1e-308`` said 'the vessel model is empty at this voxel size': now a ResourceError."""
    from porecad.errors import ResourceError
    from porecad.mesh.grid import Grid
    with pytest.raises(ResourceError, match="spacing"):
        Grid.from_box((0, 0, 0), (10, 10, 10), spacing=1e-308)
    assert Grid.from_box((0, 0, 0), (10, 10, 10), spacing=2.5).shape == (5, 5, 5)


def test_vessel_voxel_tiny_is_too_large_not_empty(run_cli, tmp_path):
    from pathlib import Path
    data = Path(__file__).resolve().parents[1] / "data" / "vessel-y-reference.json"
    code, _, err = run_cli("vessel", data, "--voxel", "1e-308", "-o", tmp_path / "v.stl")
    _refused(code, err)
    assert "empty" not in err and "samples" in err, err
