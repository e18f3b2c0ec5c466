"""Slice a part for a printer: the layer files, printability, build orientation, the report.

:func:`slice_to` is the one entry point (``porecad slice`` and
:func:`porecad.api.slice` call it). It streams the layers band by band
(:mod:`porecad.printing.raster`) into the writer
(:mod:`porecad.printing.formats`), tracks mid-air starts on the print
layers and judges walls, channels and closed pores on a voxel model
(:mod:`porecad.printing.printability`). Under ``strict`` a part with
findings is refused and nothing is written.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from ..errors import InputError
from . import printability as pr
from .formats import CLI_ASCII_MAX_BYTES, format_of, rings, writer
from .part import Part, directions, rotation_to_z
from .raster import (BAND_BYTES, LayerGrid, check_size, field_bands, field_polygons, mesh_sections, rasterise,
                     sample_layers, to_grey)


def _bands(part: Part, grid: LayerGrid, pool, threads: int):
    """Yield ``(k0, [values per layer] or None, covers or None, geometries or None)`` per band of layers.

    A field's band is sampled in ``threads`` pieces at once (the TPMS kernels release the GIL); a part
    with :attr:`~porecad.printing.part.Part.windows` a layer at a time, each layer's values
    ``(i0, i1, j0, j1, values)`` on its window only (every other pixel empty).
    """
    if part.windows is not None:
        xs, ys = grid.xs, grid.ys
        band = grid.band_size()
        for k0 in range(0, grid.n_layers, band):
            ks = range(k0, min(grid.n_layers, k0 + band))
            yield k0, list(pool.map(lambda k: part.windows.sample(xs, ys, float(grid.z(k))), ks)), None, None
        return
    if part.field is not None:
        band = grid.band_size()
        for k0 in range(0, grid.n_layers, band):
            k1 = min(grid.n_layers, k0 + band)
            cuts = np.unique(np.linspace(k0, k1, min(threads, k1 - k0) + 1).round().astype(int))
            pieces = pool.map(lambda ab: sample_layers(part.field, grid, *ab), zip(cuts[:-1], cuts[1:]))
            yield k0, [layer for piece in pieces for layer in piece], None, None
        return
    for k0 in range(0, grid.n_layers, 16):
        geoms = mesh_sections(part.mesh, grid, k0, min(grid.n_layers, k0 + 16))
        yield k0, None, [rasterise(g, grid) for g in geoms], geoms


def _field_layer(part: Part, grid: LayerGrid, vals, weights, polygons: bool):
    """``(grey, solid, area, geometry or None, (i0, i1, j0, j1))`` of a field layer: its values on the whole
    grid, or ``(i0, i1, j0, j1, values)`` on a window (:func:`_bands`), the pixels beyond it empty. The
    window's grey and solid are those of the whole layer there (:func:`_kernels.layer_grey`; its pixels at the
    body's band or beyond are empty, as those beyond it)."""
    from ._kernels import layer_grey
    ny, nx = grid.ny, grid.nx
    if isinstance(vals, tuple):
        i0, i1, j0, j1, v = vals
        grey = np.zeros((ny, nx), dtype=np.uint8)
        solid = np.zeros((ny, nx), dtype=np.bool_)
        area = 0.0
        if i1 > i0 and j1 > j0:
            w = weights[j0:j1, i0:i1] if part.boxed else weights
            area = layer_grey(v, grid.px, grid.py, w, part.boxed, grey[ny - j1:ny - j0, i0:i1], solid[j0:j1, i0:i1],
                              part.windows.outside)
        geom = None
        if polygons:
            full = np.full((ny, nx), part.windows.outside, dtype=np.float32)
            full[j0:j1, i0:i1] = v
            geom = field_polygons(full, grid, part.boxed)
        return grey, solid, area, geom, (i0, i1, j0, j1)
    grey = np.empty((ny, nx), dtype=np.uint8)
    solid = np.empty((ny, nx), dtype=np.bool_)
    area = layer_grey(vals, grid.px, grid.py, weights, part.boxed, grey, solid)
    return grey, solid, area, field_polygons(vals, grid, part.boxed) if polygons else None, (0, nx, 0, ny)


