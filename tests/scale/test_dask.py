"""Scale-out (issue 11): chunks on dask, streamed STL/PLY, zarr fields, retries, clean failures.

One module-scoped 2-worker LocalCluster (processes) serves most tests; one
CLI test starts its own ``local:2`` cluster. Grids are small: each test takes
a few seconds at most.
"""

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import distributed  # porecad[dask] (in the test extra)

import cloudpickle  # noqa: E402  (comes with distributed)

from porecad.io import read_mesh, write_mesh  # noqa: E402
from porecad.mesh.polygonise import polygonise, slab_job  # noqa: E402
from porecad.pipeline import plan_tpms, run_recipe  # noqa: E402
from porecad.scale import ChunkError, open_scheduler, run_chunks  # noqa: E402
from porecad.scale.build import collect_mesh, stream_mesh  # noqa: E402
from porecad.mesh.stream_check import SlabWindow, StreamedSolidCheck  # noqa: E402

# the test fields below are shipped to the workers by value (they cannot import this file)
cloudpickle.register_pickle_by_value(sys.modules[__name__])

BASE = {"job": "tpms", "tpms": {"type": "G", "structure": "sheet", "porosity": 0.7, "cell_size": 1.0},
        "domain": {"kind": "box", "cells": [2, 2, 1]}, "sampling": {"resolution": 16}}
TPMS_ARGS = ["tpms", "G", "--structure", "sheet", "--porosity", 0.7, "--cells", 2, 2, 1, "--resolution", 16]
SMALL_CHUNK = 0.01  # MiB: a few planes per chunk on these grids, so there are many seams


def canonical(vertices, faces):
    """Vertices sorted lexicographically, faces remapped, rotated to start at their smallest index, sorted."""
    v = np.asarray(vertices, dtype=np.float64)
    order = np.lexsort(v.T[::-1])
    rank = np.empty(len(v), np.int64)
    rank[order] = np.arange(len(v))
    f = rank[np.asarray(faces)]
    shift = np.argmin(f, axis=1)
    rows = np.arange(len(f))[:, None]
    f = f[rows, (shift[:, None] + np.arange(3)) % 3]
    f = f[np.lexsort(f.T[::-1])]
    return v[order], f


def same_mesh(a, b):
    va, fa = canonical(*a)
    vb, fb = canonical(*b)
    return va.shape == vb.shape and fa.shape == fb.shape and np.array_equal(va, vb) and np.array_equal(fa, fb)


def leftovers(directory):
    """Hidden temporary or spill files left in ``directory``."""
    return sorted(p.name for p in Path(directory).iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=40)
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def plan():
    return plan_tpms(BASE)


class Faulty:
    """A field wrapper that fails while sampling the chunk starting at plane ``z_index``.

    ``mode``: ``"kill-once"`` ends the worker process (``os._exit``) the first
    time (marker file), ``"raise-once"`` raises the first time, ``"raise"``
    always raises.
    """

    def __init__(self, field, grid, z_index, marker, mode):
        self.field, self.mode, self.marker = field, mode, str(marker)
        self.z = grid.axis(2)[z_index]

    def sample_grid(self, xs, ys, zs):
        if len(zs) > 1 and zs[0] == self.z:
            if self.mode == "raise":
                raise RuntimeError("sampling failed")
            if not os.path.exists(self.marker):
                open(self.marker, "w").close()
                if self.mode == "kill-once":
                    os._exit(1)
                raise RuntimeError("transient failure")
        return self.field.sample_grid(xs, ys, zs)


