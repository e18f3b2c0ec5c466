"""Issue 51, problem 8 and the Cancel of problem 9: size before work, cancel within moments.

Every job and ``slice`` estimate their peak memory and time before any
work (:mod:`porecad.resources`) and refuse in one line, with the estimate
and what to change, past the available memory, ``--max-memory`` or the
sample bound. The tests replace the first heavy step of each by a function
that fails, so a refusal that came after any work fails the test.

The studio's Export and Slice run in a child process that Cancel (or a new
Slice) kills: the tests use a job that never calls back (a compiled kernel
for minutes) and check that it stops, its process is gone and its folder,
temporary files included, is removed.
"""

from __future__ import annotations

import re
import tempfile
import time
from pathlib import Path

import pytest

RECIPE = """job = "tpms"
[tpms]
type = "G"
structure = "sheet"
cell_size = 2.0
porosity = 0.7
[domain]
kind = "box"
cells = [1, 1, 1]
[sampling]
resolution = 16
"""


def _refusal(code, err, status=3):
    assert code == status, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("porecad: error: "), err
    assert "Traceback" not in err
    return lines[0]


def _no_work(*args, **kwargs):
    raise AssertionError("work started before the size check")


def _gib(line: str) -> float:
    return float(re.search(r"needing about ([0-9.e+]+) GiB", line).group(1))


def test_hex_50_cubed_refused_before_work(run_cli, tmp_path, monkeypatch):
    """A 50³ grid passes the sample bound at resolution 12 but needs tens of GiB: refused with the estimate."""
    monkeypatch.setattr("porecad.jobs.hex_job.hex_nodes", _no_work)
    out = tmp_path / "big.stl"
    code, _, err = run_cli("hex", "cylinder", "P", "--grid", 50, 50, 50, "--resolution", 12, "--threshold", 0,
                           "-o", out, "--max-memory", "16GB")
    line = _refusal(code, err)
    assert "the hex scaffold is too large for this machine" in line
    assert _gib(line) > 20 and "triangles" in line and " min" in line  # the estimate: memory and time
    assert "--max-memory" in line and "--resolution" in line and "--grid" in line  # what to change
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_max_memory_refuses_a_small_job(run_cli, tmp_path, monkeypatch):
    monkeypatch.setattr("porecad.jobs.hex_job.hex_nodes", _no_work)
    code, _, err = run_cli("hex", "cylinder", "P", "--grid", 3, 3, 3, "--threshold", 0, "-o", tmp_path / "h.stl",
                           "--max-memory", "50MB")
    line = _refusal(code, err)
    assert "over the memory limit of 0.0466 GiB (--max-memory)" in line
    code, _, err = run_cli("hex", "cylinder", "P", "--grid", 3, 3, 3, "--threshold", 0, "-o", tmp_path / "h.stl",
                           "--max-memory", "lots")
    assert code == 2 and "--max-memory" in err and "not a size" in err


def test_slice_tiny_pixels_refused_before_work(run_cli, tmp_path, monkeypatch):
    """A 2 mm part at 0.1 µm pixels and layers: 8e12 pixels (about 67 h) refused, with pixels a layer x layers."""
    monkeypatch.setattr("porecad.printing.slicing.layers", _no_work)
    monkeypatch.setattr("porecad.printing.slicing.writer", _no_work)
    (tmp_path / "g.toml").write_text(RECIPE)
    out = tmp_path / "g.zip"
    code, _, err = run_cli("slice", tmp_path / "g.toml", "-o", out, "--pixel", "0.0001", "--layer", "0.0001")
    line = _refusal(code, err)
    assert "8e+12 pixels" in line and "4e+08 pixels a layer x 2e+04 layers" in line and " h)" in line
    assert "--pixel" in line and "--layer" in line
    assert not out.exists()


