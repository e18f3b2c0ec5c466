"""Polygonise on a scheduler: into memory, or streamed to a mesh file with a streamed check.

Both functions run :func:`porecad.scale.run.run_chunks`; they differ in what
happens to the welded slabs. :func:`collect_mesh` concatenates them (the
result equals :func:`porecad.mesh.polygonise.polygonise`); :func:`stream_mesh`
writes them to a file as they arrive (:mod:`porecad.io.stream_mesh`) and
checks the solid on the way (:mod:`porecad.mesh.stream_check`), so memory is
bounded by the chunks in flight, not by the mesh.
"""

from __future__ import annotations

import numpy as np

from ..errors import MeshError
from ..mesh.stream_check import SlabWindow, StreamedSolidCheck
from .run import run_chunks


def collect_mesh(job, scheduler, retries: int = 2, progress=None, window=None):
    """Run ``job`` and return ``(vertices, faces, stats)`` in memory."""
    verts, faces = [], []

    def consume(slab):
        verts.append(slab.vertices)
        faces.append(slab.faces)

    stats = run_chunks(job, scheduler, consume, retries=retries, window=window, progress=progress)
    v = np.concatenate(verts) if verts else np.zeros((0, 3))
    f = np.concatenate(faces) if faces else np.zeros((0, 3), dtype=np.int32)
    return v, f, stats


def stream_mesh(job, scheduler, path=None, force: bool = False, solid: bool = True, retries: int = 2,
                progress=None, expected_bytes: int = 0, centre=(0.0, 0.0, 0.0), window=None,
                keep_fraction: float | None = None):
    """Run ``job``, streaming the mesh to ``path`` (.stl/.ply; None: check only).

    The file appears only if every chunk succeeded, the mesh is not empty and,
    for a ``solid``, the streamed check passed (closed, edge-manifold,
    oriented, outward); otherwise :class:`~porecad.errors.MeshError` or
    :class:`~porecad.scale.run.ChunkError` is raised and nothing is left.
    With ``keep_fraction`` an STL is written without its islands: the pieces
    besides the largest one and those of at least ``keep_fraction`` of its
    volume are dropped (the check's figures are then those of the file).

    Returns
    -------
    check : dict
        :meth:`porecad.mesh.stream_check.StreamedSolidCheck.result`.
    stats : dict
        :func:`porecad.scale.run.run_chunks` statistics.
    """
    from ..io.stream_mesh import StreamedMeshWriter
    window_ = SlabWindow()
    check = StreamedSolidCheck(centre)
    drop = keep_fraction is not None and solid
    writer = StreamedMeshWriter(path, force=force, expected_bytes=expected_bytes, drop=drop) if path else None

    def consume(slab):
        pos, faces = window_.local(slab)
        check.add(slab, pos, faces)
        if writer is not None:
            writer.add(slab, pos, faces, check.pieces.face_ids)
        window_.advance(slab)

    if writer is None:
        stats = run_chunks(job, scheduler, consume, retries=retries, window=window, progress=progress)
        chk = _verified(check.result(), solid)
        chk["meshed_volume"] = chk["volume"]
        return chk, stats
    with writer:
        stats = run_chunks(job, scheduler, consume, retries=retries, window=window, progress=progress)
        chk = _verified(check.result(), solid)
        chk["meshed_volume"] = chk["volume"]  # all that was meshed, before any piece is dropped
        if not writer.drop:
            writer.close()
            return chk, stats
        keep = check.pieces.kept(keep_fraction)
        writer.close(keep)
    chk.update(check.pieces.dropped(keep), **writer.kept)
    return chk, stats


def _verified(chk: dict, solid: bool) -> dict:
    if chk["triangles"] == 0:
        raise MeshError("the structure is empty on this grid: nothing to write")
    if solid and not (chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"]):
        raise MeshError(f"internal error: the solid failed the streamed validation ({chk['open_edges']} open "
                        f"edges, {chk['duplicate_edges']} duplicate edges, volume {chk['volume']:.6g}); "
                        "nothing written")
    return chk


def streamed_mesh_report(chk: dict, domain_volume=None, solid: bool = True) -> dict:
    """The mesh part of the report (keys as :func:`porecad.analysis.basic.mesh_report`) from a streamed check."""
    area = chk["area"]
    out = {"triangles": chk["triangles"], "vertices": chk["vertices"], "surface_area": area,
           "closed": chk["closed"], "manifold": chk["manifold"], "oriented": chk["oriented"],
           "check": chk["check"]}
    from ..analysis.basic import volume_metrics
    out.update(volume_metrics(area, chk["volume"] if solid and chk["closed"] else None, domain_volume))
    if chk.get("bounds") is not None:
        out["bounds"] = chk["bounds"]
    if solid and "islands_dropped" in chk:  # dropped while writing: the figures are the file's
        out.update({k: chk[k] for k in ("pieces", "islands_dropped", "islands_volume_fraction")})
    elif solid and chk.get("pieces_volume"):  # a streamed file kept its loose pieces: counted, not dropped
        out.update(pieces=chk["pieces"], islands_dropped=0,
                   islands_volume_fraction=1.0 - chk["largest_volume"] / chk["pieces_volume"])
    return out
