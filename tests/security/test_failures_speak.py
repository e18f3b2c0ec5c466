"""Issue 51, problems 5, 6 and two of 9: every failure speaks, valid settings never end in an internal error.

The job's child process (``cli/watch.py``) and an in-process call map any
exception to one line on stderr and a non-zero exit: a porecad error keeps
its exit status, anything else is ``internal error: <Type>: <message>``
with status 70. The inputs of the fuzz run that met such an exception are
refused as bounded input errors before work (a cell of 1e-300 mm, element
sizes of 1e-300 and 1e300 mm, a degenerate surface, ``/proc`` as an image
folder); many Taubin iterations no longer fold the solid into an internal
error (the smoothing stops before the fold, with a ``smoothing-stopped``
warning); a studio websocket is refused cleanly; refine-box errors print
plain numbers.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from porecad.cli.main import INTERNAL_ERROR

TETRA = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def _one_line(code, err, *, status=None):
    assert code != 0
    if status is not None:
        assert code == status, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("porecad: error: "), err
    assert "Traceback" not in err
    return lines[0]


def _stl(path: Path, vertices, faces=TETRA) -> Path:
    import trimesh
    trimesh.Trimesh(np.asarray(vertices, float), faces, process=False).export(path)
    return path


def _porecad(cwd, *args, code=""):
    """``porecad ARGS`` as the program runs it (in a watched child process), after ``code``."""
    script = f"import sys\n{code}\nfrom porecad.cli.main import main\nsys.argv = ['porecad', *{list(args)!r}]\n" \
             "sys.exit(main())\n"
    env = {k: v for k, v in os.environ.items() if k != "PORECAD_WATCH"}
    return subprocess.run([sys.executable, "-c", script], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


# ------------------------------------------------------------------------------------- problem 5

def test_an_unexpected_exception_in_the_job_child_speaks(tmp_path):
    """Was: exit 1, nothing on stderr (the child's ``finally`` exited before the traceback)."""
    bug = "import porecad.recipes.schema as s\ndef boom(*a, **k):\n    1 / 0\ns.json_schema = boom"
    out = _porecad(tmp_path, "schema", "tpms", code=bug)
    line = _one_line(out.returncode, out.stderr, status=INTERNAL_ERROR)
    assert "internal error: ZeroDivisionError: division by zero" in line


def test_an_unexpected_exception_in_process_speaks(run_cli, monkeypatch):
    import porecad.recipes.schema as schema

    def boom(*args, **kwargs):
        raise KeyError("a\nsecond line")

    monkeypatch.setattr(schema, "json_schema", boom)
    code, _, err = run_cli("schema", "tpms")
    assert "internal error: KeyError: 'a" in _one_line(code, err, status=INTERNAL_ERROR)


def test_tiny_cell_is_refused_by_the_program(tmp_path):
    """The fuzz run's command as the program runs it: was a silent exit 1 (ZeroDivisionError in the estimate)."""
    out = _porecad(tmp_path, "tpms", "G", "--porosity", "0.6", "--cells", "1", "1", "1", "--cell-size", "1e-300",
                   "-o", "x.stl")
    line = _one_line(out.returncode, out.stderr, status=2)
    assert "--cell-size" in line and "0.001" in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("cell", ["1e-300", "1e-100", "0"])
def test_cell_sizes_below_the_bound_are_refused_before_work(run_cli, tmp_path, cell):
    code, _, err = run_cli("tpms", "G", "--porosity", "0.6", "--cells", "1", "1", "1", "--cell-size", cell,
                           "-o", tmp_path / "x.stl")
    assert "cell size must lie in [0.001" in _one_line(code, err, status=2)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("vertices,match", [
    ([[0, 0, 0]] * 4, "encloses no volume"),                                  # every triangle a point
    ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], "encloses no volume"),       # every triangle a line
])
def test_volmesh_of_a_degenerate_surface_is_refused(run_cli, tmp_path, vertices, match):
    mesh = _stl(tmp_path / "flat.stl", vertices)
    code, _, err = run_cli("volmesh", mesh, "-o", tmp_path / "v.msh")
    assert match in _one_line(code, err)
    assert not (tmp_path / "v.msh").exists()


@pytest.mark.parametrize("size", ["1e-300", "1e300", "nan", "0"])
def test_volmesh_sizes_out_of_bounds_are_refused(run_cli, tmp_path, size):
    a = 2.0
    mesh = _stl(tmp_path / "tet.stl", [[0, 0, 0], [a, 0, 0], [0, a, 0], [0, 0, a]])
    code, _, err = run_cli("volmesh", mesh, "-o", tmp_path / "v.msh", "--size", size)
    assert "element size must lie between" in _one_line(code, err, status=2)
    assert not (tmp_path / "v.msh").exists()


@pytest.mark.skipif(not Path("/proc/1").is_dir(), reason="no /proc here")
def test_ivd_of_proc_is_a_one_line_error(run_cli, tmp_path):
    code, _, err = run_cli("ivd", "/proc", "-o", tmp_path / "out")
    assert "/proc" in _one_line(code, err, status=2)
    assert not (tmp_path / "out").exists()


def test_coordinates_too_fine_for_float32_are_refused_not_an_internal_error(run_cli, tmp_path):
    """Valid settings (cells of 0.01 mm at 1e5 mm) that the files' float32 coordinates cannot hold."""
    code, _, err = run_cli("tpms", "G", "--porosity", "0.6", "--cells", "1", "1", "1", "--cell-size", "0.01",
                           "--resolution", "10", "--set", "domain.origin=[1e5, 1e5, 1e5]", "-o", tmp_path / "x.stl")
    line = _one_line(code, err, status=2)
    assert "too fine to store" in line and "internal error" not in line
    assert list(tmp_path.iterdir()) == []


