"""Slice files: a ZIP of PNG layers (DLP/SLA), a layered SVG and the Common Layer Interface (SLM/SLS).

Each writer is a context manager taking layers one at a time (memory: one
layer), writing into a temporary file that appears under its name only
when the whole stack was written (:mod:`porecad.io.atomic`).

* PNG ZIP: ``manifest.json`` (units, pixel size, layer height, image size,
  layer count, origin, the recipe) and ``layers/00000.png`` ... 8-bit grey,
  grey = fraction of the pixel inside the solid, row 0 at the largest y.
* Prusa SL1 / SL1S (``.sl1``, ``.sl1s``): with a display in the profile each layer is the
  printer's whole canvas, turned and mirrored as PrusaSlicer's SL1 raster
  (``SL1Archive::create_raster``, ``RasterBase::Trafo``) does: :func:`display_canvas`.
* SVG: one ``<g id="layer-K" data-z="Z">`` per layer holding one
  ``<path fill-rule="evenodd">`` per polygon (outer ring, then its holes),
  coordinates in mm (the group's ``scale(1,-1)`` shows y up).
* CLI (Common Layer Interface, version 2.0): ``$$UNITS/0.001`` (one unit
  is a micrometre), ``$$LAYER/z`` and ``$$POLYLINE/id,dir,n,x,y,...``
  with dir 1 an outer ring (counter-clockwise), 0 a hole (clockwise);
  ASCII or binary (``.clib``: the ASCII header, then the long commands 127
  layer and 130 polyline in little-endian); a ``.cli`` is binary when the
  ASCII would pass :data:`CLI_ASCII_MAX_BYTES`.

Every length is exact in whole nanometres (the manifest's ``*_nm`` keys): the
part stands on the plate, layer ``k`` from ``k`` to ``k + 1`` layer heights,
and the SVG and CLI give each layer's top ``(k + 1) × layer`` as exact
decimals (the binary CLI as float32 µm: exact for whole µm below 16 m).
"""

from __future__ import annotations

import json
import struct
import zipfile
import zlib

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_write
from .raster import mm_text

#: ``.cli``: the Common Layer Interface, ASCII unless its estimate passes :data:`CLI_ASCII_MAX_BYTES` (then binary)
FORMATS = {".zip": "png", ".svg": "svg", ".cli": "cli-auto", ".clib": "cli-binary", ".sl1": "sl1", ".sl1s": "sl1",
           ".uvj": "uvj"}
NAMES = ("png", "svg", "cli", "cli-binary", "sl1", "uvj")
GREY = ("png", "sl1", "uvj")  # formats of PNG layers
CLI_UNIT_MM = 0.001
CLI_ASCII_MAX_BYTES = 50_000_000


def format_of(path, fmt: str | None = None, default: str | None = None) -> str:
    """The slice format of an output path (or the one asked for; ``default``, a printer's own format, for a
    name with no known extension)."""
    if fmt:
        if fmt not in NAMES:
            raise InputError(f"unknown slice format {str(fmt)[:20]!r}; one of {', '.join(NAMES)}")
        return fmt
    ext = "." + str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else ""
    if ext not in FORMATS and default:
        format_of(path, default)  # a known name
        return "cli-auto" if default == "cli" else default
    if ext not in FORMATS:
        raise InputError(f"{path}: cannot tell the slice format from the name; end it in "
                         f"{', '.join(FORMATS)} (or give the format)")
    return FORMATS[ext]


def rings(geom, offset=(0.0, 0.0)):
    """``[(outer (n, 2), [holes])]`` of a shapely (multi)polygon moved by ``offset`` (x, y: the design to the
    plate), outer counter-clockwise, holes clockwise."""
    from shapely.geometry.polygon import orient
    out = []
    d = np.asarray(offset, dtype=np.float64)[:2]
    for p in getattr(geom, "geoms", [geom]):
        if p.is_empty or p.geom_type != "Polygon":
            continue
        p = orient(p, 1.0)
        out.append((np.asarray(p.exterior.coords)[:, :2] + d, [np.asarray(h.coords)[:, :2] + d for h in p.interiors]))
    return out


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bytes(grey: np.ndarray) -> bytes:
    """An 8-bit greyscale PNG of ``grey`` (rows filtered "up", zlib level 1: fast, and zlib frees the GIL)."""
    h, w = grey.shape
    raw = np.empty((h, w + 1), dtype=np.uint8)
    raw[:, 0] = 2
    raw[0, 0] = 0
    raw[0, 1:] = grey[0]
    np.subtract(grey[1:], grey[:-1], out=raw[1:, 1:])
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
            + _chunk(b"IDAT", zlib.compress(raw.tobytes(), 1)) + _chunk(b"IEND", b""))


