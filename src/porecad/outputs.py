"""Outputs shared by the build jobs: checking output paths up front and writing the report.

A build's ``report`` output is a JSON file when its name ends in ``.json``,
else a report directory (``report.json``, ``report.html`` and PNG plots:
the full analysis of the built mesh, :func:`porecad.analysis.report.write_build_report`).
"""

from __future__ import annotations

import json


def check_outputs(out: dict, keys, force: bool) -> None:
    """Refuse existing outputs (without ``force``) before any work is done."""
    from .analysis.report import check_report_dir, is_report_dir
    from .io import check_output_path
    for key in keys:
        if not out.get(key):
            continue
        if key == "report" and is_report_dir(out[key]):
            check_report_dir(out[key], force=force, design=True)
        else:
            check_output_path(out[key], force=force)


def write_report_output(path, report: dict, vertices, faces, domain_volume=None, design=None,
                        force: bool = False, field=None) -> None:
    """Write the build ``report`` to ``path`` (JSON file or report directory); note it in the report."""
    from .analysis.report import is_report_dir, write_build_report
    from .io import atomic_write
    from .pipeline import _json_default
    if is_report_dir(path):
        report["report_dir"] = str(path)
        write_build_report(path, vertices, faces, report, domain_volume=domain_volume, design=design,
                           force=force, field=field)
        return
    with atomic_write(path, force=force) as fh:
        fh.write((json.dumps(report, indent=1, default=_json_default) + "\n").encode())
    report["report_file"] = str(path)


def validated_report(vertices, faces, domain_volume=None, check_intersections=False, solid=True,
                     what="the solid", self_intersections: int | None = None) -> tuple[dict, dict]:
    """Check a mesh before it is written and return ``(mesh report, check)``.

    A solid must be closed, manifold, consistently and outward oriented (else
    an internal error: nothing is written); with ``check_intersections`` it
    must also be free of self-intersections (``self_intersections`` is then
    in the report). A caller that has just counted the self-intersecting
    pairs of exactly these vertices and faces passes the count as
    ``self_intersections`` and the search is not repeated.
    """
    from .analysis.basic import mesh_report
    from .errors import MeshError
    from .mesh.validate import check_solid
    known = check_intersections and solid and self_intersections is not None
    chk = check_solid(vertices, faces, check_self_intersections=check_intersections and solid and not known)
    if known:
        chk["self_intersections"] = int(self_intersections)
    report = mesh_report(vertices, faces, domain_volume=domain_volume, solid=solid, check=chk)
    if solid:
        if not (chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"]):
            raise MeshError(f"internal error: {what} failed validation ({chk}); nothing written")
        if check_intersections:
            report["self_intersections"] = int(chk["self_intersections"])
            if chk["self_intersections"]:
                raise MeshError(f"{what} has {chk['self_intersections']} self-intersecting face pairs; "
                                "nothing written")
    return report, chk


def finish_job(report: dict, vertices, faces, out: dict, force: bool, timings: dict, t0: float,
               domain_volume=None, design=None, field=None) -> dict:
    """Write the mesh and the report of a validated build; record the times. Returns the report."""
    import time

    from .io import write_mesh
    if out.get("mesh"):
        t = time.perf_counter()
        write_mesh(out["mesh"], vertices, faces, force=force)
        timings["write_s"] = time.perf_counter() - t
        report["mesh_file"] = str(out["mesh"])
    timings["total_s"] = time.perf_counter() - t0
    report["timings"] = timings
    if out.get("report"):
        write_report_output(out["report"], report, vertices, faces, domain_volume=domain_volume, design=design,
                            force=force, field=field)
    return report
