"""3D Slicer's exchange files for vessels: markups in, a centreline model and a labelmap out (issue 55).

* :func:`read_markups`: a ``.mrk.json`` markups file (Slicer ≥ 4.11) —
  fiducial lists (``Fiducial``) and curves (``Curve``, ``ClosedCurve``,
  ``Line``), each point ``controlPoints[].position`` in the markup's own
  ``coordinateSystem`` (``LPS`` or ``RAS``; Slicer writes LPS by default).
  Returned as the file gives them, with that frame.
* :func:`write_centreline_vtp`: polylines with the point array
  ``MaximumInscribedSphereRadius`` (VMTK's, which SlicerVMTK reads) and the
  field-data string ``SPACE`` = ``LPS`` or ``RAS`` as Slicer's model storage
  writes it, so Slicer places the model without asking.
* :func:`write_labelmap_nrrd`: a ``uint8`` labelmap on an image's own grid
  (``space: left-posterior-superior``, ``space directions``, ``space
  origin``, gzip), which opens over that image in Slicer (as a
  segmentation when named ``.seg.nrrd``).

Every file is written atomically (:func:`porecad.io.atomic.atomic_write`).
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from .atomic import atomic_write

#: markup types read as point lists
POINT_TYPES = ("Fiducial", "Curve", "ClosedCurve", "Line")
#: largest markups file read (bytes)
MAX_MARKUPS_BYTES = 64 << 20


def read_markups(path) -> tuple[list, str]:
    """The markups of a ``.mrk.json`` file: ``([(type, points (k, 3) mm), ...], frame)``.

    ``frame`` is the (first) markup's coordinate system, ``"lps"`` or ``"ras"``.
    """
    from .bounded import check_file_size
    from .confine import regular_file
    p = Path(path)
    regular_file(p, "a markups file")
    check_file_size(p, MAX_MARKUPS_BYTES, "a markups file")
    try:
        d = json.loads(p.read_bytes().decode("utf-8"))
        marks = d["markups"]
        out, frames = [], []
        for m in marks:
            if m.get("type") not in POINT_TYPES:
                continue
            frame = str(m.get("coordinateSystem", "LPS")).upper()
            if frame not in ("LPS", "RAS"):
                raise InputError(f"{p}: markup coordinate system {frame!r} is not LPS or RAS")
            P = np.asarray([c["position"] for c in m.get("controlPoints", [])], float).reshape(-1, 3)
            if not np.all(np.isfinite(P)) or np.any(np.abs(P) > 1e8):
                raise InputError(f"{p}: markup positions must be finite numbers (mm)")
            if len(P):
                out.append((m["type"], P))
                frames.append(frame.lower())
    except InputError:
        raise
    except (ValueError, KeyError, TypeError, AttributeError, UnicodeDecodeError) as exc:
        from .bounded import failure_reason
        raise InputError(f"{p}: not a 3D Slicer markups file ({failure_reason(exc)})") from None
    if not out:
        raise InputError(f"{p}: no markup points (fiducials or a curve) in the file")
    if len(set(frames)) > 1:
        raise InputError(f"{p}: its markups mix the LPS and RAS coordinate systems")
    return out, frames[0]


def _array(name, dtype, values, ncomp=1) -> str:
    flat = " ".join(repr(float(v)) if dtype.startswith("Float") else str(int(v)) for v in np.ravel(values))
    return (f'<DataArray type="{dtype}" Name="{name}" NumberOfComponents="{ncomp}" format="ascii">'
            f"{flat}</DataArray>")


def write_centreline_vtp(path, chains, points, radii, frame, force: bool = False) -> None:
    """Polylines ``chains`` (node-index lists) over ``points`` (in ``frame``: LPS, RAS or None) with radii."""
    conn = np.concatenate([np.asarray(c, np.int64) for c in chains])
    offs = np.cumsum([len(c) for c in chains])
    space = "" if not frame else (  # 3D Slicer's coordinate system of a model (omitted when unknown)
        '<FieldData><Array type="String" Name="SPACE" NumberOfTuples="1" format="ascii">'
        + " ".join(str(ord(ch)) for ch in frame.upper()) + " 0</Array></FieldData>\n")
    xml = ('<?xml version="1.0"?>\n<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">\n'
           f'<PolyData>\n{space}'
           f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" NumberOfLines="{len(chains)}" '
           'NumberOfStrips="0" NumberOfPolys="0">\n'
           f'<PointData Scalars="MaximumInscribedSphereRadius">'
           f'{_array("MaximumInscribedSphereRadius", "Float64", radii)}</PointData>\n'
           f'<Points>{_array("Points", "Float64", points, 3)}</Points>\n'
           f'<Lines>{_array("connectivity", "Int64", conn)}{_array("offsets", "Int64", offs)}</Lines>\n'
           '</Piece>\n</PolyData>\n</VTKFile>\n')
    with atomic_write(path, force=force) as fh:
        fh.write(xml.encode("ascii"))


def write_labelmap_nrrd(path, labels, spacing, origin, direction, force: bool = False) -> None:
    """``labels [i, j, k]`` (uint8) as a gzip NRRD in LPS on the grid ``origin + D (i, j, k) h``."""
    h = np.asarray(spacing, float)
    D = np.asarray(direction, float).reshape(3, 3)
    vec = lambda v: "(" + ",".join(repr(float(x)) for x in v) + ")"  # noqa: E731
    head = ("NRRD0004\n# Complete NRRD file format specification at:\n"
            "# http://teem.sourceforge.net/nrrd/format.html\n"
            "type: unsigned char\ndimension: 3\nspace: left-posterior-superior\n"
            f"sizes: {' '.join(str(int(n)) for n in labels.shape)}\n"
            f"space directions: {' '.join(vec(D[:, a] * h[a]) for a in range(3))}\n"
            "kinds: domain domain domain\nendian: little\nencoding: gzip\n"
            f"space origin: {vec(origin)}\n\n")
    data = gzip.compress(np.asarray(labels, np.uint8).ravel(order="F").tobytes(), compresslevel=6, mtime=0)
    with atomic_write(path, force=force) as fh:
        fh.write(head.encode("ascii"))
        fh.write(data)
