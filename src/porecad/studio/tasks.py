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
self-contained. Cancelling stops the job at its next progress call and
removes the folder: no file is left behind.
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
        if fmt not in ("stl", "3mf", "ply"):
            raise InputError(f"export format is stl, 3mf or ply, not {str(fmt)[:20]!r}")
        if self.running():
            raise InputError("an export is running: wait for it or cancel it")
        folder = self.session.new_export_dir()
        recipe = copy.deepcopy(recipe)
        stem = {"tpms": "lattice", "infill": "infill", "tbss": "tbss", "hex": "hex", "tis": "tis",
                "vessel": "vessel"}.get(recipe["job"], "scaffold")
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
        with self._lock:
            self._next += 1
            n = self._next
            self.jobs[n] = {"id": n, "state": "running", "stage": "start", "done": 0, "total": 1,
                            "folder": folder, "cancel": False, "t0": time.perf_counter(), "stem": stem}
        threading.Thread(target=self._run, args=(n, recipe, folder), name=f"porecad-studio-export-{n}",
                         daemon=True).start()
        return n

    def cancel(self, n: int) -> bool:
        with self._lock:
            j = self.jobs.get(n)
            if j is None or j["state"] != "running":
                return False
            j["cancel"] = True
            return True

    def state(self, n: int) -> dict | None:
        with self._lock:
            j = self.jobs.get(n)
            if j is None:
                return None
            out = {k: v for k, v in j.items() if k not in ("folder", "cancel", "t0", "report")}
            out["cancelling"] = j["cancel"] and j["state"] == "running"
            return out

    def folder(self, n: int) -> Path | None:
        with self._lock:
            j = self.jobs.get(n)
            return j["folder"] if j and j["state"] == "done" else None

    def _progress(self, n):
        def cb(stage, done, total):
            with self._lock:
                j = self.jobs[n]
                j.update(stage=str(stage), done=int(done), total=max(int(total), 1))
        return pv.checked_progress(lambda: self.jobs[n]["cancel"], cb)

    def _run(self, n, recipe, folder: Path):
        from ..jobs import run_recipe
        try:
            report = run_recipe(recipe, progress=self._progress(n), threads=self.threads, base=folder,
                                confine=folder)
            if self.jobs[n]["cancel"]:
                raise pv.Superseded()
            files = sorted(p.name for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))
            report_files = sorted(p.name for p in (folder / "report").iterdir()) if (folder / "report").is_dir() \
                else []
            with self._lock:
                self.jobs[n].update(state="done", stage=None, files=files, report_files=report_files,
                                    summary=summary(report), seconds=time.perf_counter() - self.jobs[n]["t0"])
        except pv.Superseded:
            shutil.rmtree(folder, ignore_errors=True)
            with self._lock:
                self.jobs[n].update(state="cancelled", stage=None)
        except BaseException as exc:  # noqa: BLE001 - shown in the page
            shutil.rmtree(folder, ignore_errors=True)
            with self._lock:
                self.jobs[n].update(state="failed", stage=None, **message(exc))
