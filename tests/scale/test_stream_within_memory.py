"""Issue 52: a job sized to need three times the memory it may use streams within it, with every check; one that
cannot stream is refused before any work with its estimate."""

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from porecad.errors import ResourceError
from porecad.jobs import run_recipe
from porecad.lattice.plan import plan_lattice
from porecad.jobs.runner import parse
from porecad.jobs.tpms_job import lattice_area
from porecad.resources import estimate


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    d = tmp_path_factory.mktemp("third")
    body = trimesh.creation.icosphere(4, radius=1.0)
    body.apply_scale([7.3, 6.1, 5.2])
    body.export(d / "ell.stl")
    recipe = {"job": "infill", "tpms": {"type": "G", "structure": "pore", "porosity": 0.6, "cell_size": 1.5},
              "domain": {"kind": "mesh", "path": str(d / "ell.stl")}, "sampling": {"voxel": 0.035}}
    _, spec, _, _ = parse(recipe, d)
    plan = plan_lattice(spec)
    apv, solid = lattice_area(plan)
    est = estimate(plan.grid, plan.cell_size, plan.structure, plan.domain_volume, plan.domain_area * solid,
                   16 << 20, 2, apv)
    return d, recipe, est


def test_three_times_the_memory_streams_within_it_with_every_check(job):
    d, recipe, est = job
    limit = int(est["peak_bytes"] / 3)
    # in a process of its own: a test worker's memory holds what earlier tests left
    p = subprocess.run([sys.executable, "-m", "porecad", "infill", str(d / "ell.stl"), "G", "--porosity", "0.6",
                        "-L", "1.5", "--voxel", "0.035", "-o", str(d / "third.stl"), "--json", "--threads", "2",
                        "--max-memory", str(limit)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["scale"]["stream"] and r["scale"]["chunk_bytes"] < 16 << 20  # thinner slabs to fit
    assert r["scale"]["peak_memory_bytes"] <= limit
    assert r["estimate"]["peak_bytes"] <= limit
    assert r["estimate"]["peak_bytes"] == pytest.approx(r["scale"]["peak_memory_bytes"], rel=0.5)
    assert r["pieces"] == 1 and r["islands_dropped"] > 0 and abs(r["porosity"] - 0.6) < 0.01
    raw = np.fromfile(d / "third.stl", dtype=np.uint8)  # the file's own triangles and volume (numpy, no porecad)
    n = int(raw[80:84].view("<u4")[0])
    tri = raw[84:].reshape(n, 50)[:, 12:48].copy().view("<f4").reshape(n, 3, 3).astype(np.float64)
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    assert n == r["triangles"] and volume == pytest.approx(r["volume"], rel=1e-6)
    assert r["triangles"] == pytest.approx(est["triangles"], rel=0.5)  # the estimate within 1.5x


def test_one_that_cannot_stream_is_refused_with_its_estimate(job):
    d, recipe, est = job
    with pytest.raises(ResourceError, match="GiB of memory"):
        run_recipe({**recipe, "output": {"mesh": str(d / "third.obj")}}, threads=2,
                   memory_limit=int(est["peak_bytes"] / 3))
    assert not (d / "third.obj").exists()
