"""The first run after an install: numba compiles porecad's kernels once (then they load from its cache).

Two things make that first run shorter and less puzzling (issue 22):

* :func:`install_notice` prints one line on stderr when the first kernel
  starts compiling, so a user knows why the first run is slower;
* :func:`precompile_in_background` starts a helper process (forked on Linux,
  so it skips importing porecad and numba again) that compiles, in the order
  a build with a report needs them, the kernels of the stages after the
  fields and marching cubes: the caps of marching cubes, the validation, the
  preview's rasteriser, then the pore analysis (winding numbers, exact
  distances, local thickness). Compiling is single-threaded and holds
  numba's lock, so on two cores the two processes compile side by side. The
  helper only fills numba's cache (``cache=True``); the main process loads
  from there, and when the cache already holds the kernels no helper starts.
  The kernels take one array type each, so the helper's tiny inputs (or
  explicit signatures) compile the very specialisations a real job calls.

Neither process compiles a kernel the other is compiling (:func:`_share`):
it waits for the other's cache entry instead. Without that, whichever kernel
one reached while the other was on it was compiled twice (1-1.3 s each);
waiting for the whole helper instead cost 0.9-1.3 s. The main process
compiles the fields and marching cubes' other kernels itself: split so, the
helper's list ends about when the pore analysis needs it. ``bench/first_run.py``
measures the result.
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import subprocess
import sys
import threading

_noticed = False
_helper = None


#: seconds between the notice's "still compiling" lines while kernels keep compiling
STILL_COMPILING_S = 15.0


def install_notice(stream=None):
    """Print one line on ``stream`` (default stderr) when numba first compiles a porecad kernel.

    While porecad's kernels keep compiling (``porecad properties`` compiles its solvers for
    about a minute on a first run), a line every :data:`STILL_COMPILING_S` seconds says how long
    it has been, so a first run is never silent for long. Returns the listener.
    """
    import time

    from numba.core import event

    state = {"start": None, "last": None}

    def say(text):
        print(f"porecad: {text}", file=stream or sys.stderr, flush=True)

    class _Notice(event.Listener):
        def on_start(self, ev):
            global _noticed
            name = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", "")
            if not name.startswith("porecad"):
                return
            now = time.monotonic()
            if not _noticed:
                _noticed = True
                state["start"] = state["last"] = now
                say("compiling numerical kernels (first run after an install; cached afterwards) ...")
            elif state["start"] is not None and now - state["last"] >= STILL_COMPILING_S:
                state["last"] = now
                took = now - state["start"]
                say(f"still compiling numerical kernels ({took:.0f} s so far; cached for later runs) ...")

        def on_end(self, ev):
            pass

    listener = _Notice()
    event.register("numba:compile", listener)
    return listener     # for numba.core.event.unregister


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
    from .analysis._render_kernel import rasterise
    from .analysis._thickness_kernel import paint_balls   # the helper's last kernel: cached once it has run
    if _cached(rasterise) and _cached(paint_balls):
        _preload()
        return None
    global _helper
    import tempfile
    share = tempfile.mkdtemp(prefix="porecad-compile-")
    atexit.register(shutil.rmtree, share, True)
    if sys.platform.startswith("linux") and threading.active_count() == 1:
        _helper = _forked(share)
    else:
        _helper = subprocess.Popen([sys.executable, "-c", "from porecad.first_run import _run_helper; "
                                    f"_run_helper({share!r}, {os.getpid()})"],
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _share(share, "main", "helper", lambda: _helper.poll() is None)
    return _helper


def _preload() -> None:
    """Load from numba's cache, on a thread, the kernels every build meets first (marching cubes, the
    validation) while the job reads its input and plans; the first stage to call each would otherwise load it
    itself, about 20-40 ms each with the second core idle (the P surface at 500³: ``polygonise_s`` 0.11-0.22 ->
    0.10-0.12 s, ``validate_s`` 0.12-0.21 -> 0.10-0.14 s, the whole process 1.6-2.3 -> 1.5-1.7 s). The thread
    is joined at exit, so that a job refused at once does not exit under it."""
    def load():
        from .mesh.polygonise import load_kernels
        load_kernels()
        _validation_kernels()

    thread = threading.Thread(target=load, name="porecad-preload", daemon=True)
    thread.start()
    atexit.register(thread.join, 5.0)


def _validation_kernels() -> None:
    """The validation's kernels, for the types a job's solid has (float64 vertices, the polygoniser's int32 faces)."""
    import numpy as np

    from .mesh.validate import check_solid, signed_volume
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int32)
    signed_volume(v, f)      # the job's validation: its volume first, then the topology
    check_solid(v, f, check_self_intersections=False)


class _Forked:
    """The forked helper: ``pid`` and ``poll()`` like a :class:`subprocess.Popen`."""

    def __init__(self, pid: int):
        self.pid = pid
        self.returncode = None
        atexit.register(self.poll)      # reap it if it is done (never waits for it)

    def poll(self):
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:
                self.returncode = 0
            else:
                if pid:
                    self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode


