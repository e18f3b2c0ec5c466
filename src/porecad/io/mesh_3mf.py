"""Reading 3MF packages: the model part, its meshes, components and build items (bounded, no DTD).

A 3MF file is a zip package whose model part (XML in the 3MF core
namespace) holds mesh objects, objects made of transformed components, and
the build items that place them. :func:`read_3mf` streams the model part,
counts what the components would place before placing anything
(:data:`MAX_3MF_PLACEMENTS`, :data:`MAX_3MF_PLACED`) and returns the placed
meshes in millimetres. :func:`porecad.io.meshfiles.read_mesh` calls it for
``.3mf`` files; the writer, ``meshfiles._write_3mf``, shares the namespaces.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from porecad.io.bounded import Malformed, zip_member

__all__ = ["read_3mf", "NS_3MF", "REL_3MF", "MAX_3MF_PLACED", "MAX_3MF_PLACEMENTS"]

#: the 3MF core namespace of a model part
NS_3MF = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
#: the relationship type that points at a package's model part
REL_3MF = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
_UNIT_MM = {
    "micron": 1e-3,
    "millimeter": 1.0,
    "centimeter": 10.0,
    "inch": 25.4,
    "foot": 304.8,
    "meter": 1000.0,
}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _parse_transform(text: str | None) -> np.ndarray:
    """3MF 4x3 row-vector matrix as a 4x4 array (p' = [p 1] @ M)."""
    m = np.eye(4)
    if text:
        parts = text.split()
        if len(parts) != 12:
            raise Malformed("a 3MF transform does not hold 12 numbers")
        try:
            vals = np.array(parts, dtype=np.float64)
        except ValueError:
            raise Malformed("a 3MF transform holds something that is not a number") from None
        if not np.isfinite(vals).all():
            raise Malformed("a 3MF transform holds a non-finite number")
        m[:, :3] = vals.reshape(4, 3)
    return m


def _model_part(zf: zipfile.ZipFile) -> str:
    from porecad.io.safe_xml import parse
    names = set(zf.namelist())
    if len(names) > 10_000:
        raise Malformed(f"a 3MF package of {len(names):,} parts is not supported (at most 10,000)")
    if "_rels/.rels" in names:
        with zip_member(zf, "_rels/.rels", "3MF relationships", limit=1 << 20) as fh:
            root = parse(fh.read((1 << 20) + 1), "the 3MF relationships part")
        for rel in root.iter():
            if _local(rel.tag) == "Relationship" and rel.get("Type") == REL_3MF:
                target = rel.get("Target", "").lstrip("/")
                if target in names:
                    return target
    for name in names:
        if name.lower().endswith(".model") and name.lower().startswith("3d/"):
            return name
    raise Malformed("no 3D model part in the 3MF package")


def read_3mf(p: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (millimetres) and faces of every mesh a 3MF package's build places, concatenated.

    Takes the path of a regular file; returns ``(vertices (V, 3), faces (F, 3))`` as parsed, before
    :func:`porecad.io.meshfiles.read_mesh` tidies and merges them. Raises :class:`Malformed` for a
    package that cannot be read (never quoting it).
    """
    try:
        zf = zipfile.ZipFile(p)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, EOFError) as exc:
        raise Malformed("not a 3MF (zip) package") from exc
    with zf:
        part = _model_part(zf)
        # each model byte holds ~1/60 of a vertex; parsing keeps ~3 bytes of strings per byte
        with zip_member(zf, part, f"{p}", memory_factor=3.0) as model:
            unit, meshes, components, items = _parse_3mf_model(model, str(p))
    scale = _UNIT_MM.get(unit)
    if scale is None:
        raise Malformed(f"unknown 3MF unit (use {', '.join(_UNIT_MM)})")

    roots = items or [(oid, np.eye(4)) for oid in meshes]
    _count_placements(roots, meshes, components)

    def place(oid: str, xform: np.ndarray, out: list) -> None:
        if oid in meshes:
            v, f = meshes[oid]
            out.append((v @ xform[:3, :3] + xform[3, :3], f))
        else:
            for cid, cx in components[oid]:
                place(cid, cx @ xform, out)

    parts: list = []
    for oid, xform in roots:
        place(oid, xform, parts)
    if not parts:
        raise Malformed("no mesh objects in the 3MF model")
    offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
    v = np.concatenate([v for v, _ in parts]) * scale
    f = np.concatenate([f + o for (_, f), o in zip(parts, offsets, strict=True)])
    return v, f


#: most vertices plus triangles that a 3MF's build items and components may place
MAX_3MF_PLACED = 200_000_000
#: most mesh placements (components x instances, over every build item) a 3MF may ask for
MAX_3MF_PLACEMENTS = 100_000


def _count_placements(roots, meshes: dict, components: dict) -> None:
    """Refuse a 3MF whose components multiply into too many placements, counted before any is made.

    Each object's placement and vertex counts are computed once (memoised,
    depth-first), so ten levels of ten components cost 10 sums, not 10**10.
    """
    memo: dict[str, tuple[int, int]] = {}

    def count(oid: str, depth: int) -> tuple[int, int]:
        if oid in memo:
            return memo[oid]
        if depth > 32:
            raise Malformed("3MF components nest too deeply (cycle?)")
        if oid in meshes:
            v, f = meshes[oid]
            memo[oid] = (1, len(v) + len(f))
        elif oid in components:
            n = size = 0
            for cid, _ in components[oid]:
                a, b = count(cid, depth + 1)
                n, size = n + a, size + b
            memo[oid] = (n, size)
        else:
            raise Malformed("3MF refers to an object that does not exist")
        return memo[oid]

    n = size = 0
    for oid, _ in roots:
        a, b = count(oid, 0)
        n, size = n + a, size + b
    if n > MAX_3MF_PLACEMENTS:
        raise Malformed(f"3MF components place objects {n:,} times (at most {MAX_3MF_PLACEMENTS:,})")
    if size > MAX_3MF_PLACED:
        raise Malformed(f"3MF components repeat objects into {size:,} vertices and triangles (at most "
                        f"{MAX_3MF_PLACED:,})")

_XYZ = ("x", "y", "z")
_V123 = ("v1", "v2", "v3")


def _parse_3mf_model(stream, what: str = "3MF model"):
    """Stream-parse a 3MF model part into meshes, components and build items (bounded, no DTD)."""
    from porecad.io.safe_xml import iterparse
    unit = "millimeter"
    meshes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    components: dict[str, list[tuple[str, np.ndarray]]] = {}
    items: list[tuple[str, np.ndarray]] = []
    coords: list[str] = []
    tris: list[str] = []
    comps: list[tuple[str, np.ndarray]] = []
    for event, elem in iterparse(stream, what, events=("start", "end")):
        name = _local(elem.tag)
        if event == "start":
            if name == "model":
                unit = elem.get("unit", "millimeter")
            elif name == "object":
                coords, tris, comps = [], [], []
            continue
        if name == "vertex":
            coords.extend(elem.get(k) for k in _XYZ)
            elem.clear()
        elif name == "triangle":
            tris.extend(elem.get(k) for k in _V123)
            elem.clear()
        elif name == "component":
            comps.append((elem.get("objectid"), _parse_transform(elem.get("transform"))))
        elif name == "object":
            oid = elem.get("id")
            if None in coords or None in tris:
                raise Malformed("3MF vertex or triangle lacks a coordinate or index")
            if coords or tris:
                try:
                    v = np.array(coords, dtype=np.float64).reshape(-1, 3)
                    f = np.array(tris, dtype=np.int64).reshape(-1, 3)
                except (ValueError, OverflowError):
                    raise Malformed("a 3MF vertex coordinate or triangle index is not a number") from None
                if f.size and (f.min() < 0 or f.max() >= len(v)):
                    raise Malformed("a 3MF triangle index is out of range")
                meshes[oid] = (v, f)
            elif comps:
                components[oid] = comps
            coords, tris, comps = [], [], []
            elem.clear()
        elif name in ("vertices", "triangles"):
            elem.clear()
        elif name == "item":
            items.append((elem.get("objectid"), _parse_transform(elem.get("transform"))))
    return unit, meshes, components, items
