"""Fitting a TBSS to a closed triangle mesh (a body), in the mesh's units (mm).

Methods (:func:`fit_tbss_to_mesh`): ``radial`` (star-shaped bodies: rays from
the centroid, :mod:`porecad.splines.meshfit_radial`), ``sliced`` (elongated
bodies: lofted sections, :mod:`porecad.splines.meshfit_sliced`), ``hex`` (any
closed genus-0 body: the hexahedral cube parameterisation of 000 ch.3,
:mod:`porecad.splines.meshfit_hex`, pushed out over the surface with
``cover``: :mod:`porecad.splines.meshfit_envelope`) and ``auto`` (radial
where the body is star-shaped about its centroid, else hex). Fits that fold
are untangled against their Jacobian
(:func:`porecad.splines.untangle.untangle_tbss`); ``auto`` first checks the
plain least-squares fit (:func:`porecad.splines.meshfit_grid.folded_share`, a
fraction of a second): one folded through more than
:data:`porecad.splines.meshfit_grid.FOLDED_SHARE_MAX` of its volume is not a
crease of a noisy surface that the untangling smooths in seconds but a fold
through the body (a branching tube, a plate whose edges the rays or the
cube map do not follow), whose untangled fit maps a scaffold that crosses
itself for minutes: ``auto`` then takes the hex fit instead where that one
needs no untangling, or refuses
(:class:`porecad.splines.meshfit_grid.FoldedFit`). A hex fit alone is not
judged by its share (the bunny's folds in 2.8 % and untangles; the tube's
in 1.8–5.9 %).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .meshfit_grid import FOLDED_SHARE_MAX, FoldedFit, mesh_arrays, volume_centroid
from .meshfit_hex import STRETCH_BALANCE, fit_hex
from .meshfit_radial import fit_radial, star_shaped
from .meshfit_sliced import fit_sliced
from .volume import as3

__all__ = ["cover_margin", "fit_tbss_to_mesh"]


def cover_margin(vertices, faces, fraction: float = 0.1) -> float:
    """A default ``inflate`` margin (mm): ``fraction`` of the body's mean thickness ``3 V / A``.

    ``3 V / A`` is a sphere's radius (a slab's half-thickness is ``V / A``):
    a tenth of it lets a radial or hex fit (whose distance to the surface is
    a few per cent of that size) cover the body without inflating thin
    parts much, so that a scaffold cut to the body
    (:func:`porecad.maps.tbss.tbss_scaffold` with ``clip``) fills it.
    """
    v, f = mesh_arrays(vertices, faces)
    vol, _ = volume_centroid(v, f)
    area = 0.5 * float(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum())
    return float(fraction) * 3.0 * abs(vol) / max(area, 1e-300)


def fit_tbss_to_mesh(vertices, faces, method: str = "auto", n_ctrl=(8, 8, 8), centre=None,
                     grid: int = 32, degree=3, untangle=None, progress=None, inflate: float = 0.0,
                     cover: bool = False, balance: int = STRETCH_BALANCE):
    """Fit a TBSS to a closed triangle mesh (a body), in the mesh's units (mm).

    ``method``: ``"radial"`` (star-shaped bodies; rays from ``centre``, default the volume centroid:
    :func:`~porecad.splines.meshfit_radial.fit_radial`), ``"sliced"`` (elongated bodies; sections along
    the principal axis lofted through ``grid`` of them: :func:`~porecad.splines.meshfit_sliced.fit_sliced`),
    ``"hex"`` (any closed genus-0 body; the hexahedral cube parameterisation of the body (000 ch.3,
    :func:`porecad.param.hex_parameterisation`) sampled on ``2 n + 2`` cells per axis, fitted by least
    squares: the whole body is covered, :func:`~porecad.splines.meshfit_hex.fit_hex`) or ``"auto"``:
    radial when the body is star-shaped about its centroid, else hex; a plain fit folded through more than
    :data:`~porecad.splines.meshfit_grid.FOLDED_SHARE_MAX` of its volume
    (:func:`~porecad.splines.meshfit_grid.folded_share`) is not untangled: the radial one gives way to the
    hex fit (``radial_refused`` says why), which must then need no untangling (else
    :class:`~porecad.splines.meshfit_grid.FoldedFit`).

    ``cover`` (hex): fit every vertex of the surface too and push the fit out where it passes inside one,
    so that the TBSS covers the body without a uniform margin (how, and the cover measured:
    :mod:`porecad.splines.meshfit_envelope`); where that fit cannot be made, or it folds where the plain
    fit does not, the plain fit is kept and ``envelope`` says why. ``balance`` (hex): rounds of stretch
    balancing of the cube map's patch maps (:data:`~porecad.splines.meshfit_hex.STRETCH_BALANCE`; 0: the
    harmonic maps of 000 §3.5; why: :func:`~porecad.splines.meshfit_hex.fit_hex`).

    ``inflate`` (mm, radial and hex): the sample grid's boundary is pushed that far outwards before the fit
    (radial: along its rays, so a star-shaped body stays star-shaped; hex: along the grid's boundary
    normals; the interior following by the Laplace equation), so that the TBSS covers the body and a
    scaffold can be cut to the body itself (:func:`porecad.maps.tbss.tbss_scaffold` with ``clip``);
    ``"auto"``: :func:`cover_margin` for a radial fit, none for a hex fit (why: :func:`_inflation`). The
    distances and extents reported are then those of the inflated fit.

    A radial or hex fit that folds (noise, or the cube's edges on a smooth surface) is untangled against
    its Jacobian (:func:`porecad.splines.untangle.untangle_tbss`, options in ``untangle``:
    ``max_iterations``, ``time_limit``, ...; ``untangle=False`` refuses instead).

    Returns
    -------
    tbss : TBSS
    diagnostics : dict
        ``method``, ``rms_distance`` / ``max_distance`` (mm, TBSS boundary samples to the surface; for
        "sliced" the side faces only), ``covered_fraction`` (TBSS volume / body volume), ``extent_error``
        (largest relative difference of the bounding-box sides), ``min_det`` / ``mean_det``,
        ``min_scaled_jacobian``, ``untangled`` (and ``untangle``: iterations, rounds, largest move in mean
        sample spacings, time); "radial" adds ``centre``, "sliced" ``axis``, ``levels``, ``sections``,
        ``length_fraction``, "hex" ``corner_choice``, ``sample_cells`` and with ``cover`` ``envelope``
        (``undercut_before`` / ``undercut``: mm by which the fit passes inside a surface vertex,
        ``iterations``, ``points``; or ``refused`` with the reason).
    """
    v, f, n, grid = _checked(vertices, faces, n_ctrl, grid)
    auto = method == "auto"
    if auto:
        method = "radial" if star_shaped(v, f, centre, rays=max(grid, 16)) else "hex"
    margin = _inflation(inflate, method, v, f)
    refused = None
    if method == "radial":
        tb, info, refused = _radial(v, f, n, degree, centre, grid, untangle, margin, auto)
        if refused is not None:  # auto only: the cube map's fit instead
            method, margin = "hex", _inflation(inflate, "hex", v, f)
    if method == "sliced":
        tb, info = _sliced(v, f, n, degree, grid, margin)
    elif method == "hex":
        tb, info = _hex(v, f, n, degree, untangle, progress, margin, cover, balance, refused)
    elif method != "radial":
        raise InputError(f"unknown TBSS fitting method {method!r}; use 'auto', 'radial', 'sliced' or 'hex'")
    info["inflate"] = margin
    if refused is not None:
        info["radial_refused"] = refused
    return tb, info


def _checked(vertices, faces, n_ctrl, grid):
    """The body mesh (:func:`~porecad.splines.meshfit_grid.mesh_arrays`), the control grid (3 ints) and
    the sample grid (an int, at least 4 and the most control points), checked: ``(v, f, n, grid)``."""
    v, f = mesh_arrays(vertices, faces)
    n = as3(n_ctrl, "n_ctrl")
    grid = int(grid)
    if grid < max(n) or grid < 4:
        raise InputError(f"grid {grid} is too coarse for {n} control points")
    return v, f, n, grid


def _inflation(inflate, method, v, f) -> float:
    """The margin (mm, a non-negative float) by which ``method``'s sample grid is inflated: ``inflate``, or
    for ``"auto"`` :func:`cover_margin` of the body ``(v, f)`` for a radial fit and none for a hex fit.

    Measured with the bench's
    scaffold (gyroid sheet, 4 periods, resolution 12): a hex fit covers more with a margin (the femur
    98.9 % of the body at 1 mm against 97.1 %; the bunny 99.4 % at 2 mm against 98.5 %), but its offset
    along the normals overlaps itself in concave parts: the bunny at 4 mm and the segmented body at
    0.38 mm gave mapped scaffolds whose crossings could not be refined away within 5 minutes. Give
    ``margin`` to trade that risk for coverage.
    """
    out = inflate
    if out == "auto":  # a cube map's offset along its normals overlaps itself in concave parts
        out = cover_margin(v, f) if method == "radial" else 0.0
    out = float(out)
    if not (np.isfinite(out) and out >= 0):
        raise InputError(f"inflate must be a non-negative distance (mm), got {out!r}")
    return out


def _radial(v, f, n, degree, centre, grid, untangle, margin, auto):
    """The radial fit, ``(tbss, diagnostics, None)``; for ``auto`` ``(None, None, reason)`` where its plain
    fit folds through the body (:class:`~porecad.splines.meshfit_grid.FoldedFit`: the hex fit instead)."""
    try:
        tb, info = fit_radial(v, f, n, degree, centre, grid, untangle, margin,
                              fold_limit=FOLDED_SHARE_MAX if auto else None)
    except FoldedFit as err:
        return None, None, err.detail
    return tb, info, None


def _sliced(v, f, n, degree, grid, margin):
    """The sliced fit, ``(tbss, diagnostics)``; refused where a margin is asked (it inflates no grid)."""
    if margin:
        raise InputError("inflate applies to radial and hex fits, not to the sliced fit")
    return fit_sliced(v, f, n, degree, grid)


def _hex(v, f, n, degree, untangle, progress, margin, cover, balance, refused):
    """The hex fit, ``(tbss, diagnostics)``; after the radial fit was ``refused`` (a reason) it must need
    no untangling, else :class:`~porecad.splines.meshfit_grid.FoldedFit` gives both reasons."""
    try:
        return fit_hex(v, f, n, degree, untangle, progress, inflate=margin, envelope=bool(cover),
                       balance=balance, fold_limit=None if refused is None else 0.0)
    except FoldedFit as err:
        raise FoldedFit(f"{refused}; {err.detail}") from None
