"""Centreline readers: VMTK/VTK XML PolyData (``.vtp``), SWC and porecad's JSON.

All readers return a validated-shape :class:`~porecad.vessels.graph.CentrelineGraph`
(call :meth:`validate` for the checks). Units are those of the file (mm expected).

``.vtp``
    VTK XML PolyData as VMTK writes centrelines: polylines (``<Lines>``) with a
    point-data array of radii, ``MaximumInscribedSphereRadius`` by default
    (``Radius``/``radius`` accepted). DataArrays may be ``ascii``, ``binary``
    (base64, with the UInt32/UInt64 block header, optionally
    ``vtkZLibDataCompressor``-compressed) or ``appended`` (raw or base64
    ``AppendedData``). No VTK installation is needed.
    VMTK's raw centrelines are one polyline per inlet→outlet path, so shared
    trunks are traced several times: points of later polylines lying within
    ``overlap`` × radius of an earlier polyline are dropped and the remaining
    run is joined to the nearest earlier node (``merge_overlaps=True``).
``.swc``
    ``id type x y z radius parent`` per line, ``#`` comments, parent ``-1`` for roots.
``.json``
    ``{"format": "porecad-centreline", "units": "mm", "points": [[x, y, z], ...],
    "radii": [r, ...], "edges": [[i, j], ...]}`` (0-based node indices), or
    ``"polylines": [{"points": [[x, y, z], ...], "radii": [...]}, ...]`` whose
    coincident end points are joined. See ``docs/vessels.md``.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np

from ..errors import InputError
from .graph import CentrelineGraph, from_polylines

RADIUS_NAMES = ("MaximumInscribedSphereRadius", "Radius", "radius", "Radii")
#: most centreline points accepted: the blends, segment fits and self-intersection checks of the vessel job
#: grow with them (VMTK centrelines have hundreds to a few thousand points)
MAX_CENTRELINE_POINTS = 20_000
#: largest SWC or JSON centreline read (bytes; a 1-million-point centreline is about 60 MB)
MAX_TEXT_BYTES = 256 << 20
#: the radius given to a markups curve's points (mm): it only bounds the image's search for the wall (3 r)
MARKUP_RADIUS = 10.0


def read_centreline(path, radius_array: str | None = None, merge_overlaps: bool = True) -> CentrelineGraph:
    """Read a centreline file by suffix (``.vtp``, ``.swc``, ``.json``)."""
    from ..io.bounded import check_file_size
    from ..io.confine import regular_file
    p = Path(os.fspath(path))
    regular_file(p, "a centreline")
    suffix = p.suffix.lower()
    if p.name.lower().endswith(".mrk.json"):
        return _bounded(read_markups_curve(p), p)
    if suffix in (".swc", ".json"):
        check_file_size(p, MAX_TEXT_BYTES, f"a {suffix[1:]} centreline")
    try:
        if suffix == ".vtp":
            return _bounded(read_vtp(p, radius_array=radius_array, merge_overlaps=merge_overlaps), p)
        if suffix == ".swc":
            return _bounded(read_swc(p), p)
        if suffix == ".json":
            return _bounded(read_json(p), p)
    except InputError:
        raise
    except (ValueError, KeyError, TypeError, IndexError, struct.error, UnicodeDecodeError, OverflowError,
            RecursionError, MemoryError, AttributeError) as exc:
        from ..io.bounded import failure_reason
        raise InputError(f"{p}: not a valid {suffix[1:]} centreline ({failure_reason(exc)})") from None
    raise InputError(f"{p}: unknown centreline format {suffix!r}; use .vtp, .swc or .json (or an `image`)")


def _bounded(graph: CentrelineGraph, p) -> CentrelineGraph:
    """Refuse a centreline with more than :data:`MAX_CENTRELINE_POINTS` nodes (before any geometry work)."""
    n = len(graph.points)
    if n > MAX_CENTRELINE_POINTS:
        from ..errors import ResourceError
        raise ResourceError(f"{p}: {n:,} centreline points (at most {MAX_CENTRELINE_POINTS:,}); resample the "
                            "centreline (a point every radius or so is enough)")
    P, R = np.asarray(graph.points, dtype=float), np.asarray(graph.radii, dtype=float)
    E = np.asarray(graph.edges)
    if not (np.all(np.isfinite(P)) and np.all(np.abs(P) <= 1e8)):
        raise InputError(f"{p}: centreline coordinates must be finite and within 1e8 mm")
    if len(R) == len(P) and not (np.all(np.isfinite(R)) and np.all(np.abs(R) <= 1e6)):
        raise InputError(f"{p}: centreline radii must be finite and at most 1e6 mm")
    if E.size and (E.min() < 0 or E.max() >= len(P)):
        raise InputError(f"{p}: a centreline edge refers to a point that does not exist")
    return graph


# ---------------------------------------------------------------------- JSON
def read_json(path) -> CentrelineGraph:
    src = str(path)
    text = Path(path).read_bytes().decode("utf-8")
    d = json.loads(text)
    if not isinstance(d, dict):
        raise InputError(f"{src}: a centreline JSON file holds one object")
    if "polylines" in d:
        lines = d["polylines"]
        if not lines:
            raise InputError(f"{src}: the centreline graph is empty")
        pts = [np.asarray(l["points"], dtype=float) for l in lines]
        rad = [np.asarray(l["radii"], dtype=float) for l in lines]
        for k, (p, r) in enumerate(zip(pts, rad)):
            if p.ndim != 2 or p.shape[1] != 3 or len(r) != len(p):
                raise InputError(f"{src}: polyline {k} needs points (M, 3) and M radii")
        return from_polylines(pts, rad, source=src)
    for key in ("points", "radii", "edges"):
        if key not in d:
            raise InputError(f"{src}: missing {key!r} (see docs/vessels.md for the JSON centreline format)")
    P = np.asarray(d["points"], dtype=float)
    R = np.asarray(d["radii"], dtype=float)
    E = np.asarray(d["edges"], dtype=np.int64)
    if P.size and (P.ndim != 2 or P.shape[1] != 3):
        raise InputError(f"{src}: points must be a list of [x, y, z]")
    if E.size and (E.ndim != 2 or E.shape[1] != 2):
        raise InputError(f"{src}: edges must be a list of [i, j]")
    return CentrelineGraph(P, R, E, source=src)


def read_markups_curve(path) -> CentrelineGraph:
    """A 3D Slicer curve (``.mrk.json``) as a centreline: no radii (an image gives them), its frame kept."""
    from ..io.slicer import read_markups
    marks, frame = read_markups(path)
    curves = [P for kind, P in marks if kind != "Fiducial" and len(P) >= 2]
    if not curves:
        raise InputError(f"{path}: no curve in the markups file (fiducials are seeds: give them as `seeds`)")
    g = from_polylines(curves, [np.full(len(P), MARKUP_RADIUS) for P in curves], source=str(path))
    g.info.update(frame=frame, radii_given=False)
    return g


def write_json(path, graph: CentrelineGraph) -> None:
    """Write a graph in the JSON centreline format."""
    Path(path).write_text(json.dumps({"format": "porecad-centreline", "units": "mm",
                                      "points": graph.points.tolist(), "radii": graph.radii.tolist(),
                                      "edges": graph.edges.tolist()}))


# ---------------------------------------------------------------------- SWC
def read_swc(path) -> CentrelineGraph:
    src = str(path)
    rows = []
    for lineno, line in enumerate(Path(path).read_bytes().decode("utf-8").splitlines(), 1):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = s.split()
        if len(parts) < 7:
            raise InputError(f"{src}: line {lineno}: SWC lines need 7 fields (id type x y z radius parent)")
        try:
            rows.append([float(v) for v in parts[:7]])
        except ValueError:
            raise InputError(f"{src}: line {lineno}: an SWC field is not a number") from None
    if not rows:
        raise InputError(f"{src}: the centreline graph is empty")
    a = np.asarray(rows)
    ids = a[:, 0].astype(np.int64)
    index = {int(i): k for k, i in enumerate(ids)}
    if len(index) != len(ids):
        raise InputError(f"{src}: duplicate SWC node ids")
    edges = []
    for k, par in enumerate(a[:, 6].astype(np.int64)):
        if par == -1:
            continue
        if int(par) not in index:
            raise InputError(f"{src}: node {ids[k]} has unknown parent {par}")
        edges.append((index[int(par)], k))
    return CentrelineGraph(a[:, 2:5], a[:, 5], np.asarray(edges, dtype=np.int64).reshape(-1, 2), source=src)


# ---------------------------------------------------------------------- VTP
def read_vtp(path, radius_array: str | None = None, merge_overlaps: bool = True,
             overlap: float = 0.5) -> CentrelineGraph:
    """VTK XML PolyData polylines with a radius array (parsed by :mod:`porecad.io.vtk_xml`: bounded, no DTD)."""
    from ..io.vtk_xml import data_array, read_vtk_xml
    src = str(path)
    vf = read_vtk_xml(path)
    root = vf.root
    if root.get("type") != "PolyData":
        raise InputError(f"{src}: not a VTK XML PolyData file")

    def array(el) -> np.ndarray:
        return data_array(vf, el)

    pieces = root.findall("./PolyData/Piece")
    if not pieces:
        raise InputError(f"{src}: no PolyData piece")
    polylines, radii = [], []
    for piece in pieces:
        npts = int(piece.get("NumberOfPoints", 0))
        if npts == 0:
            continue
        pel = piece.find("./Points/DataArray")
        if pel is None:
            raise InputError(f"{src}: no Points array")
        P = np.asarray(array(pel), dtype=float).reshape(-1, 3)
        rel = None
        names = (radius_array,) if radius_array else RADIUS_NAMES
        for el in piece.findall("./PointData/DataArray"):
            if el.get("Name") in names:
                rel = el
                break
        if rel is None:
            raise InputError(f"{src}: no point-data radius array "
                             f"({radius_array or 'MaximumInscribedSphereRadius'}) in the centreline")
        R = np.asarray(array(rel), dtype=float).reshape(-1)
        if len(P) != npts or len(R) != npts:
            raise InputError(f"{src}: {npts} points declared but {len(P)} points / {len(R)} radii read")
        conn = piece.find("./Lines/DataArray[@Name='connectivity']")
        offs = piece.find("./Lines/DataArray[@Name='offsets']")
        if conn is None or offs is None:
            raise InputError(f"{src}: the centreline has no polylines (<Lines>)")
        C = np.asarray(array(conn), dtype=np.int64)
        O = np.asarray(array(offs), dtype=np.int64)
        prev = 0
        for o in O:
            ids = C[prev:o]
            prev = o
            if len(ids) >= 2:
                if np.any(ids < 0) or np.any(ids >= npts):
                    raise InputError(f"{src}: a polyline refers to a point that does not exist")
                polylines.append(P[ids])
                radii.append(R[ids])
    if not polylines:
        raise InputError(f"{src}: the centreline graph is empty (no polylines)")
    cells = len(polylines)
    if merge_overlaps and len(polylines) > 1:
        polylines, radii = merge_overlapping(polylines, radii, overlap)
    g = from_polylines(polylines, radii, source=src)
    g.info.update(cells=cells, polylines=len(polylines))
    space = root.find("./PolyData/FieldData/Array[@Name='SPACE']")
    if space is not None and space.get("format") == "ascii":  # 3D Slicer's coordinate system of a model
        name = "".join(chr(int(c)) for c in (space.text or "").split() if c.isdigit() and 0 < int(c) < 128)
        if name.lower() in ("lps", "ras"):
            g.info["frame"] = name.lower()
    return g


def merge_overlapping(polylines, radii, overlap: float = 0.5):
    """Drop re-traced parts of later polylines (VMTK path centrelines share their trunk).

    A point of polyline k is *covered* when it lies within ``overlap * r`` of a
    point of an earlier (kept) polyline. Maximal uncovered runs are kept; a run
    that starts or ends next to a covered point is joined to the nearest kept
    earlier point, so the result is a tree of polylines.
    """
    from scipy.spatial import cKDTree
    out_p = [np.asarray(polylines[0], float)]
    out_r = [np.asarray(radii[0], float)]
    for P, R in zip(polylines[1:], radii[1:]):
        P = np.asarray(P, float)
        R = np.asarray(R, float)
        kept = np.concatenate(out_p)
        kept_r = np.concatenate(out_r)
        tree = cKDTree(kept)
        d, idx = tree.query(P)
        covered = d <= overlap * np.maximum(R, 1e-12)
        if not np.any(covered):
            out_p.append(P)
            out_r.append(R)
            continue
        k = 0
        n = len(P)
        while k < n:
            if covered[k]:
                k += 1
                continue
            j = k
            while j < n and not covered[j]:
                j += 1
            run_p, run_r = [P[k:j]], [R[k:j]]
            if k > 0:  # join to the kept point nearest the covered neighbour
                run_p.insert(0, kept[idx[k - 1]][None])
                run_r.insert(0, kept_r[idx[k - 1]][None])
            if j < n:
                run_p.append(kept[idx[j]][None])
                run_r.append(kept_r[idx[j]][None])
            rp, rr = np.concatenate(run_p), np.concatenate(run_r)
            if len(rp) >= 2:
                out_p.append(rp)
                out_r.append(rr)
            k = j
    return out_p, out_r
