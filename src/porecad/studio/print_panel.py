"""The studio's Print panel: a printer profile, the design sliced in the background, its layers and findings.

The slicing is :func:`porecad.api.slice` — what ``porecad slice`` runs — on
the design's checked recipe, writing the PNG-layer ZIP into the session's
``prints/`` folder: the file the page downloads is the file that was sliced,
and the preview is read back from it one layer at a time (memory: one layer,
shrunk by a whole factor to at most :data:`PREVIEW_PIXELS` for the page).

A printer profile comes from the page as TOML text and is read by the
printing package's own reader (:func:`porecad.printing.profile.printer_from_toml`:
at most 64 KiB, unknown keys and out-of-range values refused with one line),
like a profile file given to ``porecad slice --printer``.

One slice at a time, each in its own ``prints/N/`` folder and its own child
process (:class:`porecad.studio.tasks.Child`): Cancel or a new Slice kills
the running one at once, whatever it is computing, and removes its folder
(temporary files included): nothing is left, and a slice that is no longer
the newest keeps no file. Slices too large for the machine are refused before
any work, with the estimate (:func:`porecad.printing.slicing.slice_estimate`,
as ``porecad slice`` does).
"""

from __future__ import annotations

import io
import math
import shutil
import threading
import time
import zipfile

from ..errors import InputError
from ..printing.profile import Printer, printer_from_toml, printer_toml
from . import preview as pv
from .tasks import Child, ChildFailed, message

#: the most pixels of a layer image sent to the page (larger layers are averaged down by a whole factor)
PREVIEW_PIXELS = 1 << 20
#: the most marks of one finding drawn on the layers
MAX_MARKS = 64


def orient_of(value):
    """The ``orient`` of :func:`porecad.api.slice` from the page's choice: None, ``"auto"`` or ``[x, y, z]``."""
    if value in (None, "", "none"):
        return None
    if value == "auto":
        return "auto"
    if isinstance(value, str):
        value = value.split(",")
    try:
        d = [float(x) for x in value] if isinstance(value, list) and len(value) == 3 else None
    except (TypeError, ValueError):
        d = None
    if d is None or not all(math.isfinite(x) for x in d) or not any(d):
        raise InputError(f"`orient` must be none, auto or a direction x,y,z, got {str(value)[:40]!r}")
    return d


def marks(report: dict) -> dict:
    """Where each finding is on the layers: ``{code: [{"layer": k, "u": x, "v": y}]}``, u and v from 0 to 1.

    ``u`` runs along the image's width, ``v`` down its height (row 0 is the largest y, as in the PNGs).
    """
    m = report["manifest"]
    x0, y0, z0 = m["origin"]
    w, h = m["image_width"] * m["pixel_size"], m["image_height"] * m.get("pixel_y", m["pixel_size"])  # x, y pitch
    n = m["layer_count"]
    out = {}
    for d in report.get("warning_details", []):
        v = d.get("values") or {}
        at = v.get("at") or []
        zs = v.get("z") or [p[2] if len(p) > 2 else None for p in at]
        pts = []
        for p, z in list(zip(at, zs))[:MAX_MARKS]:
            if z is None:
                continue
            k = min(n - 1, max(0, math.floor((z - z0) / m["layer_height"] + 1e-6)))
            pts.append({"layer": k, "u": round((p[0] - x0) / w, 5), "v": round(1 - (p[1] - y0) / h, 5)})
        if pts:
            out[d["code"]] = pts
    return out


def summary(report: dict) -> dict:
    """The report keys the panel shows."""
    keys = ("route", "layers", "image", "pixel", "layer", "height", "print_time_s", "rotation", "seconds",
            "warning_details")
    out = {k: report[k] for k in keys if k in report}
    o = report.get("orientation")
    if o:
        out["orientation"] = {"chosen": o["chosen"], "ranking": o.get("ranking", [])[:5]}
    if "overhangs" in report:
        out["unsupported_area"] = report["overhangs"]["unsupported_area"]
    out["mid_air_starts"] = len(report.get("mid_air_starts", []))
    out["first_layer_z"] = report["manifest"]["first_layer_z"]
    out["marks"] = marks(report)
    return out


def layer_png(path, k: int) -> tuple[bytes, int]:
    """Layer ``k`` of a slice ZIP as a PNG of at most :data:`PREVIEW_PIXELS` pixels, and the factor it was shrunk by."""
    from PIL import Image
    with zipfile.ZipFile(path) as z:
        try:
            raw = z.read(f"layers/{int(k):05d}.png")
        except KeyError:
            raise InputError(f"no layer {k} in these slices") from None
    img = Image.open(io.BytesIO(raw))
    factor = max(1, math.ceil(math.sqrt(img.width * img.height / PREVIEW_PIXELS)))
    if factor == 1:
        return raw, 1
    out = io.BytesIO()
    img.reduce(factor).save(out, format="PNG")  # box average: the grey stays the covered fraction
    return out.getvalue(), factor