class PngZip:
    """Layers as 8-bit PNGs in a ZIP with a JSON manifest."""

    needs = "grey"

    def __init__(self, path, manifest: dict, force: bool = False):
        self.path, self.manifest, self.force = path, manifest, force

    def __enter__(self):
        self._ctx = atomic_write(self.path, force=self.force)
        self._zip = zipfile.ZipFile(self._ctx.__enter__(), "w", compression=zipfile.ZIP_STORED)
        return self

    def encode(self, k: int, grey, polygons=None) -> bytes:
        return png_bytes(grey)

    def name(self, k: int) -> str:
        return f"layers/{k:05d}.png"

    def add(self, k: int, payload: bytes):
        self._zip.writestr(self.name(k), payload)

    def extras(self) -> dict:
        """The files written after the layers: ``{name: bytes}``."""
        return {"manifest.json": json.dumps(self.manifest, indent=1).encode()}

    def __exit__(self, *exc):
        if exc[0] is None:
            for name, data in self.extras().items():
                self._zip.writestr(name, data)
        self._zip.close()
        return self._ctx.__exit__(*exc)


def _exact(n: int) -> float:
    """Whole nm as the float whose shortest text is the exact decimal in mm (JSON and INI numbers)."""
    return float(mm_text(n))


def png_rgba(grey: np.ndarray) -> bytes:
    """An 8-bit RGBA PNG of a grey image (grey in R, G and B, opaque), as PrusaSlicer writes its thumbnails."""
    h, w = grey.shape
    raw = np.empty((h, 1 + 4 * w), dtype=np.uint8)
    raw[:, 0] = 0
    px = raw[:, 1:].reshape(h, w, 4)
    px[..., :3] = grey[..., None]
    px[..., 3] = 255
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
            + _chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + _chunk(b"IEND", b""))


def display_canvas(display: dict, grey: np.ndarray) -> np.ndarray:
    """A layer's grey (row 0 the largest y) on a printer's whole display, as PrusaSlicer draws an SL1 layer.

    The display has ``pixels`` (x, y) along the plate's x and y, the part at ``offset_px``. As
    PrusaSlicer's raster (``RasterBase::Trafo``): landscape, the image is x across and y up (row 0 the
    largest y) unless ``mirror[1]``, x reversed when ``mirror[0]``; portrait (x and y swapped: an image
    of ``pixels[1]`` columns and ``pixels[0]`` rows), y across, reversed unless ``mirror[0]``, and x down,
    reversed unless ``mirror[1]``.
    """
    (nx, ny), (i0, j0) = display["pixels"], display["offset_px"]
    canvas = np.zeros((ny, nx), dtype=np.uint8)  # [y index, x index]
    canvas[j0:j0 + grey.shape[0], i0:i0 + grey.shape[1]] = grey[::-1]
    mx, my = display["mirror"]
    if display["orientation"] == "portrait":
        img = canvas.T  # [x index, y index]
        img = img if my else img[::-1]
        img = img if mx else img[:, ::-1]
    else:
        img = canvas if my else canvas[::-1]
        img = img[:, ::-1] if mx else img
    return np.ascontiguousarray(img)


def decode_own_png(payload: bytes) -> np.ndarray:
    """The grey image of a PNG written by :func:`png_bytes` (one IDAT, rows filtered "up")."""
    w, h = struct.unpack_from(">II", payload, 16)
    (n,) = struct.unpack_from(">I", payload, 33)  # the one IDAT chunk after the signature and IHDR
    raw = np.frombuffer(zlib.decompress(payload[41:41 + n]), dtype=np.uint8).reshape(h, w + 1)[:, 1:]
    return np.cumsum(raw, axis=0, dtype=np.uint8)