def test_settings_that_leave_no_material_are_refused_not_an_internal_error(run_cli, tmp_path):
    code, _, err = run_cli("hex", "cylinder", "IWP", "--grid", "1", "1", "1", "--threshold", "1e300",
                           "--allow-closed-pores", "-o", tmp_path / "x.stl")
    line = _one_line(code, err, status=4)
    assert "is empty" in line and "internal error" not in line
    assert list(tmp_path.iterdir()) == []


def test_analysis_voxel_below_the_bound_is_refused(run_cli, tmp_path):
    a = 2.0
    mesh = _stl(tmp_path / "tet.stl", [[0, 0, 0], [a, 0, 0], [0, a, 0], [0, 0, a]])
    code, _, err = run_cli("analyze", mesh, "--pores", "--voxel", "1e-300", "--json")
    assert "voxel size must be at least" in _one_line(code, err, status=2)


@pytest.mark.parametrize("modulus", ["1e300", "1e-300", "nan"])
def test_moduli_that_would_overflow_the_solve_are_refused(run_cli, tmp_path, modulus):
    """``properties --E 1e300`` ran its 500 solver iterations on non-finite numbers (past 40 s): now refused."""
    a = 2.0
    mesh = _stl(tmp_path / "tet.stl", [[0, 0, 0], [a, 0, 0], [0, a, 0], [0, 0, a]])
    code, _, err = run_cli("properties", mesh, "--stiffness", "--E", modulus, "--voxels", "4")
    assert "Young's modulus must lie in" in _one_line(code, err, status=2)


# ------------------------------------------------------------------------------------- problem 6

def test_many_taubin_iterations_write_a_valid_solid(run_cli, tmp_path):
    """Was: ``internal error: the solid failed validation (... 'outward': False ...)``."""
    import trimesh

    from porecad.mesh.validate import check_solid
    out = tmp_path / "x.stl"
    code, _, err = run_cli("tpms", "G", "--porosity", "0.6", "--cells", "1", "1", "1", "--resolution", "10",
                           "--set", "post.smooth=taubin", "--set", "post.smooth_iterations=10000", "-o", out)
    assert code == 0, err
    assert "internal error" not in err and "Traceback" not in err
    assert "taubin smoothing stopped after" in err
    m = trimesh.load(out, process=True)
    chk = check_solid(m.vertices, m.faces, check_self_intersections=False)
    assert chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"], chk


def test_smooth_solid_keeps_every_step_that_does_not_fold():
    import trimesh

    from porecad.mesh.smooth import laplacian_smooth, smooth_solid, taubin_smooth
    s = trimesh.creation.icosphere(2)
    v, steps = smooth_solid(s.vertices, s.faces, "taubin", iterations=20)
    assert steps == 20
    np.testing.assert_array_equal(v, taubin_smooth(s.vertices, s.faces, iterations=20))
    # a bipyramid whose free equator vertex is pulled through the axis: the fourth step folds its faces
    v0 = np.array([[0, 0, 0.3], [0, 0, -0.3], [1, 0, 0], [-0.5, 0.866, 0], [-0.5, -0.866, 0]])
    faces = np.array([[0, 2, 3], [0, 3, 4], [0, 4, 2], [1, 3, 2], [1, 4, 3], [1, 2, 4]])
    fixed = np.array([True, True, False, True, True])
    v, steps = smooth_solid(v0, faces, "laplacian", iterations=10, fixed=fixed)
    assert steps == 3
    np.testing.assert_array_equal(v, laplacian_smooth(v0, faces, iterations=3, fixed=fixed))
    folded = laplacian_smooth(v0, faces, iterations=4, fixed=fixed)
    n0, n3, n4 = (np.cross(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]]) for x in (v0, v, folded))
    assert np.all(np.einsum("ij,ij->i", n3, n0) >= 0) and np.any(np.einsum("ij,ij->i", n4, n0) < 0)


# ------------------------------------------------------------------------------------- problem 9

def test_studio_websocket_is_refused_cleanly():
    """Was: 500 and ``ASGI callable returned without completing handshake`` on the server's console."""
    pytest.importorskip("starlette")
    pytest.importorskip("uvicorn")
    import http.client
    import logging

    from porecad.studio.launcher import make_studio
    from porecad.studio.server import Server

    records = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = records.append
    logger = logging.getLogger("uvicorn.error")
    srv = Server(make_studio(None, threads=1, max_upload=1 << 20)).start()
    logger.addHandler(handler)
    try:
        for path in ("/ws", f"/s/{srv.studio.session.token}/ws", "/s/wrong-token/ws"):
            conn = http.client.HTTPConnection("127.0.0.1", srv.studio.port, timeout=10)
            conn.request("GET", path, headers={"Upgrade": "websocket", "Connection": "Upgrade",
                                               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ==",
                                               "Sec-WebSocket-Version": "13"})
            status = conn.getresponse().status
            conn.close()
            assert status == 403, path
    finally:
        logger.removeHandler(handler)
        srv.stop()
    assert [r.getMessage() for r in records] == []


def test_refine_box_errors_print_plain_numbers(run_cli, tmp_path):
    code, _, err = run_cli("hex", "cylinder", "IWP", "--grid", "2", "2", "2", "--threshold", "0",
                           "--refine-box", "0", "0", "0", "0", "0", "0", "-o", tmp_path / "r.stl")
    line = _one_line(code, err, status=2)
    assert "np.int64" not in line and "(0, 0, 0)..(0, 0, 0)" in line and "(2, 2, 2)" in line