def test_two_worker_cluster_gives_the_single_process_mesh(client, plan):
    grid = plan.grid
    ref = polygonise(plan.field.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    job = slab_job(plan.field.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    assert job.n_slabs > 4
    with open_scheduler(client) as sched:
        v, f, stats = collect_mesh(job, sched)
    assert stats["workers"] == 2 and stats["chunks"] == job.n_slabs and stats["retries"] == 0
    assert same_mesh((ref.vertices, ref.faces), (v, f))
    assert stats["inside_fraction"] == pytest.approx(ref.inside_fraction, abs=1e-12)
    from porecad.mesh.validate import check_solid
    chk = check_solid(v, f, check_self_intersections=False)
    assert chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"]


@pytest.mark.parametrize("ext", ["stl", "ply"])
def test_streamed_file_equals_the_in_memory_writer(client, plan, tmp_path, ext):
    grid = plan.grid
    ref = polygonise(plan.field.sample_grid, grid, caps=True)
    write_mesh(tmp_path / f"ref.{ext}", ref.vertices, ref.faces)
    job = slab_job(plan.field.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    with open_scheduler(client) as sched:
        chk, stats = stream_mesh(job, sched, tmp_path / f"s.{ext}", centre=(grid.box_min + grid.box_max) / 2)
    assert (tmp_path / f"s.{ext}").read_bytes() == (tmp_path / f"ref.{ext}").read_bytes()
    assert same_mesh(read_mesh(tmp_path / f"s.{ext}"), read_mesh(tmp_path / f"ref.{ext}"))
    assert chk["closed"] and chk["manifold"] and chk["triangles"] == len(ref.faces)
    from porecad.mesh.validate import signed_volume, stored_coordinates
    # the volume of the solid as stored (float32 coordinates), like an in-memory job's
    assert chk["volume"] == pytest.approx(signed_volume(stored_coordinates(ref.vertices), ref.faces), rel=1e-10)
    assert leftovers(tmp_path) == []


def test_streamed_check_finds_open_and_doubled_edges(plan):
    job = slab_job(plan.field.sample_grid, plan.grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))

    def checked(tamper):
        window, check = SlabWindow(), StreamedSolidCheck()

        def consume(slab):
            if slab.index == 2:
                tamper(slab)
            pos, faces = window.local(slab)
            check.add(slab, pos, faces)
            window.advance(slab)

        with open_scheduler("threads:2") as sched:
            run_chunks(job, sched, consume)
        return check.result()

    def nothing(slab):
        pass

    def drop_face(slab):
        slab.faces = slab.faces[1:]

    def double_face(slab):
        slab.faces = np.concatenate([slab.faces, slab.faces[:1]])

    assert checked(nothing)["closed"]
    r = checked(drop_face)
    assert not r["closed"] and r["open_edges"] == 3
    r = checked(double_face)
    assert not r["closed"] and not r["manifold"] and r["duplicate_edges"] == 3


def test_zarr_round_trip(client, plan, tmp_path):
    from porecad.io.zarr_field import read_field
    grid = plan.grid
    out = {"mesh": str(tmp_path / "g.stl")}
    r = run_recipe({**BASE, "output": out, "scale": {"scheduler": client.scheduler.address, "stream": True,
                                                      "zarr": str(tmp_path / "g.zarr"), "chunk_mb": SMALL_CHUNK}})
    values, g = read_field(tmp_path / "g.zarr")
    assert g.shape == grid.shape and np.allclose(g.origin, grid.origin) and np.allclose(g.spacing, grid.spacing)
    expect = plan.field.sample_grid(grid.axis(0), grid.axis(1), grid.axis(2))
    assert values.dtype == np.float32 and np.array_equal(values, expect)
    assert r["scale"]["zarr"] == str(tmp_path / "g.zarr") and r["scale"]["chunks"] > 4
    assert leftovers(tmp_path) == []


def test_killed_worker_is_replaced_and_the_job_completes(client, plan, tmp_path):
    grid = plan.grid
    marker = tmp_path / "killed"
    job = slab_job(plan.field.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    k = job.ranges[3][0]
    faulty = Faulty(plan.field, grid, k, marker, "kill-once")
    job = slab_job(faulty.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    with open_scheduler(client) as sched:
        chk, stats = stream_mesh(job, sched, tmp_path / "k.stl")
    assert marker.exists()  # a worker really died
    ref = polygonise(plan.field.sample_grid, grid, caps=True)
    write_mesh(tmp_path / "ref.stl", ref.vertices, ref.faces)
    assert chk["closed"] and same_mesh(read_mesh(tmp_path / "k.stl"), read_mesh(tmp_path / "ref.stl"))
    client.wait_for_workers(2, timeout=30)


def test_transient_failure_is_retried(plan, tmp_path):
    grid = plan.grid
    job = slab_job(plan.field.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    faulty = Faulty(plan.field, grid, job.ranges[2][0], tmp_path / "failed", "raise-once")
    job = slab_job(faulty.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    with open_scheduler("threads:2") as sched:
        v, f, stats = collect_mesh(job, sched, retries=1)
    assert stats["retries"] == 1
    ref = polygonise(plan.field.sample_grid, grid, caps=True)
    assert same_mesh((v, f), (ref.vertices, ref.faces))


@pytest.mark.parametrize("ext", ["stl", "ply"])
def test_chunk_failing_every_attempt_leaves_no_file(client, plan, tmp_path, ext):
    grid = plan.grid
    job = slab_job(plan.field.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    faulty = Faulty(plan.field, grid, job.ranges[4][0], tmp_path / "x", "raise")
    job = slab_job(faulty.sample_grid, grid, caps=True, chunk_bytes=int(SMALL_CHUNK * 2**20))
    with open_scheduler(client) as sched:
        with pytest.raises(ChunkError, match=r"chunk 5/\d+ .* failed after 3 attempt\(s\): RuntimeError"):
            stream_mesh(job, sched, tmp_path / f"f.{ext}", retries=2)
    assert not (tmp_path / f"f.{ext}").exists() and leftovers(tmp_path) == []


def test_interrupted_run_leaves_no_output(tmp_path):
    def stop(stage, done, total):
        if done == 3:
            raise KeyboardInterrupt

    out = {"mesh": str(tmp_path / "i.ply"), "report": str(tmp_path / "i.json")}
    with pytest.raises(KeyboardInterrupt):
        run_recipe({**BASE, "output": out, "scale": {"stream": True, "chunk_mb": SMALL_CHUNK,
                                                     "zarr": str(tmp_path / "i.zarr")}}, progress=stop)
    assert list(tmp_path.iterdir()) == []


def test_cli_local_cluster_streams_the_same_mesh(run_json, tmp_path):
    # a streamed mesh is written as it is meshed: its loose pieces stay (issue 37), so compare with --islands keep
    a = run_json(*TPMS_ARGS, "-o", tmp_path / "a.stl", "--islands", "keep")
    b = run_json(*TPMS_ARGS, "-o", tmp_path / "b.stl", "--scheduler", "local:2", "--stream",
                 "--chunk-mb", SMALL_CHUNK, "--report", tmp_path / "b.json")
    assert (tmp_path / "a.stl").read_bytes() == (tmp_path / "b.stl").read_bytes()
    assert b["closed"] and b["manifold"] and b["outward"] and b["triangles"] == a["triangles"]
    assert b["volume"] == pytest.approx(a["volume"], rel=1e-10)
    assert b["porosity_voxel"] == pytest.approx(a["porosity_voxel"], abs=1e-12)
    s = b["scale"]
    assert s["scheduler"] == "local:2" and s["workers"] == 2 and s["stream"] and s["chunks"] > 4
    assert s["samples"] == 31 * 31 * 16 and s["samples_per_s"] > 0 and s["peak_memory_bytes"] > 0
    assert json.loads((tmp_path / "b.json").read_text())["scale"]["chunks"] == s["chunks"]


def test_cli_stream_with_threads_ply_and_recipe(run_json, run_cli, tmp_path):
    r = run_json(*TPMS_ARGS, "-o", tmp_path / "t.ply", "--stream", "--chunk-mb", SMALL_CHUNK,
                 "--recipe", tmp_path / "t.toml")
    assert r["scale"]["scheduler"].startswith("threads") and r["closed"]
    ref = run_json(*TPMS_ARGS, "-o", tmp_path / "ref.ply", "--islands", "keep")  # as streamed: pieces kept
    assert (tmp_path / "t.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert ref["triangles"] == r["triangles"] and "scale" not in ref
    # the recipe keeps the scale table and rebuilds the same file
    code, out, err = run_cli("build", tmp_path / "t.toml", "--force", "--json")
    assert code == 0, err
    assert json.loads(out)["scale"]["stream"]
    assert (tmp_path / "t.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()


@pytest.mark.parametrize("args, match", [
    (["--scheduler", "local:0"], "number of workers"),
    (["--scheduler", "cluster"], "unknown scheduler"),
    (["--scheduler", "tcp://localhost"], "tcp://HOST:PORT"),
    (["--stream", "--smooth", "taubin"], "not possible with smoothing"),
    (["--retries", "-1"], "retries must be"),
    (["--chunk-mb", "0"], "chunk_mb must be positive"),
])
def test_cli_bad_scale_options(one_line_error, tmp_path, args, match):
    one_line_error(*TPMS_ARGS, "-o", tmp_path / "x.stl", *args, match=match)
    assert list(tmp_path.iterdir()) == []


def test_cli_stream_refuses_obj_and_existing_zarr(one_line_error, tmp_path):
    one_line_error(*TPMS_ARGS, "-o", tmp_path / "x.obj", "--stream", match="stream .stl or .ply")
    (tmp_path / "z.zarr").mkdir()
    one_line_error(*TPMS_ARGS, "-o", tmp_path / "x.stl", "--zarr", tmp_path / "z.zarr", match="already exists")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["z.zarr"]


def test_cli_unreachable_cluster_is_one_line(one_line_error, tmp_path):
    import socket
    with socket.socket() as s:  # a free port with nobody listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    one_line_error(*TPMS_ARGS, "-o", tmp_path / "x.stl", "--scheduler", f"tcp://127.0.0.1:{port}",
                   match="cannot connect to the dask scheduler")
    assert list(tmp_path.iterdir()) == []


def test_cli_without_dask_names_the_extra(one_line_error, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    one_line_error(*TPMS_ARGS, "-o", tmp_path / "x.stl", "--scheduler", "local:2",
                   match='pip install "porecad[dask]"')
    monkeypatch.setitem(sys.modules, "zarr", None)
    one_line_error(*TPMS_ARGS, "-o", tmp_path / "x.stl", "--zarr", tmp_path / "f.zarr",
                   match='pip install "porecad[dask]"')
    assert list(tmp_path.iterdir()) == []


class Unpicklable:
    """A field holding a lock: it cannot be shipped to worker processes."""

    def __init__(self, field):
        import threading
        self.field, self.lock = field, threading.Lock()

    def sample_grid(self, xs, ys, zs):
        return self.field.sample_grid(xs, ys, zs)


def test_unpicklable_field_is_refused_in_one_line(client, plan, tmp_path):
    from porecad.errors import InputError
    job = slab_job(Unpicklable(plan.field).sample_grid, plan.grid, caps=True)
    with open_scheduler(client) as sched:
        with pytest.raises(InputError, match="cannot be pickled") as err:
            stream_mesh(job, sched, tmp_path / "u.stl")
    assert "\n" not in str(err.value) and list(tmp_path.iterdir()) == []


def test_stream_is_chosen_when_the_mesh_would_not_fit(tmp_path):
    from porecad.resources import estimate
    plan = plan_tpms(BASE)
    est = estimate(plan.grid, plan.cell_size, plan.structure, plan.domain_volume,
                   plan.domain_area, 16 << 20, 2)
    out = {"mesh": str(tmp_path / "auto.stl")}
    r = run_recipe({**BASE, "output": out}, threads=2, memory_limit=int(1.9 * est["peak_bytes"]))
    assert r["scale"]["stream"] and r["closed"] and r["estimate"]["streamed"]
    small = run_recipe({**BASE, "islands": "keep", "output": {"mesh": str(tmp_path / "mem.stl")}}, threads=2,
                       memory_limit=int(4 * est["peak_bytes"]))
    assert "scale" not in small
    assert (tmp_path / "auto.stl").read_bytes() == (tmp_path / "mem.stl").read_bytes()


def _u_and_ring(xs, ys, zs):
    """A U (two bars joined only at the top, z > 8) beside a loose ball: two pieces, the U's arms apart in every
    slab but the last ones."""
    x, y, z = np.meshgrid(xs, ys, zs, indexing="ij")
    box = lambda lo, hi: np.max([lo[0] - x, x - hi[0], lo[1] - y, y - hi[1], lo[2] - z, z - hi[2]], axis=0)  # noqa
    u = np.minimum(np.minimum(box((1, 1, 1), (2, 2, 9)), box((5, 1, 1), (6, 2, 9))), box((1, 1, 8), (6, 2, 9)))
    ball = np.sqrt((x - 8.5) ** 2 + (y - 1.5) ** 2 + (z - 3) ** 2) - 1.0
    return np.minimum(u, ball).transpose(2, 1, 0).astype(np.float32)


def test_streamed_pieces_join_across_the_seams(tmp_path):
    """Issue 52: pieces are counted slab by slab (2 planes a slab here: every seam cuts the U's arms), joined
    where they meet late, and agree with the pieces of the whole mesh."""
    from porecad.mesh.grid import Grid
    from porecad.mesh.shells import shell_labels
    grid = Grid.from_box([0, 0, 0], [10, 3, 10], spacing=0.25)
    job = slab_job(lambda xs, ys, zs: _u_and_ring(xs, ys, zs), grid, caps=True, chunk_bytes=2 * 41 * 13 * 4)
    assert len(job.ranges) > 10
    with open_scheduler("threads") as sched:
        chk, _ = stream_mesh(job, sched, tmp_path / "u.stl")
    v, f = read_mesh(tmp_path / "u.stl")
    _, vol = shell_labels(v, f)
    pos = np.sort(vol[vol > 0])
    assert chk["pieces"] == len(pos) == 2
    assert chk["largest_volume"] == pytest.approx(pos[-1], rel=1e-6)
    assert chk["pieces_volume"] == pytest.approx(pos.sum(), rel=1e-6)


def test_a_streamed_infill_on_local_workers_is_the_same_file(run_json, tmp_path):
    """Issues 52 and 54: a body's streamed infill (islands dropped, porosity refined by a second pass) on a
    local:2 cluster writes the same bytes as in one process, and the same file as in memory."""
    import trimesh
    body = trimesh.creation.icosphere(3, radius=1.0)
    body.apply_scale([7.3, 6.1, 5.2])
    body.export(tmp_path / "ell.stl")
    args = ("infill", tmp_path / "ell.stl", "G", "--porosity", "0.6", "-L", "1.5", "--voxel", "0.15")
    one = run_json(*args, "-o", tmp_path / "one.stl", "--stream", "--chunk-mb", SMALL_CHUNK)
    two = run_json(*args, "-o", tmp_path / "two.stl", "--stream", "--chunk-mb", SMALL_CHUNK, "--scheduler", "local:2")
    mem = run_json(*args, "-o", tmp_path / "mem.stl", "--no-stream")
    assert two["scale"]["scheduler"] == "local:2" and two["scale"]["chunks"] > 4 and one["islands_dropped"] > 0
    assert (tmp_path / "one.stl").read_bytes() == (tmp_path / "two.stl").read_bytes()
    assert (tmp_path / "one.stl").read_bytes() == (tmp_path / "mem.stl").read_bytes()
    assert one["pieces"] == two["pieces"] == mem["pieces"] == 1