def _forked(share: str):
    """Fork the helper (Linux, before the job starts any thread): it starts compiling at once.

    A fresh interpreter would first spend about 0.6 s importing porecad and
    numba again. The child sends its output nowhere, leaves through
    ``os._exit`` (no exit handlers, no flushing of the parent's buffers) and
    never returns into the caller.
    """
    from numba.core.registry import cpu_target
    cpu_target.target_context      # numba's typing and target set-up, shared with the child (about 0.25 s)
    sys.stdout.flush()
    sys.stderr.flush()
    parent = os.getpid()
    pid = os.fork()
    if pid:
        return _Forked(pid)
    code = 1
    try:
        null = os.open(os.devnull, os.O_RDWR)
        for fd in (0, 1, 2):
            os.dup2(null, fd)
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        _run_helper(share, parent)
        code = 0
    finally:
        os._exit(code)


def _run_helper(share: str, parent: int) -> None:
    """The helper's work: :func:`_compile`, sharing the kernels with the main process ``parent``."""
    _share(share, "helper", "main", lambda: os.getppid() == parent)
    _compile()


#: longest wait (s) for the other process to finish compiling a kernel
SHARE_WAIT_S = 30.0


def _share(directory: str, mine: str, theirs: str, alive) -> None:
    """Never compile a porecad kernel that the other process is compiling: wait for its cache entry.

    While this process compiles a kernel it keeps a marker file
    ``<directory>/<module>.<name>.<mine>``; before numba looks a kernel up in
    its cache, a marker of ``theirs`` for it means the other process is
    compiling it: wait (while ``alive()``, at most :data:`SHARE_WAIT_S`) and
    load it then. Without this both processes compiled the kernel that one
    reached while the other was on it (1-1.3 s each for the marching cubes'
    caps, the validation and the exact distances on the demo). No deadlock:
    a process waits only from inside the compilation of a caller, and
    porecad's kernels do not call each other in a cycle.
    """
    import time

    from numba.core import caching, event

    def marker(py_func, who):
        module = getattr(py_func, "__module__", None) or ""
        if not module.startswith("porecad"):
            return None
        return os.path.join(directory, f"{module}.{getattr(py_func, '__qualname__', '?')}.{who}")

    class _Mark(event.Listener):
        def on_start(self, ev):
            path = marker(getattr(ev.data.get("dispatcher"), "py_func", None), mine)
            if path:
                try:
                    open(path, "w").close()
                except OSError:      # the folder is gone: the other process has finished
                    pass

        def on_end(self, ev):
            pass     # the marker goes once the kernel is in the cache (save_overload below)

    def unmark(py_func):
        path = marker(py_func, mine)
        if path:
            try:
                os.unlink(path)
            except OSError:
                pass

    load = getattr(caching.Cache, "load_overload", None)
    save = getattr(caching.Cache, "save_overload", None)
    if load is None or save is None:        # numba internals moved: no sharing
        return
    event.register("numba:compile", _Mark())

    def save_overload(self, sig, data):
        try:
            return save(self, sig, data)
        finally:
            unmark(getattr(self, "_py_func", None))

    caching.Cache.save_overload = save_overload

    def load_overload(self, sig, target_context):
        busy = marker(getattr(self, "_py_func", None), theirs)
        if busy:
            deadline = time.monotonic() + SHARE_WAIT_S
            while os.path.exists(busy) and time.monotonic() < deadline and alive():
                time.sleep(0.005)
        return load(self, sig, target_context)

    caching.Cache.load_overload = load_overload


def _compile() -> None:
    """Compile, in the order a build with a report needs them, the kernels of tiny inputs with the builds' types.

    Marching cubes' caps (the job compiles the rest of marching cubes
    meanwhile and then loads them), the validation, the preview's rasteriser
    and the pore analysis (winding numbers, exact distances, local thickness).
    """
    import numpy as np

    from .mesh._mc_kernel import compile_caps
    compile_caps()     # the caps of marching cubes: the job compiles the rest meanwhile (the cube cases too:
    # given to the helper, its list ended after the pore analysis needed it, 1 s later on the demo)
    _validation_kernels()
    box = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=np.float64)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    cube = np.array([t for a, b, c, e in quads for t in ((a, b, c), (a, c, e))], dtype=np.int32)
    plates = np.concatenate([box * [4, 4, 1], box * [4, 4, 1] + [0, 0, 2]])
    faces = np.concatenate([cube, cube + 8])
    from .analysis.render import render
    render(plates, faces, 8, 6, cut=(np.zeros(3), (0.0, -1.0, 0.0)))   # the report's preview (a worker thread)
    from .analysis.pores import pore_analysis
    pore_analysis(plates, faces, spacing=0.25)      # two plates: a slot between them
