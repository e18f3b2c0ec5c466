"""The fields and solids of the Python API: ``pc.tpms``, ``pc.pore``, ``pc.rod``, ``pc.sheet``, the bodies.

A TPMS is an unbounded field (:func:`tpms`); a structure (:func:`pore`,
:func:`rod`, :func:`sheet`) turns it into a solid at a threshold or a
porosity; bodies (:func:`box`, :func:`sphere`, :func:`disc`,
:func:`mesh_body`) bound it, and :func:`expression` makes a grading field.
:mod:`porecad.api` exports every name here (``import porecad as pc``).
"""

from __future__ import annotations

import os

import numpy as np

from .errors import InputError

__all__ = ["tpms", "pore", "rod", "sheet", "box", "sphere", "disc", "mesh_body", "expression"]


def tpms(type: str, cell_size=1.0, origin=(0.0, 0.0, 0.0)):  # noqa: A002 - the TPMS "type" is the domain word
    """A triply periodic minimal surface field (unbounded).

    Parameters
    ----------
    type : str
        Catalogue name or alias (``"G"``, ``"gyroid"``, ``"P"``, ``"D"``, ``"IWP"``, ...;
        ``porecad tpms --list``).
    cell_size : float or (3,) float
        Period in mm (per axis).
    origin : (3,) float
        A lattice point (mm).

    Returns
    -------
    TPMSField

    References
    ----------
    Documents 000 ch.2, 002 §2 and 004 §2 (the catalogue and its sources).

    Examples
    --------
    >>> import porecad as pc
    >>> g = pc.tpms("gyroid", cell_size=2.0)
    >>> float(g([[0.0, 0.0, 0.0]])[0])
    0.0
    """
    from .fields.tpms import TPMSField
    cs = np.broadcast_to(np.asarray(cell_size, dtype=float), (3,))
    if not np.all(np.isfinite(cs)) or np.any(cs <= 0):
        raise InputError(f"cell_size must be positive, got {cell_size!r}")
    return TPMSField(type, cs, origin=origin)


def _structure(field, structure, threshold, porosity, allow_closed_pores):
    from .calibration import check_one_of, constant_threshold
    from .fields.base import Field
    from .grading import PorosityToThreshold
    from .solids import StructureField
    ttype = getattr(getattr(field, "type", None), "name", None)
    check_one_of(threshold, porosity)
    if porosity is not None and ttype is None:
        raise InputError("a `porosity` needs a TPMS field (its calibration curve); give a `threshold` instead")
    if isinstance(porosity, Field):
        return StructureField(field, structure, PorosityToThreshold(porosity, ttype, structure))
    if ttype is not None and not isinstance(threshold, Field):
        threshold, _ = constant_threshold(ttype, structure, threshold, porosity, allow_closed_pores)
    return StructureField(field, structure, threshold)


def pore(field, threshold=None, porosity=None, allow_closed_pores=False):
    """The pore solid of a TPMS: material where ``φ ≥ C`` (document 001's pore structure).

    Parameters
    ----------
    field : Field
        Usually :func:`tpms`.
    threshold : float or Field, optional
        ``C`` (a number, or a field for grading).
    porosity : float or Field, optional
        Target void fraction instead: ``C`` from the type's calibration curve
        (point by point for a field).
    allow_closed_pores : bool
        Build outside the valid (open, connected) range instead of refusing.

    Returns
    -------
    StructureField
        Negative inside the material.

    Examples
    --------
    >>> import porecad as pc
    >>> solid = pc.pore(pc.tpms("P"), threshold=0.0)
    >>> m = pc.polygonise(solid, bounds=([0, 0, 0], [1, 1, 1]), resolution=60)
    >>> round(1 - m.volume, 2)   # 002 Table 3: 49.98 % at C = 0
    0.5
    """
    return _structure(field, "pore", threshold, porosity, allow_closed_pores)


