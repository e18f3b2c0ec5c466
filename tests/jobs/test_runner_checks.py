"""The runner, not the job, checks every solid before anything is written (issue 53 item 1).

A job hands over its mesh with a :class:`~porecad.jobs.contract.Validation`;
``runner.run_job`` checks it (closed, manifold, outward; self-intersections
where asked), adds the measured figures to the report, and only then calls
the job's ``derive``. These tests use a stand-in job whose solid is a cube,
or the cube with a face missing or turned inside out, so that each outcome
is known without porecad's own numbers.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from porecad.errors import MeshError
from porecad.jobs.contract import Job, Result, Validation
from porecad.jobs.runner import run_job
from porecad.mesh.validate import stored_coordinates

# the unit cube [0, 2]^3, outward oriented: volume 8, area 24
CUBE_V = 2.0 * np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                         [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
CUBE_F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                   [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])


def _job(vertices, faces, validation, derive=None, seen=None):
    def run(spec, progress=None, options=None):
        with options.stages("build"):
            pass
        if seen is not None:
            seen["vertices_dtype"] = np.asarray(vertices).dtype
        return Result({"kind": "stand-in"}, vertices, faces, validation=validation, derive=derive)
    return Job("stand-in", object, run)


def test_a_good_solid_gets_its_measured_figures_then_the_jobs_derive():
    calls = []

    def derive(report):
        calls.append(dict(report))  # what the job sees: the measured figures already there
        report["half_volume"] = report["volume"] / 2

    v = CUBE_V + np.float64(1e-9)  # not float32: the runner checks the coordinates the files store
    result = run_job(_job(v, CUBE_F, Validation("the cube", domain_volume=10.0), derive), spec=None)
    r = result.report
    assert r["kind"] == "stand-in" and r["closed"] and r["manifold"] and r["oriented"]
    assert r["volume"] == pytest.approx(8.0) and r["surface_area"] == pytest.approx(24.0)
    assert r["porosity"] == pytest.approx(0.2) and r["domain_volume"] == 10.0
    assert calls and calls[0]["volume"] == pytest.approx(8.0) and r["half_volume"] == pytest.approx(4.0)
    assert np.array_equal(result.vertices, stored_coordinates(v))  # the checked coordinates are those written
    assert result.check is not None and result.check["closed"]
    assert set(r["timings"]) >= {"build_s", "validate_s", "total_s"}


@pytest.mark.parametrize("broken", ["open", "inside out"])
def test_a_broken_solid_is_refused_and_derive_never_runs(broken):
    faces = CUBE_F[:-1] if broken == "open" else CUBE_F[:, ::-1]
    calls = []
    with pytest.raises(MeshError, match="the cube"):
        run_job(_job(CUBE_V, faces, Validation("the cube"), calls.append), spec=None)
    assert calls == []


def test_self_intersections_are_searched_when_asked_and_a_job_count_is_trusted():
    # two cubes overlapping: closed, manifold and outward, but the faces cross
    v2 = np.vstack([CUBE_V, CUBE_V + 1.0])
    f2 = np.vstack([CUBE_F, CUBE_F + 8])
    report = run_job(_job(v2, f2, Validation("two cubes")), spec=None).report  # not asked: written
    assert report["closed"] and "self_intersections" not in report
    with pytest.raises(MeshError, match="two cubes has [0-9]+ self-intersecting face pairs \\(try this\\)"):
        run_job(_job(v2, f2, Validation("two cubes", intersections=True, hint="try this")), spec=None)
    # a count the job made on exactly the coordinates the files store is taken as given, not searched again;
    # one made on coordinates the rounding moves is not trusted
    v32 = stored_coordinates(v2)
    with pytest.raises(MeshError, match="has 999 self-intersecting"):
        run_job(_job(v32, f2, Validation("two cubes", intersections=True, known_pairs=999)), spec=None)
    with pytest.raises(MeshError, match="self-intersecting") as exc:
        run_job(_job(v2 + 1e-9, f2, Validation("two cubes", intersections=True, known_pairs=999)), spec=None)
    assert "999" not in str(exc.value)


def test_a_result_with_nothing_to_check_is_left_as_the_job_made_it():
    job = _job(None, None, None)
    job = dataclasses.replace(job, run=lambda spec, progress=None, options=None: Result({"files": 3},
                                                                                       mesh_written=True))
    result = run_job(job, spec=None)
    assert result.report["files"] == 3 and "closed" not in result.report and result.check is None
