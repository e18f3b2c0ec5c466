import json
from pathlib import Path

import pytest

from porecad.cli import main


@pytest.fixture
def run_cli(capsys):
    """Run the CLI in-process; return (exit code, stdout, stderr)."""

    def _run(*args):
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return code, out, err

    return _run


@pytest.fixture
def one_line_error(run_cli):
    """Run the CLI expecting a failure with one line on stderr (containing ``match``), no traceback."""

    def _check(*args, match):
        code, out, err = run_cli(*args)
        assert code != 0
        assert len(err.strip().splitlines()) == 1, err
        assert match in err, err
        assert "Traceback" not in err
        return err

    return _check


@pytest.fixture
def run_json(run_cli):
    def _run(*args):
        code, out, err = run_cli(*args, "--json")
        assert code == 0, err
        return json.loads(out)

    return _run


FEMUR = Path(__file__).resolve().parents[2] / "shared" / "data" / "femur.stl"


def _real_femur():
    """The real femur (``$PORECAD_FEMUR`` or ``../shared/data/femur.stl``), or None."""
    from porecad.datasets import femur_path as find
    from porecad.errors import InputError
    try:
        return find()
    except InputError:
        return FEMUR if FEMUR.exists() else None


def pytest_report_header(config):
    """Say, at the top of every run, which femur the femur tests measure (issue 38: no silent fallback)."""
    real = _real_femur()
    if real is not None:
        return f"porecad femur tests: {real}"
    return ("porecad femur tests: ../shared/data/femur.stl is MISSING: they run on a generated 120 mm capsule "
            "(femur_path), which checks the same promises on other geometry; set PORECAD_FEMUR to use the femur")


@pytest.fixture(scope="session")
def femur_path(tmp_path_factory):
    """The real femur, or a generated femur-sized capsule where the shared data is absent (the run's header
    says which: :func:`pytest_report_header`)."""
    real = _real_femur()
    if real is not None:
        return real
    import trimesh
    p = tmp_path_factory.mktemp("body") / "capsule.stl"
    trimesh.creation.capsule(height=120.0, radius=14.0, count=[48, 48]).export(p)
    return p