def test_a_long_slice_says_its_time_before_work(run_cli, tmp_path, monkeypatch):
    """A slice estimated past a minute (here 4,000 layers of 1 M pixels, about 2 min) that fits in memory
    says how long it will take before any layer is made (the fuzz run met one that said nothing for 70 s)."""
    monkeypatch.setattr("porecad.printing.slicing.layers", _no_work)
    (tmp_path / "g.toml").write_text(RECIPE)
    code, _, err = run_cli("slice", tmp_path / "g.toml", "-o", tmp_path / "g.zip", "--pixel", "0.002",
                           "--layer", "0.0005")
    first = err.strip().splitlines()[0]
    assert first.startswith("porecad: note: slicing this part (") and "min (estimated before it starts)" in first
    assert not (tmp_path / "g.zip").exists()


def test_slice_memory_estimate_and_max_memory(run_cli, tmp_path, monkeypatch):
    """Sections of a mesh at 0.2 µm pixels: 1e8 pixels a layer need GiB in flight; refused past --max-memory."""
    import trimesh
    monkeypatch.setattr("porecad.printing.slicing.layers", _no_work)
    trimesh.creation.box((2, 2, 2)).export(tmp_path / "box.stl")
    code, _, err = run_cli("slice", tmp_path / "box.stl", "-o", tmp_path / "b.zip", "--pixel", "0.0002",
                           "--layer", "0.02", "--max-memory", "4GB", "--orient", "auto")
    line = _refusal(code, err)
    assert "slicing this part is too large for this machine" in line and "(--max-memory)" in line
    assert _gib(line) > 20  # 1e8 pixels (more when turned) x 264 bytes in flight
    assert not (tmp_path / "b.zip").exists()


def test_tis_two_million_tets_refused_before_tetrahedralising(run_cli, tmp_path, monkeypatch):
    import trimesh
    monkeypatch.setattr("porecad.jobs.tis_job.tet_domain", _no_work)
    trimesh.creation.icosphere(subdivisions=2, radius=10).export(tmp_path / "ball.stl")
    args = ("tis", tmp_path / "ball.stl", "--tets", 2_000_000, "--relative-threshold", 0.2, "-o", tmp_path / "t.stl")
    line = _refusal(*run_cli(*args)[::2])
    assert "2,000,000 tets at 17 samples per edge are 1,637,666,667 lattice samples" in line and "--tets" in line
    line = _refusal(*run_cli(*args, "--resolution", 5, "--max-memory", "8GB")[::2])
    assert "the TIS scaffold is too large for this machine" in line and _gib(line) > 50 and "--tets" in line
    assert not (tmp_path / "t.stl").exists()


def test_the_other_jobs_are_sized(run_cli, tmp_path, monkeypatch):
    """tbss, arbf and vessel refuse past --max-memory before their heavy step, as hex and tis do."""
    import trimesh
    monkeypatch.setattr("porecad.jobs.tbss_job._prepare_cut", _no_work)
    code, _, err = run_cli("tbss", "box", "P", "--periods", 40, 40, 40, "--resolution", 16, "-o", tmp_path / "t.stl",
                           "--max-memory", "16GB")
    line = _refusal(code, err)
    assert "the TBSS scaffold is too large" in line and _gib(line) > 100 and "--resolution" in line
    monkeypatch.setattr("porecad.jobs.arbf_job.arbf_domain", _no_work)
    ball = tmp_path / "in" / "ball.stl"
    ball.parent.mkdir()
    trimesh.creation.icosphere(subdivisions=2, radius=10).export(ball)
    code, _, err = run_cli("arbf", ball, "--tets", 2000, "-o", tmp_path / "a.stl", "--max-memory", "500MB")
    line = _refusal(code, err)
    assert "the ARBF scaffold is too large" in line and "(--max-memory)" in line and "--tets" in line
    code, _, err = run_cli("arbf", ball, "--tets", 20000, "--resolution", 40, "-o", tmp_path / "a.stl")
    assert "samples (at most 40,000,000)" in _refusal(code, err)
    assert [p.name for p in tmp_path.iterdir()] == ["in"]