def layers(part: Part, grid: LayerGrid, polygons: bool, encode=None, threads: int = 2):
    """Yield ``(k, grey, solid, area, geometry or None, payload, islands)`` for every layer in order.

    Layers of a band are done in ``threads`` threads (the kernels and the PNG encoder release the GIL):
    grey and solid (:func:`_field_layer`), the contour polygons when ``polygons``, the writer's
    ``encode(k, grey, geometry)`` and the pieces resting on nothing (:func:`_kernels.new_islands`, on
    the layer's window: no solid lies beyond it).
    """
    from concurrent.futures import ThreadPoolExecutor

    from ._kernels import new_islands
    weights = grid.box_weights() if part.boxed else np.ones((1, 1), dtype=np.float32)
    prev = None

    def one(k, vals, cov, geom):
        if vals is not None:
            grey, solid, area, geom, win = _field_layer(part, grid, vals, weights, polygons)
        else:
            grey = to_grey(cov)
            solid = cov >= 0.5
            area = float(cov.sum(dtype=np.float64)) * grid.pixel_area
            win = (0, grid.nx, 0, grid.ny)
        return k, grey, solid, area, geom, encode(k, grey, geom) if encode else None, win

    def islands(d, below):
        if below is None:
            return None
        i0, i1, j0, j1 = d[6]
        return new_islands(d[2][j0:j1, i0:i1], below[j0:j1, i0:i1], j0, i0)

    with ThreadPoolExecutor(max(1, threads)) as pool:
        for k0, vals, covs, geoms in _bands(part, grid, pool, max(1, threads)):
            n = len(vals) if vals is not None else len(covs)
            done = list(pool.map(lambda i: one(k0 + i, None if vals is None else vals[i],
                                                None if covs is None else covs[i],
                                                None if geoms is None else geoms[i]), range(n)))
            below = [prev] + [d[2] for d in done[:-1]]
            isl = list(pool.map(lambda i: islands(done[i], below[i]), range(n)))
            for d, found in zip(done, isl):
                yield (*d[:6], found)
            prev = done[-1][2]


def check_grid(part: Part, printer, pixel: float, max_voxels: int) -> LayerGrid:
    """The cubic voxel grid of the part's model: a third of the printer's smallest limit (the print's pixel where
    that is coarser; four pixels without limits), coarser only to stay within ``max_voxels``, padded with a void
    wider than any limit."""
    ext = np.asarray(part.hi) - np.asarray(part.lo)
    limits = [x for x in (printer.min_feature, printer.min_channel) if x > 0]
    v = max(min(limits) / 3 if limits else pixel * 4, pixel)
    pad = lambda v: (math.ceil(max(limits, default=0.0) / v) + 2) * v  # noqa: E731 - void wider than any limit
    while np.prod((ext + 2 * pad(v)) / v + 1) > max_voxels:
        v *= 1.25
    return LayerGrid.around(part.lo - pad(v), part.hi + pad(v), v, v)


def model_layers(part: Part, g: LayerGrid):
    """Yield the part's solid layers (bool ``(ny, nx)``) on the grid ``g`` in order: nothing beyond the part's box
    (an unbounded lattice), a void rim around it."""
    inside = []
    for a, n in ((0, g.nx), (1, g.ny), (2, g.n_layers)):
        c = g.lo[a] + (np.arange(n) + 0.5) * g.pixel
        out = (c < part.lo[a]) | (c > part.hi[a])
        out[[0, -1]] = True
        inside.append(~out)
    plane = np.outer(inside[1], inside[0])
    if part.field is not None:
        inner = LayerGrid(g.lo, g.pixel, g.pixel, g.nx, g.ny, g.n_layers, tuple(part.hi))
        stream = ((k0 + i, c >= 0.5) for k0, _, cov in field_bands(part.field, inner, boxed=part.boxed)
                  for i, c in enumerate(cov))
    else:
        stream = ((k, sol) for k, _, sol, _, _, _, _ in layers(part, g, polygons=False))
    for k, sol in stream:
        yield sol & plane if inside[2][k] else np.zeros_like(sol)