class Prints:
    """The Print panel's worker of a session: the printer, the newest slice, its ZIP and report."""

    def __init__(self, session):
        self.session = session
        self.printer = Printer()
        self.folder = session.work / "prints"
        self.folder.mkdir(exist_ok=True)
        self.job: dict | None = None
        self._n = 0
        self._lock = threading.Lock()

    def profile(self) -> dict:
        """The session's printer: its keys, its TOML text and the build directions the page offers."""
        from ..printing.part import directions
        return {"printer": self.printer.as_dict(), "text": printer_toml(self.printer),
                "directions": [[round(float(x), 6) for x in d] for d in directions()]}

    def set_profile(self, text) -> dict:
        """Read a profile from TOML text (untrusted: checked like a ``--printer`` file); it is the session's now."""
        if not isinstance(text, str):
            raise InputError("send {\"text\": \"...toml...\"}")
        self.printer = printer_from_toml(text, "the printer profile")
        return self.profile()

    def start(self, recipe: dict, orient=None, pixel=None, layer=None) -> int:
        """Slice a checked recipe in the background (the running slice is cancelled); its number."""
        from ..printing.raster import check_size
        orient = orient_of(orient)
        pixel, layer = (None if v in (None, "") else check_size(name, v)
                        for name, v in (("the pixel", pixel), ("the layer height", layer)))
        with self._lock:
            if self.job is not None and self.job["state"] == "running":
                self.job["cancel"] = True
                self.job["child"].kill()
            self._n += 1
            n = self._n
            old = self.job
            folder = self.folder / str(n)
            folder.mkdir()
            path = folder / f"{n}.zip"
            args = (recipe, str(path), self.printer.as_dict(), orient, pixel, layer)
            try:
                child = Child("slice", args, folder)
            except BaseException:
                shutil.rmtree(folder, ignore_errors=True)
                raise
            self.job = job = {"id": n, "state": "running", "stage": "planning", "done": 0, "total": 1,
                              "cancel": False, "path": path, "t0": time.perf_counter(),
                              "stem": str(recipe.get("job", "design")), "child": child}
        if old is not None and old["state"] != "running":
            shutil.rmtree(old["path"].parent, ignore_errors=True)
        threading.Thread(target=self._run, args=(job,), name=f"porecad-studio-slice-{n}", daemon=True).start()
        return n

    def cancel(self) -> bool:
        """Stop the running slice now (its process is killed; its folder removed)."""
        with self._lock:
            if self.job is None or self.job["state"] != "running":
                return False
            self.job["cancel"] = True
            self.job["child"].kill()
            return True

    def state(self) -> dict:
        with self._lock:
            j = self.job
            if j is None:
                return {"state": "idle"}
            out = {k: v for k, v in j.items() if k not in ("path", "t0", "report", "cancel", "child")}
            out["cancelling"] = j["cancel"] and j["state"] == "running"
            return out

    def done(self) -> dict:
        """The newest slice, finished (an :class:`InputError` otherwise)."""
        with self._lock:
            j = self.job
        if j is None or j["state"] != "done":
            raise InputError("no finished slices: press Slice first")
        return j

    def layer(self, k: int) -> bytes:
        return layer_png(self.done()["path"], k)[0]

    def _run(self, job):
        def update(stage, done, total):
            with self._lock:
                job.update(stage=str(stage), done=int(done), total=max(int(total), 1))
        try:
            report = job["child"].wait(update)
            report["slices"] = job["path"].name
            done = {"state": "done", "stage": None, "report": report, "summary": summary(report),
                    "bytes": job["path"].stat().st_size, "preview_factor": layer_png(job["path"], 0)[1],
                    "seconds": round(time.perf_counter() - job["t0"], 2)}
            with self._lock:
                if job["cancel"] or self.job is not job:
                    raise pv.Superseded()
                job.update(done)
        except pv.Superseded:
            shutil.rmtree(job["path"].parent, ignore_errors=True)
            with self._lock:
                job.update(state="cancelled", stage=None)
        except BaseException as exc:  # noqa: BLE001 - shown in the page
            shutil.rmtree(job["path"].parent, ignore_errors=True)
            with self._lock:
                job.update(state="failed", stage=None, **(exc.args[0] if isinstance(exc, ChildFailed) else
                                                           message(exc)))


def slice_job(recipe: dict, path: str, printer: dict, orient, pixel, layer, progress=None) -> dict:
    """What a slice's child runs: :func:`porecad.api.slice` of the design into ``path`` (sized before any work)."""
    from ..api import slice as slice_design
    return slice_design(recipe, path, printer=printer, pixel=pixel, layer=layer, orient=orient, force=True,
                        progress=progress)
