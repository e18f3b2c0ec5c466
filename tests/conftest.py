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


@pytest.fixture(scope="session")
def femur_path(tmp_path_factory):
    """``../shared/data/femur.stl`` (or ``$PORECAD_FEMUR``, :func:`porecad.datasets.femur_path`), or a
    generated femur-sized capsule where the shared data is absent."""
    from porecad.datasets import femur_path as find
    from porecad.errors import InputError
    try:
        return find()
    except InputError:
        pass
    if FEMUR.exists():
        return FEMUR
    import trimesh
    p = tmp_path_factory.mktemp("body") / "capsule.stl"
    trimesh.creation.capsule(height=120.0, radius=14.0, count=[48, 48]).export(p)
    return p