class ThumbnailZip(PngZip):
    """A resin printer's ZIP of PNG layers that also holds a view from above (the layers' maximum)."""

    THUMBNAILS = ()
    RGBA = False

    def add(self, k: int, payload: bytes):
        super().add(k, payload)
        step = max(1, self.manifest["layer_count"] // 64)
        if k % step == 0:  # the view from above: every step-th layer decoded
            grey = decode_own_png(payload)
            self._top = grey if getattr(self, "_top", None) is None else np.maximum(self._top, grey)

    def thumbnails(self) -> dict:
        """``{name: PNG}`` of the view from above (cut to the part) fitted (nearest pixel) into each thumbnail."""
        top = getattr(self, "_top", None)
        if top is None or not top.any():
            top = np.zeros((1, 1), dtype=np.uint8)
        else:
            rows, cols = np.nonzero(top.any(axis=1))[0], np.nonzero(top.any(axis=0))[0]
            top = top[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        out = {}
        for name, (w, h) in self.THUMBNAILS:
            img = np.zeros((h, w), dtype=np.uint8)
            s = min(w / top.shape[1], h / top.shape[0])
            tw, th = max(1, int(top.shape[1] * s)), max(1, int(top.shape[0] * s))
            rows = np.minimum((np.arange(th) / s).astype(int), top.shape[0] - 1)
            cols = np.minimum((np.arange(tw) / s).astype(int), top.shape[1] - 1)
            y0, x0 = (h - th) // 2, (w - tw) // 2
            img[y0:y0 + th, x0:x0 + tw] = top[np.ix_(rows, cols)]
            out[name] = png_rgba(img) if self.RGBA else png_bytes(img)
        return out


class PrusaSl1(ThumbnailZip):
    """Prusa SL1 / SL1S: ``config.ini`` (the printer's job keys), ``prusaslicer.ini`` (the display and the
    exposure), the layers ``<jobDir>00000.png`` ... and two RGBA thumbnails, as PrusaSlicer's ``SL1Archive``
    writes them. With a display in the profile each layer is the display's whole canvas
    (:func:`display_canvas`); without one, the part's own raster."""

    THUMBNAILS = (("thumbnail/thumbnail400x400.png", (400, 400)), ("thumbnail/thumbnail800x480.png", (800, 480)))
    RGBA = True
    JOB = "porecad"

    def name(self, k: int) -> str:
        return f"{self.JOB}{k:05d}.png"

    def encode(self, k: int, grey, polygons=None) -> bytes:
        display = self.manifest["plate"].get("display")
        return png_bytes(display_canvas(display, grey) if display else grey)

    def model(self) -> str:
        p = self.manifest.get("printer_profile", {})
        return p.get("model") or ("SL1S" if str(self.path).lower().endswith(".sl1s") else "SL1")

    def extras(self) -> dict:
        m, p = self.manifest, self.manifest.get("printer_profile", {})
        n, bottom = m["layer_count"], min(int(p.get("bottom_layers", 0)), m["layer_count"])
        config = {"action": "print", "expTime": p.get("exposure", 0.0), "expTimeFirst": p.get("bottom_exposure", 0.0),
                  "expUserProfile": 0, "fileCreationTimestamp": "", "hollow": 0, "jobDir": self.JOB,
                  "layerHeight": _exact(m["layer_height_nm"]), "materialName": "", "numFade": bottom, "numFast": n,
                  "numSlow": 0, "printProfile": "porecad", "printTime": round(n * p.get("layer_time", 0.0), 3),
                  "printerModel": self.model(), "printerProfile": m.get("printer", ""), "printerVariant": "default",
                  "prusaSlicerVersion": "porecad", "usedMaterial": 0}
        display = m["plate"].get("display")
        if display:
            (w, h), (px, py) = display["size_nm"], display["pixels"]
            look = {"display_orientation": display["orientation"], "display_mirror_x": int(display["mirror"][0]),
                    "display_mirror_y": int(display["mirror"][1])}
        else:
            px, py = m["image_width"], m["image_height"]
            w, h = px * m["pixel_x_nm"], py * m["pixel_y_nm"]
            look = {"display_orientation": "landscape", "display_mirror_x": 0, "display_mirror_y": 0}
        slicer = {"display_height": _exact(h), "display_pixels_x": px, "display_pixels_y": py,
                  "display_width": _exact(w), **look,
                  "exposure_time": config["expTime"], "faded_layers": bottom,
                  "initial_exposure_time": config["expTimeFirst"], "layer_height": config["layerHeight"],
                  "printer_model": config["printerModel"], "printer_technology": "SLA",
                  "printer_variant": "default"}
        ini = lambda d: "".join(f"{k} = {v}\n" for k, v in sorted(d.items())).encode()  # noqa: E731
        # file by file what PrusaSlicer writes (tests/printing/test_sl1_reference.py): no manifest of porecad's
        return {"config.ini": ini(config), "prusaslicer.ini": ini(slicer), **self.thumbnails()}


class UvtoolsUvj(ThumbnailZip):
    """UVtools' vendor-neutral UVJ: ``config.json`` (Properties: Size, Exposure, Bottom; a Layers entry per layer
    with its Z), ``slice/00000000.png`` ... and ``preview/tiny.png``, ``preview/huge.png``."""

    THUMBNAILS = (("preview/tiny.png", (400, 400)), ("preview/huge.png", (800, 480)))

    def name(self, k: int) -> str:
        return f"slice/{k:08d}.png"

    def extras(self) -> dict:
        m, p = self.manifest, self.manifest.get("printer_profile", {})
        n, h = m["layer_count"], m["layer_height_nm"]
        exposure = {"LightOnTime": p.get("exposure", 0.0), "LightOffTime": 0.0}
        settings = {"Properties": {
            "Size": {"X": m["image_width"], "Y": m["image_height"],
                     "Millimeter": {"X": _exact(m["image_width"] * m["pixel_x_nm"]),
                                    "Y": _exact(m["image_height"] * m["pixel_y_nm"])},
                     "Layers": n, "LayerHeight": _exact(h)},
            "Exposure": exposure,
            "Bottom": {"LightOnTime": p.get("bottom_exposure", 0.0), "LightOffTime": 0.0,
                       "Count": min(int(p.get("bottom_layers", 0)), n)},
            "AntiAliasLevel": 1},
            "Layers": [{"Z": _exact((k + 1) * h), "Exposure": exposure} for k in range(n)]}
        return {"config.json": json.dumps(settings, indent=1).encode(), **self.thumbnails(),
                "manifest.json": super().extras()["manifest.json"]}


class LayeredSvg:
    """One ``<g>`` per layer, polygons with holes in mm."""

    needs = "polygons"

    def __init__(self, path, manifest: dict, force: bool = False):
        self.path, self.manifest, self.force = path, manifest, force

    def __enter__(self):
        self._ctx = atomic_write(self.path, force=self.force)
        self._f = self._ctx.__enter__()
        m = self.manifest
        x0, y0, _ = m["plate"]["origin_nm"]
        w, h = m["image_width"] * m["pixel_x_nm"], m["image_height"] * m["pixel_y_nm"]
        box = " ".join(mm_text(v) for v in (x0, -(y0 + h), w, h))
        self._f.write((f'<?xml version="1.0" encoding="UTF-8"?>\n<svg xmlns="http://www.w3.org/2000/svg" '
                       f'width="{mm_text(w)}mm" height="{mm_text(h)}mm" viewBox="{box}" '
                       f'data-layer-height="{mm_text(m["layer_height_nm"])}" data-layers="{m["layer_count"]}">\n'
                       ).encode())
        return self

    def encode(self, k: int, grey, polygons=None) -> bytes:
        z = mm_text((k + 1) * self.manifest["layer_height_nm"])
        parts = [f' <g id="layer-{k}" data-z="{z}" transform="scale(1,-1)" fill="white">\n']
        for outer, holes in rings(polygons, self.manifest["plate"]["offset"]):
            d = " ".join("M " + " L ".join(f"{x:.5f},{y:.5f}" for x, y in r[:-1]) + " Z" for r in [outer, *holes])
            parts.append(f'  <path fill-rule="evenodd" d="{d}"/>\n')
        parts.append(" </g>\n")
        return "".join(parts).encode()

    def add(self, k: int, payload: bytes):
        self._f.write(payload)

    def __exit__(self, *exc):
        if exc[0] is None:
            self._f.write(b"</svg>\n")
        return self._ctx.__exit__(*exc)


class CommonLayer:
    """The Common Layer Interface, ASCII or binary (long commands)."""

    needs = "polygons"

    def __init__(self, path, manifest: dict, force: bool = False, binary: bool = False):
        self.path, self.manifest, self.force, self.binary = path, manifest, force, binary

    def __enter__(self):
        self._ctx = atomic_write(self.path, force=self.force)
        self._f = self._ctx.__enter__()
        m = self.manifest
        x0, y0, z0 = m["plate"]["origin_nm"]
        w, h = m["image_width"] * m["pixel_x_nm"], m["image_height"] * m["pixel_y_nm"]
        dims = [x0, y0, z0, x0 + w, y0 + h, z0 + m["layer_count"] * m["layer_height_nm"]]
        head = ["$$HEADERSTART", "$$BINARY" if self.binary else "$$ASCII", f"$$UNITS/{CLI_UNIT_MM:.6f}",
                "$$VERSION/200", "$$LABEL/1,porecad", f"$$DIMENSION/{','.join(mm_text(v, 3) for v in dims)}",
                f"$$LAYERS/{m['layer_count']}", "$$HEADEREND"]
        self._f.write(("\n".join(head) + "\n").encode())
        if not self.binary:
            self._f.write(b"$$GEOMETRYSTART\n")
        return self

    def encode(self, k: int, grey, polygons=None) -> bytes:
        z = (k + 1) * self.manifest["layer_height_nm"]  # the layer's top above the plate, whole nm
        u = 1.0 / CLI_UNIT_MM
        if self.binary:
            out = [struct.pack("<Hf", 127, z / 1000)]
        else:
            out = [f"$$LAYER/{mm_text(z, 3)}\n"]
        for outer, holes in rings(polygons, self.manifest["plate"]["offset"]):
            for direction, r in [(1, outer)] + [(0, hole) for hole in holes]:
                pts = np.asarray(r, dtype=np.float64) * u
                if self.binary:
                    out.append(struct.pack("<Hiii", 130, 1, direction, len(pts)))
                    out.append(pts.astype("<f4").tobytes())
                else:
                    xy = ",".join(f"{x:.3f},{y:.3f}" for x, y in pts)
                    out.append(f"$$POLYLINE/1,{direction},{len(pts)},{xy}\n")
        return b"".join(o if isinstance(o, bytes) else o.encode() for o in out)

    def add(self, k: int, payload: bytes):
        self._f.write(payload)

    def __exit__(self, *exc):
        if exc[0] is None and not self.binary:
            self._f.write(b"$$GEOMETRYEND\n")
        return self._ctx.__exit__(*exc)


def encode(fmt: str, manifest: dict, k: int, grey, polygons=None) -> bytes:
    """Layer ``k`` as the bytes the writer of ``fmt`` appends (a module function: it travels to dask workers)."""
    cls = {"png": PngZip, "sl1": PrusaSl1, "uvj": UvtoolsUvj, "svg": LayeredSvg}.get(fmt, CommonLayer)
    w = cls.__new__(cls)
    w.manifest, w.binary = manifest, fmt == "cli-binary"
    return w.encode(k, grey, polygons)


def writer(path, fmt: str, manifest: dict, force: bool = False):
    """The writer of ``fmt`` for ``path``."""
    if fmt in GREY:
        return {"png": PngZip, "sl1": PrusaSl1, "uvj": UvtoolsUvj}[fmt](path, manifest, force)
    if fmt == "svg":
        return LayeredSvg(path, manifest, force)
    return CommonLayer(path, manifest, force, binary=fmt == "cli-binary")


def read_cli_ascii(text: str) -> list:
    """``[(z_mm, [(dir, (n, 2) mm)])]`` of an ASCII CLI file (for checks; bounded by the text given)."""
    layers = []
    unit = 1.0
    for line in text.splitlines():
        if line.startswith("$$UNITS/"):
            unit = float(line[8:])
        elif line.startswith("$$LAYER/"):
            layers.append((float(line[8:]) * unit, []))
        elif line.startswith("$$POLYLINE/"):
            v = line[11:].split(",")
            n = int(v[2])
            pts = np.asarray(v[3:3 + 2 * n], dtype=float).reshape(n, 2) * unit
            layers[-1][1].append((int(v[1]), pts))
    return layers
