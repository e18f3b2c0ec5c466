"""The least-squares TBSS through a body's structured sample grid, shared by the radial and hex fits.

The body mesh's checks and measures (:func:`mesh_arrays`,
:func:`volume_centroid`, :func:`surface_distance`); the fit through the grid,
its edges opened or its control net untangled where it folds
(:func:`fitted_tbss`); how much of the plain fit folds (:func:`folded_share`,
:func:`check_folds`, :class:`FoldedFit`, see
:mod:`porecad.splines.meshfit`); and a fit's report against the body
(:func:`fit_report`).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .construct import finish_tbss
from .lspia import fit_grid_lstsq

__all__ = ["FOLDED_SHARE_MAX", "FoldedFit", "check_folds", "fit_report", "fitted_tbss", "folded_share",
           "mesh_arrays", "surface_distance", "volume_centroid"]

#: the most of a plain fit's Jacobian samples that may fold (scaled Jacobian ≤ 0) for ``auto`` to keep it.
#: Measured (radial fits, 8³ control points): noisy blobs and star blobs 0.22–0.28 % (untangled in seconds);
#: the branching tube 3.8 %, plates 1 and 2 cells thick 8.6 % and 5.1 % (whose untangled fits took minutes)
FOLDED_SHARE_MAX = 0.01


class FoldedFit(InputError):
    """The plain fits ``auto`` tries fold through the body; ``detail`` says how far (one line)."""

    def __init__(self, detail: str):
        self.detail = detail
        super().__init__(f"the TBSS fit folds through the body: {detail}; fit with `method` \"hex\" or "
                         "\"radial\" to untangle it anyway (minutes), or fill the body by infill, TIS or ARBF")


def folded_share(G, params, n_ctrl, degree) -> float:
    """The fraction of the plain least-squares fit's Jacobian samples where it folds (scaled Jacobian ≤ 0)."""
    from .untangle import scaled_jacobian_samples
    from .volume import TBSS
    vol = fit_grid_lstsq(G, n_ctrl, degree, params=params)
    return float(np.mean(scaled_jacobian_samples(TBSS(vol.control, vol.degrees, vol.knots)) <= 0))


def check_folds(G, params, n_ctrl, degree, method, limit):
    """:class:`FoldedFit` where the plain fit folds in more than ``limit`` of its volume (0: where it needs
    untangling, its edges opened)."""
    share = folded_share(G, params, n_ctrl, degree)
    if share > limit:
        if not limit:
            try:
                fitted_tbss(G, params, n_ctrl, degree, untangle=False)
                return
            except InputError:
                pass
        raise FoldedFit(f"the {method} fit folds in {share:.1%} of its volume" + (f" (at most {limit:.0%})"
                                                                                   if limit else ""))


