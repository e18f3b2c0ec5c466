"""Background work of a session: previews (the newest design wins) and exports (progress, cancel).

:class:`Previews` runs one design at a time in a worker thread, in stages
that each replace the last on the page: ``coarse`` (the whole part at
:data:`~porecad.studio.preview.COARSE_SAMPLES`), ``window`` (lattice designs:
two cells at the export's sampling, with the pore/strut analysis and the
thickness sections) or ``analysis`` (the others), and ``refined`` (the whole
part at :data:`~porecad.studio.preview.REFINED_SAMPLES`). A newer design stops
the running one at its next progress call.

:class:`Exports` runs ``porecad.jobs.run_recipe`` — what ``porecad build``
runs — on the design's recipe in a fresh ``exports/N`` folder that also holds
a copy of each input, so that the folder (the recipe with its inputs) is
self-contained. The job runs in a child process (:class:`Child`): Cancel
kills it at once, whatever it is computing, and removes the folder (its
temporary files included): no file is left behind.
"""

from __future__ import annotations

import copy
import shutil
import threading
import time
import traceback
from pathlib import Path

from ..errors import PorecadError, one_line
from . import preview as pv


def message(exc: BaseException) -> dict:
    """The page's error for an exception: one line, and the form field or recipe key it is about."""
    from ..errors import RecipeError
    from .design import FieldError
    if isinstance(exc, FieldError):
        return {"error": one_line(str(exc)), "field": exc.field}
    if isinstance(exc, RecipeError):
        return {"error": one_line(str(exc)), "key": exc.key}
    if isinstance(exc, PorecadError):
        return {"error": one_line(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)}
    if isinstance(exc, MemoryError):
        return {"error": "out of memory: lower the resolution"}
    traceback.print_exception(type(exc), exc, exc.__traceback__)
    return {"error": f"internal error ({type(exc).__name__}: {one_line(exc)[:200]})"}


class Child:
    """``fn(*args, progress=...)`` in a child process that :meth:`kill` stops at once (a job in a compiled kernel
    does not notice a flag for minutes; a process is killed in milliseconds).

    The child is a fresh interpreter (never a fork of the studio, whose threads may hold locks a fork would
    copy held; never a re-run of the program that started the studio), in its own session (a terminal's
    Ctrl-C goes to the studio, which stops it) and with its temporary files in ``folder`` (removed with it by
    the caller). The job's name (one of :data:`CHILD_JOBS`) and ``args`` go to it as JSON (nothing the child
    reads can run code); progress and the result come back through a pipe:
    :meth:`wait` calls ``on_progress(stage, done, total)`` and returns the result, raises
    :class:`~porecad.studio.preview.Superseded` once killed, or :class:`ChildFailed` with the page's error.
    """

    def __init__(self, job: str, args: tuple, folder):
        import json
        import os
        import subprocess
        import sys
        from multiprocessing.connection import Connection
        if job not in CHILD_JOBS:
            raise ValueError(f"unknown child job {job!r}")
        r, w = os.pipe()
        env = dict(os.environ, TMPDIR=str(folder), PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", "from porecad.studio.tasks import child_main; child_main()", str(w)],
                stdin=subprocess.PIPE, pass_fds=(w,), env=env, cwd=str(folder), start_new_session=True)
        finally:
            os.close(w)
        self.conn = Connection(r, writable=False)
        self.killed = False
        try:
            self.proc.stdin.write(json.dumps([CHILD_JOBS[job], list(args), str(folder)]).encode())
            self.proc.stdin.close()
        except OSError:  # it died at once: wait() says so
            pass

    def kill(self) -> None:
        """Stop the child now (SIGKILL); :meth:`wait` then raises Superseded."""
        self.killed = True
        if self.proc.poll() is None:
            self.proc.kill()

    def wait(self, on_progress=None):
        from multiprocessing.connection import wait
        try:
            while not self.killed:
                if not wait([self.conn], timeout=0.5):
                    continue
                try:
                    kind, *data = self.conn.recv()
                except (EOFError, OSError):  # the child is gone without a word
                    kind, data = "gone", ()
                if kind == "progress":
                    if on_progress is not None:
                        on_progress(*data)
                elif kind == "done":
                    return data[0]
                elif kind == "failed":
                    raise ChildFailed(data[0])
                elif not self.killed:
                    code = self.proc.wait()
                    why = f"killed by signal {-code}" if code < 0 else f"exit {code}"
                    raise ChildFailed({"error": f"the job stopped unexpectedly ({why}; out of memory?)"})
            raise pv.Superseded()
        finally:  # whatever ended the wait, the child ends too (it has sent all it had to)
            if self.proc.poll() is None:
                self.proc.kill()
            self.proc.wait()
            self.conn.close()