def rod(field, threshold=None, porosity=None, allow_closed_pores=False):
    """The rod solid of a TPMS: material where ``φ ≤ C`` (001). Parameters as :func:`pore`."""
    return _structure(field, "rod", threshold, porosity, allow_closed_pores)


def sheet(field, threshold=None, porosity=None, allow_closed_pores=False):
    """The sheet solid of a TPMS: material where ``|φ| ≤ C`` (001). Parameters as :func:`pore`.

    Examples
    --------
    >>> import porecad as pc
    >>> s = pc.sheet(pc.tpms("G", cell_size=1.0), porosity=0.7)
    >>> m = pc.polygonise(s, bounds=([0, 0, 0], [1, 1, 1]), resolution=50)
    >>> abs((1 - m.volume) - 0.7) < 0.01
    True
    """
    return _structure(field, "sheet", threshold, porosity, allow_closed_pores)


def box(size=None, lo=None, hi=None):
    """An axis-aligned box: ``box(10)``, ``box((10, 20, 5))`` (from the origin) or ``box(lo=..., hi=...)``.

    Examples
    --------
    >>> import porecad as pc
    >>> pc.box(10).bounds[1].tolist()
    [10.0, 10.0, 10.0]
    """
    from .fields.sdf import Box
    if size is not None:
        if lo is not None or hi is not None:
            raise InputError("give a size, or lo and hi")
        hi = np.broadcast_to(np.asarray(size, dtype=float), (3,))
        lo = np.zeros(3)
    if lo is None or hi is None:
        raise InputError("give a size, or lo and hi")
    return Box(lo, hi)


def sphere(radius, centre=(0.0, 0.0, 0.0)):
    """A ball (exact signed distance)."""
    from .fields.sdf import Sphere
    return Sphere(centre, radius)


def disc(a=22.5, b=16.0, height=10.0):
    """The bundled analytic lumbar intervertebral disc (semi-axes ``a``, ``b``, ``height`` in mm)."""
    from .fields.sdf import LumbarDisc
    return LumbarDisc(a=a, b=b, height=height)


def mesh_body(source, band=None):
    """A closed body (mesh file or ``(vertices, faces)``) as a field: signed distance, negative inside.

    The body is checked and repaired where possible (:func:`porecad.bodies.load_body`).

    Parameters
    ----------
    source : path or (vertices, faces) or Mesh
        STL, OBJ, PLY, OFF, 3MF, or an image with a body (see ``porecad infill --help``).
    band : float, optional
        Distances are exact within this band around the surface (mm; default:
        the smallest extent / 20).

    Returns
    -------
    MeshBody
    """
    from .bodies import MeshBody, load_body
    if isinstance(source, (str, os.PathLike)):
        v, f, _ = load_body(source)
    else:
        v, f = (np.asarray(a) for a in source)
    ext = v.max(axis=0) - v.min(axis=0)
    return MeshBody(v, f, band=float(ext.min()) / 20.0 if band is None else float(band))


def expression(expr: str, body=None, cell_size: float = 1.0):
    """A field from a safe numpy expression in ``x, y, z`` (mm) and, with a ``body``, ``d`` and ``dn``.

    ``d`` is the depth below the body's surface (mm, positive inside) and
    ``dn = d / max depth``; depth is sampled on a grid of ``cell_size / 8``.

    Examples
    --------
    >>> import porecad as pc
    >>> ramp = pc.expression("0.5 + 0.01 * z")
    >>> float(ramp([[0.0, 0.0, 10.0]])[0])
    0.6
    """
    from .grading import ExpressionField, GradingContext
    if body is None:
        return ExpressionField(str(expr), None)
    lo, hi = body.bounds
    coarse = float(cell_size) / 8.0

    def depth():
        from .bodies.distance import BodyDepth
        return BodyDepth(body, coarse)
    return ExpressionField(str(expr), GradingContext(lo, hi, coarse, depth=depth))