def test_vessel_estimate_is_refused_past_the_limit():
    from porecad.errors import ResourceError
    from porecad.vessels.field_grid import vessel_estimate
    from porecad.resources import require_fits
    est = vessel_estimate(1e8)
    assert 4e9 < est["peak_bytes"] < 10e9 and est["seconds"] > 10
    with pytest.raises(ResourceError, match=r"the vessel model is too large for this machine: about 1\.\d+e\+07 "
                                             r"triangles needing about [4-9]\.\d+ GiB .* \(`memory_limit`\); "
                                             r"use a larger `voxel`"):
        require_fits(est, 2 << 30, "use a larger `voxel`", "the vessel model")


# ------------------------------------------------------------------------------------------- the studio

def stubborn_job(*args, progress=None):
    """A job that leaves a temporary file and then computes for ten minutes without calling back."""
    folder = Path(tempfile.gettempdir())  # the child's temporary folder: the job's own
    (folder / ".partial.tmp").write_bytes(b"x" * 1000)
    tempfile.mkstemp()
    time.sleep(600)


def _until(predicate, timeout, what):
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"{what} within {timeout} s")
        time.sleep(0.02)
    return time.monotonic() - t0


@pytest.fixture
def session(tmp_path):
    from porecad.studio.session import Session
    s = Session(root=tmp_path)
    yield s
    s.close()


def test_studio_export_cancel_kills_the_job(session, monkeypatch):
    from porecad.studio import tasks
    monkeypatch.setitem(tasks.CHILD_JOBS, "export", f"{__name__}:stubborn_job")  # the child imports this file
    exports = tasks.Exports(session, threads=1)
    n = exports.start({"job": "tpms"}, "stl", html=False)
    folder = session.exports / "1"
    _until(lambda: (folder / ".partial.tmp").exists(), 60, "the export did not start")
    child = exports.jobs[n]["child"]
    assert exports.cancel(n)
    took = _until(lambda: exports.state(n)["state"] != "running", 10, "Cancel did not stop the export")
    assert exports.state(n)["state"] == "cancelled" and took < 10
    assert child.proc.poll() is not None
    assert list(session.exports.iterdir()) == []  # the folder, its partial file and temporary file removed


def test_studio_slice_cancel_and_new_slice_kill_the_running_one(session, monkeypatch):
    from porecad.studio import print_panel, tasks
    monkeypatch.setitem(tasks.CHILD_JOBS, "slice", f"{__name__}:stubborn_job")
    prints = print_panel.Prints(session)
    first = prints.start({"job": "tpms"})
    _until(lambda: (prints.folder / str(first) / ".partial.tmp").exists(), 60, "the slice did not start")
    child = prints.job["child"]
    second = prints.start({"job": "tpms"})  # a new Slice stops the running one
    _until(lambda: child.proc.poll() is not None and not (prints.folder / str(first)).exists(), 10,
           "a new Slice did not stop the running one")
    _until(lambda: (prints.folder / str(second) / ".partial.tmp").exists(), 60, "the second slice did not start")
    child = prints.job["child"]
    assert prints.cancel()
    _until(lambda: prints.state()["state"] == "cancelled", 10, "Cancel did not stop the slice")
    assert child.proc.poll() is not None
    assert list(prints.folder.iterdir()) == []


def test_studio_refuses_an_oversize_slice_before_work(session):
    """The studio's slice is sized as ``porecad slice`` sizes it: refused in one line, nothing left."""
    from porecad.studio.print_panel import Prints
    prints = Prints(session)
    recipe = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "cell_size": 2.0, "porosity": 0.7},
              "domain": {"kind": "box", "cells": [1, 1, 1]}, "sampling": {"resolution": 16}}
    prints.start(recipe, pixel=0.0001, layer=0.0001)
    _until(lambda: prints.state()["state"] != "running", 60, "the slice was not refused")
    s = prints.state()
    assert s["state"] == "failed" and "8e+12 pixels" in s["error"] and "`pixel`" in s["error"], s
    assert list(prints.folder.iterdir()) == []