class ChildFailed(Exception):
    """A :class:`Child`'s job failed: ``args[0]`` is the page's error (:func:`message`)."""


#: what a :class:`Child` may run: name -> ``module:function`` (the studio sends the child one of these)
CHILD_JOBS = {"export": "porecad.studio.tasks:export_job", "slice": "porecad.studio.print_panel:slice_job"}


def child_main():
    """The child of :class:`Child` (``python -c ... FD``): reads ``["module:function", args, folder]`` as JSON on
    stdin (from the studio: a job of :data:`CHILD_JOBS`), runs it with its temporary files in ``folder``, sends
    progress (at most 20 a second) and the result or the error."""
    import importlib
    import json
    import os
    import signal
    import sys
    import tempfile
    from multiprocessing.connection import Connection
    conn = Connection(int(sys.argv[1]), readable=False)
    try:  # Linux: killed with the studio, whatever ends it
        import ctypes
        ctypes.CDLL(None).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    job, args, folder = json.load(sys.stdin.buffer)
    module, name = job.split(":")
    fn = getattr(importlib.import_module(module), name)
    os.environ["TMPDIR"] = tempfile.tempdir = folder
    lock = threading.Lock()
    last = [0.0]

    def progress(stage, done, total):
        now = time.monotonic()
        if now - last[0] >= 0.05 or done >= total:
            last[0] = now
            with lock:
                conn.send(("progress", str(stage), int(done), int(total)))
    try:
        result = fn(*args, progress=progress)
        with lock:
            conn.send(("done", result))
    except BaseException as exc:  # noqa: BLE001 - sent to the page, one line
        with lock:
            conn.send(("failed", message(exc)))
    finally:
        conn.close()


def summary(report: dict) -> dict:
    """The report keys the page shows."""
    keys = ("job", "triangles", "vertices", "closed", "manifold", "oriented", "volume", "surface_area",
            "domain_volume", "porosity", "porosity_voxel", "porosity_calibrated", "threshold", "target_porosity",
            "in_valid_range", "porosity_min", "porosity_max", "type", "structure", "warnings", "warning_details", "body_volume",
            "self_intersections", "timings", "mesh_file", "recipe_file")
    return {k: report.get(k) for k in keys if k in report}


