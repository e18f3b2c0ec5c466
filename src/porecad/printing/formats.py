"""Slice files: a ZIP of PNG layers (DLP/SLA), a layered SVG and the Common Layer Interface (SLM/SLS).

Each writer is a context manager taking layers one at a time (memory: one
layer), writing into a temporary file that appears under its name only
when the whole stack was written (:mod:`porecad.io.atomic`).

* PNG ZIP: ``manifest.json`` (units, pixel size, layer height, image size,
  layer count, origin, the recipe) and ``layers/00000.png`` ... 8-bit grey,
  grey = fraction of the pixel inside the solid, row 0 at the largest y.
* SVG: one ``<g id="layer-K" data-z="Z">`` per layer holding one
  ``<path fill-rule="evenodd">`` per polygon (outer ring, then its holes),
  coordinates in mm (the group's ``scale(1,-1)`` shows y up).
* CLI (Common Layer Interface, version 2.0): ``$$UNITS/0.001`` (one unit
  is a micrometre), ``$$LAYER/z`` and ``$$POLYLINE/id,dir,n,x,y,...``
  with dir 1 an outer ring (counter-clockwise), 0 a hole (clockwise);
  ASCII (``.cli``) or binary (``.clib``: the ASCII header, then the long
  commands 127 layer and 130 polyline in little-endian).
"""

from __future__ import annotations

import json
import struct
import zipfile
import zlib

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_write

FORMATS = {".zip": "png", ".svg": "svg", ".cli": "cli", ".clib": "cli-binary"}
CLI_UNIT_MM = 0.001


def format_of(path, fmt: str | None = None) -> str:
    """The slice format of an output path (or the one asked for)."""
    if fmt:
        if fmt not in FORMATS.values():
            raise InputError(f"unknown slice format {fmt!r}; one of {', '.join(FORMATS.values())}")
        return fmt
    ext = "." + str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else ""
    if ext not in FORMATS:
        raise InputError(f"{path}: cannot tell the slice format from the name; end it in "
                         f"{', '.join(FORMATS)} (or give the format)")
    return FORMATS[ext]


def rings(geom):
    """``[(outer (n, 2), [holes])]`` of a shapely (multi)polygon, outer counter-clockwise, holes clockwise."""
    from shapely.geometry.polygon import orient
    out = []
    for p in getattr(geom, "geoms", [geom]):
        if p.is_empty or p.geom_type != "Polygon":
            continue
        p = orient(p, 1.0)
        out.append((np.asarray(p.exterior.coords)[:, :2], [np.asarray(h.coords)[:, :2] for h in p.interiors]))
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

    def add(self, k: int, payload: bytes):
        self._zip.writestr(f"layers/{k:05d}.png", payload)

    def __exit__(self, *exc):
        if exc[0] is None:
            self._zip.writestr("manifest.json", json.dumps(self.manifest, indent=1))
        self._zip.close()
        return self._ctx.__exit__(*exc)


class LayeredSvg:
    """One ``<g>`` per layer, polygons with holes in mm."""

    needs = "polygons"

    def __init__(self, path, manifest: dict, force: bool = False):
        self.path, self.manifest, self.force = path, manifest, force

    def __enter__(self):
        self._ctx = atomic_write(self.path, force=self.force)
        self._f = self._ctx.__enter__()
        m = self.manifest
        x0, y0 = m["origin"][:2]
        w, h = m["image_width"] * m["pixel_size"], m["image_height"] * m["pixel_size"]
        self._f.write((f'<?xml version="1.0" encoding="UTF-8"?>\n<svg xmlns="http://www.w3.org/2000/svg" '
                       f'width="{w:.6g}mm" height="{h:.6g}mm" viewBox="{x0:.6f} {-(y0 + h):.6f} {w:.6f} {h:.6f}" '
                       f'data-layer-height="{m["layer_height"]:.6g}" data-layers="{m["layer_count"]}">\n'
                       ).encode())
        return self

    def encode(self, k: int, grey, polygons=None) -> bytes:
        z = self.manifest["first_layer_z"] + k * self.manifest["layer_height"]
        parts = [f' <g id="layer-{k}" data-z="{z:.6f}" transform="scale(1,-1)" fill="white">\n']
        for outer, holes in rings(polygons):
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
        lo = m["origin"]
        w, h = m["image_width"] * m["pixel_size"], m["image_height"] * m["pixel_size"]
        dims = [lo[0], lo[1], lo[2], lo[0] + w, lo[1] + h, lo[2] + m["height"]]
        head = ["$$HEADERSTART", "$$BINARY" if self.binary else "$$ASCII", f"$$UNITS/{CLI_UNIT_MM:.6f}",
                "$$VERSION/200", "$$LABEL/1,porecad", f"$$DIMENSION/{','.join(f'{v:.6f}' for v in dims)}",
                f"$$LAYERS/{m['layer_count']}", "$$HEADEREND"]
        self._f.write(("\n".join(head) + "\n").encode())
        if not self.binary:
            self._f.write(b"$$GEOMETRYSTART\n")
        return self

    def encode(self, k: int, grey, polygons=None) -> bytes:
        z = self.manifest["first_layer_z"] + k * self.manifest["layer_height"]
        u = 1.0 / CLI_UNIT_MM
        if self.binary:
            out = [struct.pack("<Hf", 127, z * u)]
        else:
            out = [f"$$LAYER/{z * u:.3f}\n"]
        for outer, holes in rings(polygons):
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
    cls = {"png": PngZip, "svg": LayeredSvg}.get(fmt, CommonLayer)
    w = cls.__new__(cls)
    w.manifest, w.binary = manifest, fmt == "cli-binary"
    return w.encode(k, grey, polygons)


def writer(path, fmt: str, manifest: dict, force: bool = False):
    """The writer of ``fmt`` for ``path``."""
    if fmt == "png":
        return PngZip(path, manifest, force)
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
