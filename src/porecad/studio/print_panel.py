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

One slice at a time: a new one cancels the running one at its next progress
step (the writer's temporary file is removed: nothing is left), and a slice
that is no longer the newest keeps no file.
"""

from __future__ import annotations

import io
import math
import threading
import time
import zipfile

from ..errors import InputError
from ..printing.profile import Printer, printer_from_toml, printer_toml
from . import preview as pv
from .tasks import message

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
    w, h, n = m["image_width"] * m["pixel_size"], m["image_height"] * m["pixel_size"], m["layer_count"]
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
            self._n += 1
            n = self._n
            old = self.job
            self.job = {"id": n, "state": "running", "stage": "planning", "done": 0, "total": 1, "cancel": False,
                        "path": self.folder / f"{n}.zip", "t0": time.perf_counter(),
                        "stem": str(recipe.get("job", "design"))}
        if old is not None and old["state"] != "running":
            old["path"].unlink(missing_ok=True)
        threading.Thread(target=self._run, args=(self.job, recipe, self.printer, orient, pixel, layer),
                         name=f"porecad-studio-slice-{n}", daemon=True).start()
        return n

    def cancel(self) -> bool:
        with self._lock:
            if self.job is None or self.job["state"] != "running":
                return False
            self.job["cancel"] = True
            return True

    def state(self) -> dict:
        with self._lock:
            j = self.job
            if j is None:
                return {"state": "idle"}
            out = {k: v for k, v in j.items() if k not in ("path", "t0", "report", "cancel")}
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

    def _run(self, job, recipe, printer, orient, pixel, layer):
        from ..api import slice as slice_design

        def update(stage, done, total):
            with self._lock:
                job.update(stage=str(stage), done=int(done), total=max(int(total), 1))
        progress = pv.checked_progress(lambda: job["cancel"], update)
        try:
            report = slice_design(recipe, job["path"], printer=printer.as_dict(), pixel=pixel, layer=layer,
                                  orient=orient, force=True, progress=progress)
            report["slices"] = job["path"].name
            done = {"state": "done", "stage": None, "report": report, "summary": summary(report),
                    "bytes": job["path"].stat().st_size, "preview_factor": layer_png(job["path"], 0)[1],
                    "seconds": round(time.perf_counter() - job["t0"], 2)}
            with self._lock:
                if job["cancel"] or self.job is not job:
                    raise pv.Superseded()
                job.update(done)
        except pv.Superseded:
            job["path"].unlink(missing_ok=True)
            with self._lock:
                job.update(state="cancelled", stage=None)
        except BaseException as exc:  # noqa: BLE001 - shown in the page
            job["path"].unlink(missing_ok=True)
            with self._lock:
                job.update(state="failed", stage=None, **message(exc))