class Previews:
    """The preview worker of a session."""

    def __init__(self, session, threads=None):
        self.session = session
        self.threads = threads
        self.gen = 0
        self.states: dict[int, dict] = {}
        self.blobs: dict[tuple, bytes] = {}
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._pending = None
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name="porecad-studio-preview", daemon=True)
        self._thread.start()

    def submit(self, design: dict, recipe: dict) -> int:
        """Queue a design (its checked recipe); the running one stops. Returns its preview number."""
        with self._lock:
            self.gen += 1
            gen = self.gen
            self.states[gen] = {"gen": gen, "state": "queued", "stage": None, "levels": {}, "messages": [],
                                "t0": time.perf_counter()}
            for old in [g for g in self.states if g < gen - 4]:  # keep a few
                self.states.pop(old, None)
            self.blobs = {k: v for k, v in self.blobs.items() if k[0] >= gen - 4}
            self._pending = (gen, design, recipe)
            self._wake.notify()
        return gen

    def state(self, gen: int) -> dict | None:
        with self._lock:
            s = self.states.get(gen)
            return copy.deepcopy({k: v for k, v in s.items() if k != "t0"}) if s else None

    def blob(self, gen: int, name: str) -> bytes | None:
        with self._lock:
            return self.blobs.get((gen, name))

    def close(self):
        with self._lock:
            self._closed = True
            self.gen += 1
            self._wake.notify()

    # ------------------------------------------------------------------ worker
    def _loop(self):
        while True:
            with self._lock:
                while self._pending is None and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                gen, design, recipe = self._pending
                self._pending = None
            try:
                self._run(gen, design, recipe)
                self._set(gen, state="done", stage=None)
            except pv.Superseded:
                self._set(gen, state="superseded", stage=None)
            except BaseException as exc:  # noqa: BLE001 - the page shows it; the worker goes on
                self._set(gen, state="failed", stage=None, **message(exc))

    def _set(self, gen, **kw):
        with self._lock:
            s = self.states.get(gen)
            if s is not None:
                s.update(kw)

    def _level(self, gen, name, vertices, faces, report: dict, extra=None):
        dv, df, cell = pv.display_mesh(vertices, faces)
        blob = pv.pack_mesh(dv, df)
        with self._lock:
            s = self.states.get(gen)
            if s is None:
                return
            self.blobs[(gen, name)] = blob
            s["levels"][name] = {"report": summary(report), "display_faces": int(len(df)),
                                 "lod_cell": cell, "seconds": time.perf_counter() - s["t0"], **(extra or {})}

    def _run(self, gen, design, recipe):
        cancelled = lambda: self.gen != gen or self._closed  # noqa: E731
        progress = pv.checked_progress(cancelled, lambda stage, d, t: self._set(gen, progress=[stage, d, t]))
        job = recipe["job"]
        bounds = None
        if job == "infill":
            bounds = self.session.body_bounds(design)
        self._set(gen, state="running", stage="coarse")
        r0, info0 = pv.coarse_recipe(recipe, pv.COARSE_SAMPLES, bounds)
        v, f, report = pv.run_job(r0, progress, self.threads)
        self._level(gen, "coarse", v, f, report, info0)
        if cancelled():
            raise pv.Superseded()
        min_feature = design.get("min_feature")
        try:
            min_feature = float(min_feature) if min_feature not in (None, "") else None
        except (TypeError, ValueError):
            min_feature = None
        if job in ("tpms", "infill"):
            self._set(gen, stage="window")
            wv, wf, winfo = pv.window_mesh(recipe, progress, self.threads)
            self._level(gen, "window", wv, wf, {"porosity": winfo["porosity"], "triangles": int(len(wf))},
                        {"window": winfo})
            target = (wv, wf)
        else:
            target = (v, f)
        if cancelled():
            raise pv.Superseded()
        self._set(gen, stage="analysis")
        stats, meta, strut, pore = pv.thickness_analysis(*target, min_feature=min_feature)
        meta["of"] = "window" if job in ("tpms", "infill") else "coarse"
        with self._lock:
            if gen in self.states:
                self.blobs[(gen, "sections")] = pv.pack_blob(meta, strut, pore)
                self.states[gen]["analysis"] = {k: v for k, v in stats.items() if not isinstance(v, dict)
                                                or k in ("percolation", "thin_struts")}
                self.states[gen]["analysis"]["of"] = meta["of"]
        if cancelled():
            raise pv.Superseded()
        r2, info2 = pv.coarse_recipe(recipe, pv.REFINED_SAMPLES, bounds)
        if r2 != r0:
            self._set(gen, stage="refined")
            v, f, report = pv.run_job(r2, progress, self.threads)
            self._level(gen, "refined", v, f, report, info2)


