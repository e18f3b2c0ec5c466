"""Every registered job holds to the contract (issue 38 item 5): spec -> run -> Result -> runner.

For each job of the registry, a small recipe (the one ``test_recipes`` builds
from the command line) is parsed into its spec and run in memory
(``runner.run_job``: the job, then the runner's check of its solid) in an empty
folder: it returns a :class:`Result` with a validated solid and writes nothing (the whole folder tree, the recipe's outputs
included, is the same before and after); the runner's report then has every
common key and every warning structured. ``ivd`` is the documented
exception (it writes its folder itself: docs/architecture.md).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import tomllib
from test_recipes import JOBS

from porecad.findings import Finding
from porecad.jobs import registry
from porecad.jobs.contract import Result
from porecad.jobs.runner import COMMON_KEYS, common_report, parse, run_job

WRITES_ITS_OWN_FOLDER = {"ivd"}


def _tree(root):
    return sorted((os.path.relpath(os.path.join(d, n), root), os.path.getsize(os.path.join(d, n)))
                  for d, _, names in os.walk(root) for n in names)


def test_every_registered_job_is_covered():
    assert set(registry.names()) == set(JOBS) | WRITES_ITS_OWN_FOLDER


@pytest.mark.parametrize("name", sorted(JOBS))
def test_run_computes_and_writes_nothing(run_cli, tmp_path, name, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    code, _, err = run_cli(*JOBS[name](work), "-o", work / "out.stl", "--recipe", work / "out.toml")
    assert code == 0, err
    recipe = tomllib.loads((work / "out.toml").read_text())
    (work / "out.stl").unlink()  # the output the recipe names: run must not write it again
    empty = tmp_path / "cwd"
    empty.mkdir()
    monkeypatch.chdir(empty)
    job, spec, outputs, _ = parse(recipe, base=work)
    assert job.name == name and outputs["mesh"] == os.path.join(str(work), "out.stl")
    before = _tree(tmp_path)
    result = run_job(job, spec)
    assert _tree(tmp_path) == before  # nothing written, anywhere under the test's folder
    assert isinstance(result, Result) and not result.mesh_written
    v = np.asarray(result.vertices)
    assert np.array_equal(v, v.astype(np.float32)) and result.faces.shape[1] == 3 and len(result.faces) > 0
    report = common_report(result.report, job.name, 2)
    assert list(report)[:len(COMMON_KEYS)] == list(COMMON_KEYS)
    assert report["closed"] and report["manifold"] and report["triangles"] == len(result.faces)
    for w in report["warning_details"]:  # structured: a valid code (never plain text), a sentence, JSON values
        assert w["code"] != "note", w
        assert Finding(w["code"], w["message"], w["values"]).as_dict() == w
    assert report["warnings"] == [w["message"] for w in report["warning_details"]]