def check_model(part: Part, printer, pixel: float):
    """A coarse whole voxel model of the part (for its proxy mesh): (solid, lo, voxel, values or None)."""
    g = check_grid(part, printer, pixel, pr.MAX_MODEL_VOXELS)
    v = g.pixel
    solid = np.stack(list(model_layers(part, g)))
    values = None
    if part.field is not None:  # the field's own values make a smoother proxy than the voxels
        inner = LayerGrid(g.lo, v, v, g.nx, g.ny, g.n_layers, tuple(part.hi))
        values = np.concatenate([0.5 - cov for _, _, cov in field_bands(part.field, inner, boxed=part.boxed)])
        values[~solid & (values < 0)] = 0.5
    return solid, np.asarray(g.lo), v, values


def proxy_mesh(part: Part, model):
    """A triangle mesh of the part for overhangs: its own mesh, or marching cubes of the voxel model."""
    if part.mesh is not None:
        return np.asarray(part.mesh.vertices), np.asarray(part.mesh.faces)
    from skimage.measure import marching_cubes
    solid, lo, v, values = model
    if not solid.any():
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=int)
    verts, faces, _, _ = marching_cubes(np.where(solid, -1.0, 1.0).astype(np.float32) if values is None else values,
                                        0.0, spacing=(v, v, v))
    verts = verts[:, ::-1] + lo + v / 2
    return verts, faces[:, ::-1]


def rank_orientations(vertices, faces, printer, layer: float) -> list:
    """The 26 build directions ranked by unsupported area, then height: ``[{direction, unsupported_area, height}]``."""
    out = []
    v = np.asarray(vertices, dtype=np.float64)
    facets = pr.mesh_facets(v, faces)  # once: each direction only projects them (as rotating d to +z would)
    for d in directions():
        h = v @ d
        floor = h.min() + layer if len(h) else 0.0
        o = pr.overhangs(v, faces, printer.max_overhang, floor, up=d, facets=facets, by_angle=False)
        out.append({"direction": [round(float(x), 6) for x in d], "unsupported_area": round(o["unsupported_area"], 6),
                    "height": round(float(np.ptp(h)) if len(h) else 0.0, 6)})
    return sorted(out, key=lambda r: (r["unsupported_area"], r["height"]))


def _fit(part: Part, printer) -> None:
    size = np.asarray(part.hi) - np.asarray(part.lo)
    if np.any(size > np.asarray(printer.build) + 1e-9):
        raise InputError(f"the part ({' x '.join(f'{s:.4g}' for s in size)} mm) is larger than the printer's build "
                         f"volume ({' x '.join(f'{b:.4g}' for b in printer.build)} mm)")


#: peak bytes per pixel of the layers in flight: a field's band (values, sampling scratch, grey and solid) and each
#: thread's layer; a mesh's band of 16 layers (coverage, grey, solid) and each thread's 4 x 4 supersampled fill
FIELD_BAND_BYTES, FIELD_LAYER_BYTES = 14, 16
MESH_BAND_BYTES, MESH_LAYER_BYTES = 16 * 6, 84
#: seconds per pixel (2 cores, a gyroid cell at 1-4 M pixels a layer: field 13-40 ns, mesh sections 160-240 ns)
SECONDS_PER_PIXEL = {"field": 30e-9, "mesh": 250e-9}


