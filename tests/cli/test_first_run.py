"""The first run after an install (issue 22, item 4): serial kernels on threads, and the background compile."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import porecad.kernel_threads as kt


@pytest.fixture
def threads(monkeypatch):
    def use(n):
        monkeypatch.setattr(kt, "thread_count", lambda: n)
    return use


def _sphere():
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    return np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)


def test_threaded_kernels_do_not_depend_on_the_thread_count(threads):
    """Nearest points, ray crossings and topology: the same arrays on 1 and 3 threads."""
    from porecad.analysis.surface_index import SurfaceIndex
    from porecad.bodies.mesh import MeshBody
    from porecad.mesh.topology import edge_topology

    v, f = _sphere()
    rng = np.random.default_rng(3)
    p = rng.uniform(-1.5, 1.5, (5000, 3))
    grid = np.linspace(-1.2, 1.2, 31)
    out = []
    for n in (1, 3):
        threads(n)
        d, c, t = SurfaceIndex(v, f, cell=0.2).nearest(p, 2.0, with_triangles=True)
        inside = MeshBody(v, f, band=0.1).inside_grid(grid, grid, grid)
        out.append((d, c, t, inside, edge_topology(f)))
    a, b = out
    for x, y in zip(a[:4], b[:4]):
        assert np.array_equal(x, y)
    assert a[4] == b[4]
    # and right: distances to a unit sphere (a fine polyhedron) and its inside
    r = np.linalg.norm(p, axis=1)
    assert np.all(np.abs(a[0] - np.abs(r - 1.0)) < 0.02)
    z, y, x = np.meshgrid(grid, grid, grid, indexing="ij")
    ball = x * x + y * y + z * z
    assert np.array_equal(a[3][np.abs(ball - 1) > 0.05], (ball < 1)[np.abs(ball - 1) > 0.05])
    assert a[4]["closed"] and a[4]["nonmanifold_vertices"] == 0 and a[4]["euler"] == 2


def test_a_warm_run_loads_its_first_kernels_on_a_thread_while_it_plans():
    """With the kernels cached, the first ones a build meets (marching cubes, the validation) are loaded on a
    thread, not by the stages that call them; the thread is joined at exit."""
    code = ("import threading\n"
            "from porecad.mesh._mc_kernel import _mesh_slab\n"
            "from porecad.mesh.topology import _star_chunks\n"
            "from porecad.mesh.validate import _block_volume_area\n"
            "ks = (_mesh_slab, _star_chunks, _block_volume_area)\n"
            "before = [len(k.signatures) for k in ks]\n"
            "from porecad import first_run\n"
            "first_run._preload()\n"
            "t = [t for t in threading.enumerate() if t.name == 'porecad-preload']\n"
            "t[0].join(600)\n"
            "print(before, [len(k.signatures) for k in ks], len(t))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=900)
    assert out.stdout.split("\n")[-2] == "[0, 0, 0] [1, 1, 1] 1"


def test_background_compile_fills_the_cache(tmp_path):
    """The helper process leaves the validation and analysis kernels in an empty numba cache."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    check = ("from porecad.first_run import _cached\n"
             "from porecad.analysis import _nearest_kernel as n, _thickness_kernel as t\n"
             "from porecad.mesh.box_bins import bin_boxes\n"
             "from porecad.mesh.topology import _star_chunks\n"
             "from porecad.mesh._mc_kernel import _emit_caps\n"
             "from porecad.analysis._render_kernel import rasterise\n"
             "ks = [n.nearest, bin_boxes, t.propagate_closest, t.ridge_flags, t.medial_pairs, t.paint_balls,\n"
             "      t.prune_balls, _star_chunks, _emit_caps, rasterise]\n"
             "print(sum(_cached(k) for k in ks), len(ks))\n")
    before = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True, check=True)
    assert before.stdout.split()[0] == "0"
    subprocess.run([sys.executable, "-c", "from porecad.first_run import _compile; _compile()"], env=env,
                   check=True, capture_output=True, timeout=600)
    after = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True, check=True)
    done, total = after.stdout.split()
    assert done == total
    # the helper compiled the very specialisations a build uses: the demo's job (coarser) with its
    # report compiles only what the helper leaves to it (fields, the rest of marching cubes)
    build = ("import json, sys\n"
             "from numba.core import event\n"
             "seen = []\n"
             "class L(event.Listener):\n"
             "    def on_start(self, ev):\n"
             "        f = getattr(ev.data.get('dispatcher'), 'py_func', None)\n"
             "        if f is not None and f.__module__.startswith('porecad'):\n"
             "            seen.append(f.__qualname__)\n"
             "    def on_end(self, ev):\n"
             "        pass\n"
             "event.register('numba:compile', L())\n"
             "from porecad.jobs import run_recipe\n"
             "from porecad.jobs.tpms_job import demo_recipe\n"
             "import os; os.makedirs(sys.argv[1])\n"
             "r = demo_recipe(sys.argv[1])\n"
             "r['sampling']['voxel'] = 0.5\n"
             "run_recipe(r)\n"
             "print(json.dumps(seen))\n")
    out = subprocess.run([sys.executable, "-c", build, str(tmp_path / "demo")], env=env, capture_output=True,
                         text=True, check=True, timeout=600)
    compiled = set(json.loads(out.stdout.strip().splitlines()[-1]))
    helpers = {"nearest", "bin_boxes", "_column_counts", "_column_fill", "_winding_on_columns",
               "propagate_closest", "ridge_flags", "medial_pairs", "prune_balls", "paint_balls", "_star_chunks",
               "_vertex_face_csr", "_block_volume_area", "_emit_caps", "rasterise"}
    assert "_mesh_slab" in compiled          # the build's own share: it did compile
    assert not compiled & helpers, compiled & helpers
    assert (tmp_path / "demo" / "demo_report" / "report.html").exists()