class Exports:
    """The export worker of a session: one export at a time."""

    def __init__(self, session, threads=None):
        self.session = session
        self.threads = threads
        self.jobs: dict[int, dict] = {}
        self._lock = threading.Lock()
        self._next = 0

    def running(self) -> bool:
        with self._lock:
            return any(j["state"] == "running" for j in self.jobs.values())

    def start(self, recipe: dict, fmt: str = "stl", html: bool = True) -> int:
        """Start exporting a checked recipe (mesh in ``fmt``, the recipe, the report); its number."""
        from ..errors import InputError
        from ..io.mesh_formats import mesh_formats
        if fmt not in mesh_formats("write"):
            raise InputError(f"export format is one of {', '.join(mesh_formats('write'))}, not {str(fmt)[:20]!r}")
        if self.running():
            raise InputError("an export is running: wait for it or cancel it")
        folder = self.session.new_export_dir()
        recipe = copy.deepcopy(recipe)
        stem = {"tpms": "lattice", "infill": "infill", "tbss": "tbss", "hex": "hex", "tis": "tis",
                "vessel": "vessel"}.get(recipe["job"], "scaffold")
        try:  # the folder, a copy of each input and the job's process: all, or nothing left
            for table, key in (("domain", "path"), ("body", "path"), ("input", "path")):
                t = recipe.get(table)
                if isinstance(t, dict) and t.get(key):
                    src = self.session.inside(t[key])
                    dst = folder / src.name
                    try:
                        dst.hardlink_to(src)
                    except OSError:
                        shutil.copyfile(src, dst)
                    t[key] = src.name
            recipe["output"] = {"mesh": f"{stem}.{fmt}", "recipe": f"{stem}.toml",
                                "report": "report" if html else f"{stem}.report.json"}
            child = Child("export", (recipe, str(folder), self.threads), folder)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        with self._lock:
            self._next += 1
            n = self._next
            self.jobs[n] = {"id": n, "state": "running", "stage": "start", "done": 0, "total": 1,
                            "folder": folder, "cancel": False, "t0": time.perf_counter(), "stem": stem,
                            "child": child}
        threading.Thread(target=self._run, args=(n, folder), name=f"porecad-studio-export-{n}",
                         daemon=True).start()
        return n

    def cancel(self, n: int) -> bool:
        """Stop export ``n`` now (its process is killed; its folder removed)."""
        with self._lock:
            j = self.jobs.get(n)
            if j is None or j["state"] != "running":
                return False
            j["cancel"] = True
            j["child"].kill()
            return True

    def state(self, n: int) -> dict | None:
        with self._lock:
            j = self.jobs.get(n)
            if j is None:
                return None
            out = {k: v for k, v in j.items() if k not in ("folder", "cancel", "t0", "report", "child")}
            out["cancelling"] = j["cancel"] and j["state"] == "running"
            return out

    def folder(self, n: int) -> Path | None:
        with self._lock:
            j = self.jobs.get(n)
            return j["folder"] if j and j["state"] == "done" else None

    def _run(self, n, folder: Path):
        def progress(stage, done, total):
            with self._lock:
                self.jobs[n].update(stage=str(stage), done=int(done), total=max(int(total), 1))
        try:
            report = self.jobs[n]["child"].wait(progress)
            files = sorted(p.name for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))
            report_files = sorted(p.name for p in (folder / "report").iterdir()) if (folder / "report").is_dir() \
                else []
            with self._lock:
                if self.jobs[n]["cancel"]:
                    raise pv.Superseded()
                self.jobs[n].update(state="done", stage=None, files=files, report_files=report_files,
                                    summary=summary(report), seconds=time.perf_counter() - self.jobs[n]["t0"])
        except pv.Superseded:
            shutil.rmtree(folder, ignore_errors=True)
            with self._lock:
                self.jobs[n].update(state="cancelled", stage=None)
        except BaseException as exc:  # noqa: BLE001 - shown in the page
            shutil.rmtree(folder, ignore_errors=True)
            with self._lock:
                self.jobs[n].update(state="failed", stage=None,
                                    **(exc.args[0] if isinstance(exc, ChildFailed) else message(exc)))


def export_job(recipe: dict, folder: str, threads, progress=None) -> dict:
    """What an export's child runs: ``porecad build`` of the recipe in its folder (outputs confined there)."""
    from ..jobs import run_recipe
    return run_recipe(recipe, progress=progress, threads=threads, base=folder, confine=folder)