def slice_estimate(part: Part, pixel: float, layer: float, orient=None, threads: int = 2, pixel_y=None,
                   printer=None) -> dict:
    """The estimate (:func:`porecad.resources.require_fits`) of slicing ``part``: pixels, peak bytes, seconds.

    With ``orient`` the part's box is turned by the direction asked for ("auto": every candidate
    direction), its largest extents counted: an upper bound of the turned part's. With a ``printer`` the
    printability checks are counted too: a band of their model (:func:`check_bytes`).
    """
    from ..resources import work_estimate
    lo, hi = np.asarray(part.lo, dtype=float), np.asarray(part.hi, dtype=float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    turns = [np.eye(3)]
    if isinstance(orient, str) and orient == "auto":
        turns += [rotation_to_z(d) for d in directions()]
    elif orient is not None and not isinstance(orient, str):
        d = np.asarray(orient, dtype=float)
        if d.shape == (3,) and np.all(np.isfinite(d)) and np.linalg.norm(d) >= 1e-9:
            turns.append(rotation_to_z(d))
    ext = np.max([np.ptp(corners @ R.T, axis=0) for R in turns], axis=0)
    ext = np.where(np.isfinite(ext), ext, 0.0)
    layer_px = float(max(1.0, math.ceil(ext[0] / pixel))) * float(max(1.0, math.ceil(ext[1] / (pixel_y or pixel))))
    n_layers = float(max(1, round(ext[2] / layer)))
    if part.field is not None:
        band = max(1.0, min(n_layers, float(BAND_BYTES // (4 * layer_px))))
        peak = layer_px * (band * FIELD_BAND_BYTES + threads * FIELD_LAYER_BYTES)
    else:
        peak = layer_px * (MESH_BAND_BYTES + threads * MESH_LAYER_BYTES)
    if printer is not None:
        peak = max(peak, check_bytes(part, printer, min(pixel, pixel_y or pixel)))
    est = work_estimate(layer_px * n_layers, 0, sample_bytes=0,
                        sample_seconds=SECONDS_PER_PIXEL["field" if part.field is not None else "mesh"],
                        extra_bytes=peak)
    est.update(layer_pixels=layer_px, layers=n_layers, unit="pixels")
    return est


#: bytes per voxel of the printability model's band while it is judged (:mod:`porecad.printing.banded`: the
#: window, its masks and labels) and of a field part's whole proxy model (values, marching cubes); with a
#: mesh's slices the peak measured 0.67-1.15 GB against 0.22-0.25 GB estimated for the layers alone
CHECK_BYTES_PER_VOXEL, PROXY_BYTES_PER_VOXEL = 40, 24


def check_bytes(part: Part, printer, pixel: float) -> float:
    """Peak bytes of the printability checks: a band of their model, and a field part's proxy model."""
    from .banded import WINDOW_VOXELS
    g = check_grid(part, printer, pixel, pr.MAX_CHECK_VOXELS)
    voxels = float(g.nx) * g.ny * g.n_layers
    out = min(voxels, WINDOW_VOXELS) * CHECK_BYTES_PER_VOXEL
    if part.field is not None:
        out += min(voxels, pr.MAX_MODEL_VOXELS) * PROXY_BYTES_PER_VOXEL
    return out


def placement(grid: LayerGrid, printer) -> dict:
    """Where the layers stand on the plate, in whole nm: layer 0 on it (z from 0), the image centred in the
    build area (``place = "centre"``) or at the design's x and y (``"design"``); ``offset`` (mm) moves the
    design's coordinates (the slices' grid, the findings) to the plate's.

    With a display in the profile (its pitch the grid's), the plate is the display: the image sits on whole
    display pixels (``display.offset_px``, pixel (0, 0) at the plate's origin) and must lie on it."""
    from .raster import nm
    pitch = (nm(grid.px), nm(grid.py))
    size = (grid.nx * pitch[0], grid.ny * pitch[1])
    display = None
    if printer.has_display and pitch == (nm(printer.pixel_x), nm(printer.pixel_y)):
        n = (printer.display_pixels_x, printer.display_pixels_y)
        if printer.place == "centre":
            at = [(d - k) // 2 for d, k in zip(n, (grid.nx, grid.ny))]
        else:
            at = [round(nm(v) / p) for v, p in zip(grid.lo[:2], pitch)]
        if any(a < 0 or a + k > d for a, k, d in zip(at, (grid.nx, grid.ny), n)):
            raise InputError(f"the part ({grid.nx} x {grid.ny} pixels"
                             f"{' at its design place' if printer.place == 'design' else ''}) does not fit the "
                             f"printer's display ({n[0]} x {n[1]} pixels)")
        xy = [a * p for a, p in zip(at, pitch)]
        display = {"pixels": list(n), "offset_px": at, "orientation": printer.display_orientation,
                   "mirror": [printer.display_mirror_x, printer.display_mirror_y],
                   "size_nm": [nm(printer.display_width), nm(printer.display_height)]}
    elif printer.place == "centre":
        xy = [(nm(b) - s) // 2 for b, s in zip(printer.build[:2], size)]
    else:
        xy = [nm(v) for v in grid.lo[:2]]
    origin = [*xy, 0]
    out = {"place": printer.place, "origin_nm": origin, "offset": [o / 1e6 - lo for o, lo in zip(origin, grid.lo)],
           "layer_z": "layer k lies from k to k + 1 layer heights above the plate; the SVG and CLI give its top"}
    if display is not None:
        out["display"] = display
    return out


def cli_ascii_bytes(part: Part, grid: LayerGrid) -> int:
    """The size of the part's ASCII CLI, estimated from the contours of three layers (at 1/4, 1/2 and 3/4)."""
    ks = sorted({min(grid.n_layers - 1, int(grid.n_layers * f)) for f in (0.25, 0.5, 0.75)})
    per = []
    for k in ks:
        if part.field is not None:
            geom = field_polygons(sample_layers(part.field, grid, k, k + 1)[0], grid, part.boxed)
        else:
            geom = mesh_sections(part.mesh, grid, k, k + 1)[0]
        rs = [r for outer, holes in rings(geom) for r in [outer, *holes]]
        per.append(24 + sum(30 + 20 * len(r) for r in rs))  # "$$POLYLINE/1,d,n," and "x.xxx,y.yyy," per point
    return int(grid.n_layers * sum(per) / len(per))


def hours_minutes(seconds: float) -> str:
    """``10 h 53 min`` (rounded to the minute)."""
    m = int(round(seconds / 60))
    return f"{m // 60} h {m % 60:02d} min" if m >= 60 else f"{m} min"


def slice_to(part: Part, out, printer, pixel=None, layer=None, fmt=None, orient=None, force=False, strict=False,
             check=True, progress=None, threads=None, scheduler=None, keep_part=False, memory_limit=None) -> dict:
    """Slice ``part`` into the file ``out`` and return the report (findings in ``warnings``).

    ``scheduler``: None (a thread pool of ``threads``) or a dask scheduler spec (``local:N``,
    ``tcp://HOST:PORT``, a Client) that takes the bands of a field part (:mod:`porecad.printing.bands`).
    Before any work the slices are sized (:func:`slice_estimate`) and refused past the memory available
    or ``memory_limit`` (bytes), or past :data:`porecad.resources.MAX_SAMPLES` pixels.
    """
    from ..resources import announce_time, require_fits
    t0 = time.perf_counter()
    threads = min(2, os.cpu_count() or 1) if threads is None else int(threads)
    pixel, pixel_y = pixel_sizes(printer, pixel)
    layer = check_size("the layer height", printer.layer if layer is None else layer)
    fmt = format_of(out, fmt, printer.format)
    est = slice_estimate(part, pixel, layer, orient, threads, pixel_y, printer if check else None)
    size = f"{est['layer_pixels']:.3g} pixels a layer x {est['layers']:.3g} layers"
    require_fits(est, memory_limit, f"{size}: use a larger `pixel` or `layer` height", "slicing this part")
    announce_time(est, f"slicing this part ({size})")
    report = {"printer": printer.as_dict(), "route": part.route, "format": fmt}
    if orient is not None:
        R = orientation(part, printer, orient, min(pixel, pixel_y), layer, report)
        part = part.rotated(R)
        report["rotation"] = R.round(9).tolist()
    _fit(part, printer)
    grid = LayerGrid.around(part.lo, part.hi, pixel, layer, pixel_y)
    if fmt == "cli-auto":
        report["cli_ascii_bytes"] = cli_ascii_bytes(part, grid)
        fmt = report["format"] = "cli-binary" if report["cli_ascii_bytes"] > CLI_ASCII_MAX_BYTES else "cli"
    manifest = slices_manifest(part, grid, printer, fmt, report.get("rotation"))
    islands = pr.IslandTracker(grid, min_area=4 * pixel * pixel_y)
    areas = []
    findings = []
    w = writer(out, fmt, manifest, force)
    with w:
        if scheduler is not None and part.field is not None:
            from ..scale import open_scheduler
            from .bands import scheduled_layers
            stream = ((k, None, None, area, None, payload, found) for k, area, payload, found in
                      scheduled_layers(part, grid, fmt, manifest, w.needs == "polygons", open_scheduler(scheduler)))
        else:
            stream = layers(part, grid, w.needs == "polygons", w.encode, threads)
        for k, grey, solid, area, geom, payload, found in stream:
            w.add(k, payload)
            islands.add(k, found)
            areas.append(area)
            if progress is not None and ((k + 1) % 32 == 0 or k + 1 == grid.n_layers):
                progress("slices", k + 1, grid.n_layers)
        report["seconds_slices"] = round(time.perf_counter() - t0, 3)
        findings += islands.findings()
        if check:
            g = check_grid(part, printer, min(pixel, pixel_y), pr.MAX_CHECK_VOXELS)
            more, info = pr.check_layers(model_layers(part, g), (g.n_layers, g.ny, g.nx), g.lo, g.pixel, printer,
                                         min(pixel, pixel_y), progress)
            findings += more
            v, f = proxy_mesh(part, None if part.mesh is not None else check_model(part, printer, min(pixel, pixel_y)))
            report["overhangs"] = pr.overhangs(v, f, printer.max_overhang, float(part.lo[2]) + layer)
            if report["overhangs"]["unsupported_area"] > 0:
                a = report["overhangs"]["unsupported_area"]
                findings.append(pr.Finding("unsupported-overhang", f"{a:.3g} mm² of down-facing surface is steeper "
                                           f"than the printer's {printer.max_overhang:g}° overhang and needs supports",
                                           {"area": a, "max_overhang": printer.max_overhang}))
            report["checks"] = info
        report["mid_air_starts"] = islands.starts
        if strict and findings:
            raise InputError(f"the part is not printable on {printer.name}: {findings[0].message} "
                             f"({len(findings)} finding{'s' if len(findings) > 1 else ''}; nothing written)")
    report.update({"slices": str(out), "layers": grid.n_layers, "image": [grid.nx, grid.ny], "pixel": pixel,
                   "pixel_x": pixel, "pixel_y": pixel_y, "layer": layer, "height": grid.height,
                   "print_time_s": grid.n_layers * printer.layer_time,
                   "print_time": hours_minutes(grid.n_layers * printer.layer_time),
                   "layer_area": [round(a, 6) for a in areas], "manifest": {k: v for k, v in manifest.items()
                                                                              if k != "recipe"},
                   "warnings": findings, "seconds": round(time.perf_counter() - t0, 3)})
    if keep_part:  # the part as printed (turned), for a mesh export
        report["part"] = part
    return report


def slices_manifest(part: Part, grid: LayerGrid, printer, fmt: str, rotation=None) -> dict:
    """The manifest the writers take: the grid, the plate (:func:`placement`), the printer, the recipe.

    A ``.sl1`` for a printer with a display is that display's canvas, so it needs the display's pixel."""
    manifest = {"porecad": "slices", **grid.manifest(), "plate": placement(grid, printer), "printer": printer.name,
                "printer_profile": printer.as_dict(), "route": part.route, "recipe": part.recipe}
    if rotation is not None:
        manifest["rotation"] = rotation
    if fmt == "sl1" and printer.has_display and "display" not in manifest["plate"]:
        raise InputError(f"a .sl1 for {printer.name} is its display's canvas: slice at the display's pixel "
                         f"({printer.pixel_x:g} x {printer.pixel_y:g} mm), not {grid.px:g} x {grid.py:g} mm")
    return manifest


def pixel_sizes(printer, pixel=None) -> tuple:
    """``(x, y)`` pixel (mm, whole nm): the profile's ``pixel_x`` and ``pixel_y``, or ``pixel`` (a number: both;
    a pair: x and y) when given."""
    if pixel is None:
        pair = (printer.pixel_x, printer.pixel_y)
    elif isinstance(pixel, (tuple, list)) and len(pixel) == 2:
        pair = tuple(pixel)
    else:
        pair = (pixel, pixel)
    if pair[0] is pair[1] or pair[0] == pair[1]:
        v = check_size("the pixel", pair[0])
        return v, v
    return check_size("the pixel in x", pair[0]), check_size("the pixel in y", pair[1])


def orientation(part: Part, printer, orient, pixel, layer, report) -> np.ndarray:
    """The rotation of ``orient``: "auto" (least unsupported area, then least height) or a direction [x, y, z]."""
    if isinstance(orient, str):
        if orient != "auto":
            raise InputError(f"orient must be 'auto' or a direction x,y,z, got {orient!r}")
        v, f = proxy_mesh(part, check_model(part, printer, pixel) if part.mesh is None else None)
        ranking = rank_orientations(v, f, printer, layer)
        report["orientation"] = {"chosen": ranking[0]["direction"], "ranking": ranking}
        return rotation_to_z(ranking[0]["direction"])
    d = np.asarray(orient, dtype=float)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
        raise InputError(f"orient must be 'auto' or a direction x,y,z, got {orient!r}")
    report["orientation"] = {"chosen": (d / np.linalg.norm(d)).tolist()}
    return rotation_to_z(d)