def mesh_arrays(vertices, faces):
    """The body mesh as contiguous ``(V, 3)`` float64 vertices and ``(F, 3)`` int64 faces, checked
    (shapes, finite coordinates, integer indices of existing vertices): ``(v, f)``."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
        raise InputError(f"mesh vertices must be a (V >= 4, 3) array, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 4:
        raise InputError(f"mesh faces must be an (F >= 4, 3) array, got shape {f.shape}")
    if not np.all(np.isfinite(v)):
        raise InputError("mesh vertices have non-finite coordinates")
    if not np.issubdtype(f.dtype, np.integer):
        raise InputError("mesh faces must be integer vertex indices")
    f = np.ascontiguousarray(f, dtype=np.int64)
    if f.min() < 0 or f.max() >= len(v):
        raise InputError("mesh faces reference missing vertices")
    return v, f


def volume_centroid(v, f):
    """Signed volume and volume centroid (sum of tetrahedra from a reference point)."""
    ref = v.mean(axis=0)
    a, b, c = v[f[:, 0]] - ref, v[f[:, 1]] - ref, v[f[:, 2]] - ref
    vol6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    V = vol6.sum() / 6.0
    if abs(V) < 1e-300:
        raise InputError("the body mesh encloses no volume")
    cen = ref + ((a + b + c) * vol6[:, None]).sum(axis=0) / (24.0 * V)
    return float(V), cen


def surface_distance(tb, v, f, faces=("u0", "u1", "v0", "v1", "w0", "w1"), n=24):
    """rms and max distance (mm) of TBSS boundary samples to the mesh surface."""
    from ..bodies.mesh import MeshBody

    pts = np.concatenate([tb.boundary_points(fc, n).reshape(-1, 3) for fc in faces])
    band = 0.25 * float(np.ptp(v, axis=0).max())
    d = np.abs(MeshBody(v, f, band).evaluate(pts))
    return float(np.sqrt(np.mean(d * d))), float(d.max())


def fitted_tbss(G, params, n_ctrl, degree, untangle, vol=None):
    """Least-squares TBSS through the sample grid (or the given fit ``vol`` of it); edges opened, or the
    control net untangled against ``G`` where it folds."""
    from .untangle import min_scaled_jacobian, untangle_tbss
    from .volume import TBSS
    if vol is None:
        vol = fit_grid_lstsq(G, n_ctrl, degree, params=params)
    ell = float(np.mean([np.linalg.norm(np.diff(G, axis=a), axis=-1).mean() for a in range(3)]))
    try:
        tb, _ = finish_tbss(vol.control, vol.degrees, vol.knots)
        sj = min_scaled_jacobian(tb)
        moved = float(np.linalg.norm(tb.control - vol.control, axis=-1).max())
        if sj > 0 and moved <= ell:
            return tb, {"untangled": False, "min_scaled_jacobian": sj}
        # opening the edges of a nearly folded net can throw a corner point far away (or leave a zero)
        folded = f"opening its edges moved a control point {moved:.3g} mm (min scaled Jacobian {sj:.3g})"
    except InputError as err:
        if untangle is False:
            raise
        folded = str(err)
    if untangle is False:
        raise InputError(f"TBSS folds: {folded}")
    # from the plain least-squares net: opening the edges of a folded net can throw corner points far away
    tb0 = TBSS(vol.control, vol.degrees, vol.knots)
    opts = dict(untangle or {})
    unknown = sorted(set(opts) - {"max_iterations", "time_limit"})
    if unknown:
        raise InputError(f"unknown untangle option(s) {', '.join(map(str, unknown))}; use max_iterations, time_limit")
    res = untangle_tbss(tb0, G, params, **opts)
    if not res["converged"]:
        raise InputError(f"{res['reason']} (the fit folded: {folded})")
    tb = res["tbss"]
    return tb, {"untangled": True, "untangle": {k: res[k] for k in ("iterations", "rounds", "moved", "time_s",
                                                                     "min_scaled_jacobian_before")},
                "min_scaled_jacobian": float(res["min_scaled_jacobian"])}


def fit_report(tb, v, f, vol_body, extra, faces=("u0", "u1", "v0", "v1", "w0", "w1")):
    """The diagnostics of a fit ``tb`` of the body ``(v, f)`` of volume ``vol_body``: ``extra`` with
    ``rms_distance``, ``max_distance`` (of the ``faces`` to the surface), ``covered_fraction``,
    ``extent_error``, ``min_det`` and ``mean_det`` added (a new dict)."""
    info = tb.check_jacobian()
    rms, dmax = surface_distance(tb, v, f, faces=faces)
    lo, hi = tb.bounds()
    ext = np.ptp(v, axis=0)
    out = dict(extra)
    out.update({"rms_distance": rms, "max_distance": dmax, "covered_fraction": tb.volume() / abs(vol_body),
                "extent_error": float(np.max(np.abs((hi - lo) - ext) / ext)),
                "min_det": info["min_det"], "mean_det": info["mean_det"]})
    return out
