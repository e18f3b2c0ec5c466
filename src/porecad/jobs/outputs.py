"""Outputs shared by the jobs: the validated mesh report and the report file or directory.

A build's ``report`` output is a JSON file when its name ends in ``.json``,
else a report directory (``report.json``, ``report.html`` and PNG plots:
the full analysis of the built mesh, :func:`porecad.analysis.report.write_build_report`).
"""

from __future__ import annotations

import json


def write_report_output(path, report: dict, vertices, faces, domain_volume=None, design=None,
                        force: bool = False, field=None, domain=None, skin=None, check=None) -> None:
    """Write the build ``report`` to ``path`` (JSON file or report directory); note it in the report.

    ``domain`` is the job's design domain and ``skin`` the thickness of its
    closing shell (see :class:`porecad.jobs.contract.Result`); a report
    directory's analysis measures porosity, pore and strut sizes and
    connectivity inside that domain. ``check``: the job's validation of
    these arrays (not repeated).
    """
    from ..analysis.report import is_report_dir, write_build_report
    from ..io import atomic_write
    from ..io.jsonable import json_default
    if is_report_dir(path):
        from .contract import DeferredDomain
        report["report_dir"] = str(path)
        if isinstance(domain, DeferredDomain):
            domain = domain.resolve()
        write_build_report(path, vertices, faces, report, domain_volume=domain_volume, design=design,
                           force=force, field=field, domain=domain, skin=skin, check=check)
        return
    with atomic_write(path, force=force) as fh:
        fh.write((json.dumps(report, indent=1, default=json_default) + "\n").encode())
    report["report_file"] = str(path)


def validated_report(vertices, faces, domain_volume=None, check_intersections=False, solid=True,
                     what="the solid", self_intersections: int | None = None,
                     hint: str = "") -> tuple[dict, dict, object]:
    """Check a mesh before it is written and return ``(mesh report, check, vertices)``.

    A solid must be closed, manifold, consistently and outward oriented (else
    an internal error: nothing is written); with ``check_intersections`` it
    must also be free of self-intersections (``self_intersections`` is then
    in the report). A caller that has just counted the self-intersecting
    pairs of exactly these vertices and faces passes the count as
    ``self_intersections`` and the search is not repeated. ``hint`` (what
    may avoid the self-intersections) joins the refusal's message.

    The mesh is checked as it will be stored (float32 coordinates,
    :func:`~porecad.mesh.validate.stored_coordinates`; a :class:`Result`
    rounds its vertices the same way): a count made on other coordinates is
    not trusted. The returned ``vertices`` are those checked: the job
    measures and writes them.
    """
    from ..analysis.basic import mesh_report
    from ..errors import MeshError
    from ..mesh.validate import check_solid, stored_with
    if len(faces) == 0:  # settings that leave no material (a threshold past the field's range, ...)
        raise MeshError(f"{what} is empty: the settings leave no material; nothing written")
    unrounded = vertices
    vertices, self_intersections = stored_with(vertices, self_intersections)
    known = check_intersections and solid and self_intersections is not None
    chk = check_solid(vertices, faces, check_self_intersections=check_intersections and solid and not known)
    if known:
        chk["self_intersections"] = int(self_intersections)
    report = mesh_report(vertices, faces, domain_volume=domain_volume, solid=solid, check=chk)
    if solid:
        if not (chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"]):
            _refuse_unstorable(unrounded, faces, what)
            raise MeshError(f"internal error: {what} failed validation ({chk}); nothing written")
        if check_intersections:
            report["self_intersections"] = int(chk["self_intersections"])
            if chk["self_intersections"]:
                raise MeshError(f"{what} has {chk['self_intersections']} self-intersecting face pairs"
                                f"{' (' + hint + ')' if hint else ''}; nothing written")
    return report, chk, vertices


def _refuse_unstorable(vertices, faces, what: str) -> None:
    """InputError when only the rounding to the files' float32 coordinates spoils the solid (a design too fine
    for how far it lies from the origin), so that settings within their bounds never end in an internal error."""
    import numpy as np

    from ..errors import InputError
    from ..mesh.validate import check_solid
    v = np.asarray(vertices, dtype=np.float64)
    chk = check_solid(v, faces, check_self_intersections=False)
    if v.size and chk["closed"] and chk["manifold"] and chk["oriented"] and chk["outward"]:
        far = float(np.abs(v).max())
        raise InputError(f"{what} is too fine to store: mesh files hold single-precision coordinates, which "
                         f"{far:.3g} mm from the origin are {float(np.spacing(np.float32(far))):.2g} mm apart; "
                         "move the design nearer the origin or make its cells larger")
