"""The first run after an install: numba compiles porecad's kernels once (then they load from its cache).

Two things make that first run shorter and less puzzling (issue 22):

* :func:`install_notice` prints one line on stderr when the first kernel
  starts compiling, so a user knows why the first run is slower;
* :func:`precompile_in_background` compiles the kernels of the last stages
  of a build (mesh validation, STL writing, then the report's pore
  analysis and preview) in a second process while this one compiles the first stages
  (fields, marching cubes): compiling is single-threaded and holds numba's
  lock, so on two cores this halves the wait. The helper only fills numba's
  cache (``cache=True``); when the main process reaches those kernels it
  loads them from there, and when the cache already holds them no helper is
  started. The kernels take one array type each (faces int64 or the
  polygoniser's int32, float64 points), so the helper's tiny inputs compile
  the very specialisations a real job calls.

The main process never waits for the helper. A kernel it reaches before the
helper has cached it, it compiles itself (the same code, so the results do
not depend on who compiled it): at worst the helper's work was spent for
nothing on the other core. Waiting for the whole helper before the pore
analysis cost the demo 0.9-1.3 s on 2 cores (``bench/first_run.py``): the
helper compiles in the order the stages run, so the kernels the analysis
needs first are cached long before the helper's last one.
"""

from __future__ import annotations

import os
import subprocess
import sys

_noticed = False
_helper = None


def install_notice(stream=None) -> None:
    """Print one line on ``stream`` (default stderr) when numba first compiles a porecad kernel."""
    from numba.core import event

    class _Notice(event.Listener):
        def on_start(self, ev):
            global _noticed
            if _noticed:
                return
            name = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", "")
            if name.startswith("porecad"):
                _noticed = True
                print("porecad: compiling numerical kernels (first run after an install; cached afterwards) ...",
                      file=stream or sys.stderr, flush=True)

        def on_end(self, ev):
            pass

    event.register("numba:compile", _Notice())


def _cached(dispatcher) -> bool:
    """Whether numba's cache holds an entry for this kernel (any signature)."""
    try:
        return os.path.exists(dispatcher._cache._cache_file._index_path)
    except AttributeError:      # numba internals moved: assume not cached
        return False


def precompile_in_background():
    """Start the helper process unless the cache has its kernels; returns the process or None."""
    if os.environ.get("NUMBA_DISABLE_JIT") == "1":
        return None
    from .analysis._render_kernel import rasterise   # the helper's last kernel: cached once it has run
    from .analysis._thickness_kernel import paint_balls
    from .io.meshfiles import fill_stl_records
    if _cached(fill_stl_records) and _cached(paint_balls) and _cached(rasterise):
        return None
    global _helper
    _helper = subprocess.Popen([sys.executable, "-c", "from porecad.first_run import _compile; _compile()"],
                               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return _helper


def _compile() -> None:
    """Validation, an STL write and a pore analysis of tiny meshes with the builds' array types (fills the cache)."""
    import tempfile

    import numpy as np

    from .io import write_mesh
    from .mesh.validate import bounds, check_solid, signed_volume

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int32)
    check_solid(v, f, check_self_intersections=False)     # the polygoniser's int32 faces
    signed_volume(v, f)
    bounds(v)
    with tempfile.TemporaryDirectory() as d:
        write_mesh(os.path.join(d, "t.stl"), v, f, force=True)
    # the report's analysis: winding numbers, exact distances, local thickness (a plate with a slot)
    from .analysis.pores import pore_analysis
    box = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=np.float64)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    cube = np.array([t for a, b, c, e in quads for t in ((a, b, c), (a, c, e))], dtype=np.int32)
    plates = np.concatenate([box * [4, 4, 1], box * [4, 4, 1] + [0, 0, 2]])
    faces = np.concatenate([cube, cube + 8])
    pore_analysis(plates, faces, spacing=0.25)
    from .analysis.render import render
    render(plates, faces, 8, 6, cut=(np.zeros(3), (0.0, -1.0, 0.0)))
