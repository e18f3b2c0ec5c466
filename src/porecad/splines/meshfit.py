"""Fitting a TBSS to a closed triangle mesh (a body), in the mesh's units (mm).

Methods (:func:`fit_tbss_to_mesh`): ``radial`` (star-shaped bodies: rays from
the centroid), ``sliced`` (elongated bodies: lofted sections), ``hex`` (any
closed genus-0 body: the hexahedral cube parameterisation of 000 ch.3) and
``auto`` (radial where the body is star-shaped about its centroid, else hex).
Fits that fold are untangled against their Jacobian
(:func:`porecad.splines.untangle.untangle_tbss`); ``auto`` first checks the
plain least-squares fit (:func:`folded_share`, a fraction of a second): one
folded through more than :data:`FOLDED_SHARE_MAX` of its volume is not a
crease of a noisy surface that the untangling smooths in seconds but a fold
through the body (a branching tube, a plate whose edges the rays or the
cube map do not follow), whose untangled fit maps a scaffold that crosses
itself for minutes: ``auto`` then takes the hex fit instead where that one
needs no untangling, or refuses (:class:`FoldedFit`). A hex fit alone is not
judged by its share (the bunny's folds in 2.8 % and untangles; the tube's
in 1.8–5.9 %).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..errors import InputError
from .construct import finish_tbss, point3
from .loft import axis_frame, laplace_fill, loft_tbss, polygon_frame, star_about
from .lspia import fit_grid_lstsq
from .volume import as3

__all__ = ["FOLDED_SHARE_MAX", "FoldedFit", "fit_tbss_to_mesh", "folded_share", "star_shaped"]

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


def _check_folds(G, params, n_ctrl, degree, method, limit):
    """:class:`FoldedFit` where the plain fit folds in more than ``limit`` of its volume (0: where it needs
    untangling, its edges opened)."""
    share = folded_share(G, params, n_ctrl, degree)
    if share > limit:
        if not limit:
            try:
                _fitted(G, params, n_ctrl, degree, untangle=False)
                return
            except InputError:
                pass
        raise FoldedFit(f"the {method} fit folds in {share:.1%} of its volume" + (f" (at most {limit:.0%})"
                                                                                   if limit else ""))


def _mesh_arrays(vertices, faces):
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


def _volume_centroid(v, f):
    """Signed volume and volume centroid (sum of tetrahedra from a reference point)."""
    ref = v.mean(axis=0)
    a, b, c = v[f[:, 0]] - ref, v[f[:, 1]] - ref, v[f[:, 2]] - ref
    vol6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    V = vol6.sum() / 6.0
    if abs(V) < 1e-300:
        raise InputError("the body mesh encloses no volume")
    cen = ref + ((a + b + c) * vol6[:, None]).sum(axis=0) / (24.0 * V)
    return float(V), cen


@njit(cache=True, parallel=True)
def _ray_hits(v0, e1, e2, origin, dirs, tol, counts, tfirst):
    """Distinct crossings ``t > 0`` of rays ``origin + t dir`` with triangles (Möller-Trumbore).

    Hits closer than ``tol`` along a ray (one crossing through a shared edge or
    vertex) count once; ``tfirst`` is the nearest crossing.
    """
    R = dirs.shape[0]
    F = v0.shape[0]
    for i in prange(R):
        buf = np.empty(256)
        cnt = 0
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        for f in range(F):
            ax, ay, az = e1[f, 0], e1[f, 1], e1[f, 2]
            bx, by, bz = e2[f, 0], e2[f, 1], e2[f, 2]
            px = dy * bz - dz * by
            py = dz * bx - dx * bz
            pz = dx * by - dy * bx
            det = ax * px + ay * py + az * pz
            if det == 0.0:
                continue
            inv = 1.0 / det
            tx = origin[0] - v0[f, 0]
            ty = origin[1] - v0[f, 1]
            tz = origin[2] - v0[f, 2]
            uu = (tx * px + ty * py + tz * pz) * inv
            if uu < -1e-12 or uu > 1.0 + 1e-12:
                continue
            qx = ty * az - tz * ay
            qy = tz * ax - tx * az
            qz = tx * ay - ty * ax
            vv = (dx * qx + dy * qy + dz * qz) * inv
            if vv < -1e-12 or uu + vv > 1.0 + 1e-12:
                continue
            t = (bx * qx + by * qy + bz * qz) * inv
            if t <= tol:
                continue
            if cnt < 256:
                buf[cnt] = t
                cnt += 1
        if cnt == 0:
            counts[i] = 0
            tfirst[i] = 0.0
            continue
        s = np.sort(buf[:cnt])
        k = 1
        for j in range(1, cnt):
            if s[j] - s[j - 1] > tol:
                k += 1
        counts[i] = k
        tfirst[i] = s[0]


def _radial_boundary(v, f, centre, dirs):
    """Distances from ``centre`` to the surface along unit ``dirs``; star-shapedness checked."""
    v0 = np.ascontiguousarray(v[f[:, 0]])
    e1 = np.ascontiguousarray(v[f[:, 1]] - v0)
    e2 = np.ascontiguousarray(v[f[:, 2]] - v0)
    ext = float(np.ptp(v, axis=0).max())
    counts = np.empty(len(dirs), np.int64)
    tf = np.empty(len(dirs))
    _ray_hits(v0, e1, e2, centre, np.ascontiguousarray(dirs), 1e-9 * ext, counts, tf)
    bad = np.flatnonzero(counts != 1)
    if bad.size:
        c = centre
        if np.all(counts % 2 == 0):
            raise InputError(f"centre ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}) lies outside the body")
        i = int(bad[0])
        d = dirs[i]
        raise InputError(
            f"body is not star-shaped about centre ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}): the ray "
            f"toward ({d[0]:.3g}, {d[1]:.3g}, {d[2]:.3g}) crosses the surface {int(counts[i])} "
            "times; try the `fit` sliced")
    return tf


def _cube_boundary_dirs(n):
    s = np.linspace(-1.0, 1.0, n)
    Q = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1)
    bmask = np.zeros((n, n, n), bool)
    bmask[[0, -1], :, :] = True
    bmask[:, [0, -1], :] = True
    bmask[:, :, [0, -1]] = True
    q = Q[bmask]
    return bmask, q / np.linalg.norm(q, axis=1)[:, None]


def _surface_distance(tb, v, f, faces=("u0", "u1", "v0", "v1", "w0", "w1"), n=24):
    """rms and max distance (mm) of TBSS boundary samples to the mesh surface."""
    from ..bodies.mesh import MeshBody

    pts = np.concatenate([tb.boundary_points(fc, n).reshape(-1, 3) for fc in faces])
    band = 0.25 * float(np.ptp(v, axis=0).max())
    d = np.abs(MeshBody(v, f, band).evaluate(pts))
    return float(np.sqrt(np.mean(d * d))), float(d.max())


def _fitted(G, params, n_ctrl, degree, untangle, vol=None):
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


def _report(tb, v, f, vol_body, extra, faces=("u0", "u1", "v0", "v1", "w0", "w1")):
    info = tb.check_jacobian()
    rms, dmax = _surface_distance(tb, v, f, faces=faces)
    lo, hi = tb.bounds()
    ext = np.ptp(v, axis=0)
    out = dict(extra)
    out.update({"rms_distance": rms, "max_distance": dmax, "covered_fraction": tb.volume() / abs(vol_body),
                "extent_error": float(np.max(np.abs((hi - lo) - ext) / ext)),
                "min_det": info["min_det"], "mean_det": info["mean_det"]})
    return out


def star_shaped(vertices, faces, centre=None, rays: int = 12) -> bool:
    """Whether every ray from ``centre`` (default: the volume centroid) toward the boundary nodes of a
    ``rays³`` cube grid crosses the surface once (the radial fit's condition)."""
    v, f = _mesh_arrays(vertices, faces)
    _, cen = _volume_centroid(v, f)
    c = cen if centre is None else point3(centre, "centre")
    try:
        _radial_boundary(v, f, c, _cube_boundary_dirs(int(rays))[1])
    except InputError:
        return False
    return True


def cover_margin(vertices, faces, fraction: float = 0.1) -> float:
    """A default ``inflate`` margin (mm): ``fraction`` of the body's mean thickness ``3 V / A``.

    ``3 V / A`` is a sphere's radius (a slab's half-thickness is ``V / A``):
    a tenth of it lets a radial or hex fit (whose distance to the surface is
    a few per cent of that size) cover the body without inflating thin
    parts much, so that a scaffold cut to the body
    (:func:`porecad.maps.tbss.tbss_scaffold` with ``clip``) fills it.
    """
    v, f = _mesh_arrays(vertices, faces)
    vol, _ = _volume_centroid(v, f)
    area = 0.5 * float(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum())
    return float(fraction) * 3.0 * abs(vol) / max(area, 1e-300)


def _inflated(G, margin):
    """The sample grid with its boundary pushed ``margin`` (mm) outwards along its normals, interior following.

    The boundary displacement ``margin n`` (outward unit normals of the
    grid's boundary, :func:`porecad.param.grid_untangle.boundary_normals`) is
    extended into the interior by the discrete Laplace equation
    (:func:`porecad.splines.loft.laplace_fill`).
    """
    if not margin:
        return G
    from ..param.grid_untangle import boundary_normals
    ids = np.arange(int(np.prod(G.shape[:3]))).reshape(G.shape[:3])
    bid, nrm = boundary_normals(G, ids)
    disp = np.zeros_like(G).reshape(-1, 3)
    disp[bid] = float(margin) * nrm
    return G + laplace_fill(disp.reshape(G.shape), 3)


def _fit_radial(v, f, n_ctrl, degree, centre, grid, untangle=None, inflate=0.0, fold_limit=None):
    vol_body, cen = _volume_centroid(v, f)
    c = cen if centre is None else point3(centre, "centre")
    bmask, dirs = _cube_boundary_dirs(grid)
    t = _radial_boundary(v, f, c, dirs)
    G = np.zeros((grid, grid, grid, 3))
    G[bmask] = c + (t + inflate)[:, None] * dirs
    G = laplace_fill(G, 3)
    s = np.linspace(0.0, 1.0, grid)
    if fold_limit is not None:
        _check_folds(G, (s, s, s), n_ctrl, degree, "radial", fold_limit)
    tb, fit = _fitted(G, (s, s, s), n_ctrl, degree, untangle)
    return tb, _report(tb, v, f, vol_body, {"method": "radial", "centre": tuple(float(x) for x in c), **fit})


#: rounds of stretch balancing of the cube map's patch maps for a TBSS fit
#: (:func:`porecad.param.patch_maps.harmonic_map`). Measured at ``n_ctrl=8`` with ``cover``
#: (vol(body ∩ TBSS) / vol(body), extents of body ∩ TBSS), harmonic maps -> 2 rounds: the bunny
#: 99.6 % / 2.07 % -> 99.9 % / 1.1 % (its ear tip had been squeezed 4 % from a face's corner, where
#: pushing the fit out for it made its boundary pass through itself); the femur 99.2 % -> 99.8 %;
#: the bone, the segmented body and the limbs as before (99.97 %, 99.6 %, 85 %)
STRETCH_BALANCE = 2


def _fit_hex(v, f, n_ctrl, degree, untangle=None, progress=None, stretch=True, inflate=0.0, envelope=False,
             balance=STRETCH_BALANCE, fold_limit=None):
    """Volumetric fit from the hexahedral cube parameterisation (000 ch.3) sampled at ``2 n + 2`` cells per axis.

    The structured grid's boundary nodes lie on the surface (per-patch
    harmonic maps), its interior nodes solve the discrete Laplace equation
    (000 eq. 3.2.3); the grid is not untangled (the spline's control net is,
    against the spline's own Jacobian). A cubic control grid ``n³`` is
    stretched along the body's long axes (``n`` times the mean grid-line
    length along the axis over the middle one, between ``n`` and ``3 n``).
    """
    from ..param.hexcube import hex_parameterisation
    vol_body, _ = _volume_centroid(v, f)
    cells = tuple(max(2 * k + 2, 12) for k in n_ctrl)
    nodes, info = hex_parameterisation(v, f, grid=cells, untangle=False, progress=progress,
                                       keep_locators=envelope, balance=balance)
    if stretch and len(set(n_ctrl)) == 1:
        # a cubic control grid on an elongated body: control points along each axis in proportion to the
        # mean length of the grid lines along it (at least n, at most 3 n), sampled again to match
        ln = np.array([np.linalg.norm(np.diff(nodes, axis=a), axis=-1).sum(axis=a).mean() for a in range(3)])
        n0 = n_ctrl[0]
        want = tuple(int(np.clip(round(n0 * x / np.sort(ln)[1]), n0, 3 * n0)) for x in ln)
        if want != tuple(n_ctrl):
            n_ctrl = want
            cells = tuple(max(2 * k + 2, 12) for k in n_ctrl)
            nodes, info = hex_parameterisation(v, f, grid=cells, untangle=False, progress=progress,
                                               keep_locators=envelope, balance=balance)
    params = tuple(np.linspace(0.0, 1.0, k + 1) for k in cells)
    G = _inflated(nodes, inflate)
    if fold_limit is not None:
        _check_folds(G, params, n_ctrl, degree, "hex", fold_limit)
    extra = {"method": "hex", "corner_choice": info["corner_choice"], "control": list(n_ctrl),
             "sample_cells": list(cells), "patch_balance": int(balance)}
    plain = None
    if envelope:
        # a plain fit that is valid as it stands is kept where the pushed one folds: pushing out for a part
        # the cube map does not reach (a thin limb) bends the whole map (the limbs body: min det J x 0.08,
        # its scaffold's crossings beyond repair), while pushing out a folded fit costs nothing new
        try:
            plain, valid_plain = _fitted(G, params, n_ctrl, degree, untangle=False), True
        except InputError:
            plain, valid_plain = None, False
        best, why = None, []
        for pushes, relax in ENVELOPE_STRENGTHS:  # the one that covers most of the body
            try:
                tb, fit, overlaps = _envelope_fitted(G, params, n_ctrl, degree, False if valid_plain else untangle,
                                                     info, inflate, pushes, relax)
                if overlaps:  # part of the way from the plain fit, as far as its boundary stays clear of itself
                    plain = plain if plain is not None else _fitted(G, params, n_ctrl, degree, untangle)
                    tb, alpha, sj = _partly_pushed(plain[0], tb)
                    fit["envelope"]["pushed_share"] = alpha
                    fit["min_scaled_jacobian"] = sj
            except InputError as err:
                why.append("the pushed fit folds where the plain fit does not" if valid_plain and
                           "folds" in str(err) else str(err))
                continue
            cov = _covered(tb, v, f)
            fit["envelope"].update(pushes=pushes, relax=relax, covered_fraction=cov)
            if best is None or cov > best[0]:
                best = (cov, tb, fit)
        if best is not None:
            return best[1], _report(best[1], v, f, vol_body, {**extra, **best[2]})
        extra["envelope"] = {"refused": "; ".join(dict.fromkeys(why))}
    tb, fit = plain if plain is not None else _fitted(G, params, n_ctrl, degree, untangle)
    return tb, _report(tb, v, f, vol_body, {**extra, **fit})


#: push-out steps and their over-relaxation (:func:`porecad.splines.lspia.fit_envelope`) of the pushed fits
#: tried; measured best: the femur (10, 2.0), 99.2 % covered; the bunny (6, 1.5), 99.6 %
ENVELOPE_STRENGTHS = ((3, 1.0), (6, 1.5), (10, 2.0))


def _covered(tb, v, f) -> float:
    """vol(body ∩ TBSS) / vol(body) by the exact Boolean (:func:`porecad.maps.tbss.body_overlap`; -1 where it
    cannot be formed: that fit is ranked last)."""
    from ..maps.tbss import body_overlap
    o = body_overlap(tb, v, f)
    return -1.0 if o is None else round(float(o["fraction"]), 6)


#: shares of the push tried, largest first, when the pushed fit's boundary passes through itself
PUSH_SHARES = (0.75, 0.5, 0.35, 0.25)


def _partly_pushed(plain, pushed):
    """``(tbss, share, min scaled Jacobian)``: the control net ``plain + share (pushed - plain)`` with the largest
    share of :data:`PUSH_SHARES` that does not fold and whose boundary does not pass through itself."""
    from .untangle import min_scaled_jacobian
    from .volume import TBSS
    for alpha in PUSH_SHARES:
        tb = TBSS(plain.control + alpha * (pushed.control - plain.control), plain.degrees, plain.knots)
        sj = float(min_scaled_jacobian(tb))
        if sj > 0 and _boundary_crossings(tb) is None:
            return tb, alpha, sj
    raise InputError("the pushed fit's boundary passes through itself, and so does every share of the push tried")


def _envelope_fitted(G, params, n_ctrl, degree, untangle, info, inflate, pushes=3, relax=1.0):
    """The hex fit through the grid and every surface vertex, pushed out where it cuts the body's corners.

    The grid's boundary nodes sample the surface ``2 n + 2`` times per axis;
    a tip, an ear or a condyle between them is cut off by the plain fit
    (the bunny: 3.5 % of its extent, the femur: 3 % of its volume). Every
    vertex of the surface, at its cube parameters from the patch maps
    (:func:`porecad.param.patch_maps.surface_points`), joins the
    least-squares fit, pushed out along its normal where the fit passes
    inside it (:func:`porecad.splines.lspia.fit_envelope`). Where that fit
    folds, it is untangled against the grid with the boundary nodes moved
    onto the pushed surface (so that the untangling keeps the cover).

    Pushed out on two sides of a narrow gap (the bunny's ears), the solid's
    boundary can pass through itself: positive Jacobian everywhere, yet not
    one-to-one, and a scaffold mapped through it crosses itself wherever the
    body lies in the overlap (the bunny at resolution 16: crossings that no
    refinement removes). So the points near such an overlap
    (:func:`_overlap_points`) are held at the surface and the fit is made
    again, up to :data:`ENVELOPE_ROUNDS` times. Returns ``(tbss, info,
    overlaps)``: ``overlaps`` when the last fit's boundary still passes
    through itself (:func:`_fit_hex` then takes part of the push,
    :func:`_partly_pushed`).
    """
    from ..mesh.validate import signed_volume
    from ..param.patch_maps import surface_points
    from .lspia import fit_envelope
    from .volume import tensor_apply
    from .basis import basis_matrix
    uvw, xyz, nrm = surface_points(info["locators"])
    if signed_volume(info["vertices"], info["faces"]) < 0:
        nrm = -nrm
    xyz = xyz + float(inflate) * nrm
    on = np.zeros(G.shape[:3], bool)
    on[[0, -1]] = on[:, [0, -1]] = on[:, :, [0, -1]] = True
    hold = np.zeros(len(uvw), bool)
    B = None
    for attempt in range(ENVELOPE_ROUNDS):
        vol, env = fit_envelope(G, xyz, nrm, uvw, n_ctrl, degree, params=params, hold=hold,
                                iterations=pushes, relax=relax)
        # the untangling's samples: the grid, its boundary on the pushed surface
        if B is None:  # the same knots every round
            B = [basis_matrix(vol.knots[a], vol.degrees[a], params[a]).toarray() for a in range(3)]
        G2 = G.copy()
        G2[on] = tensor_apply(B, vol.control)[on]
        try:
            tb, fit = _fitted(G2, params, n_ctrl, degree, untangle, vol=vol)
        except InputError:
            if attempt == 0:
                raise
            break  # the last fit, whose boundary overlaps itself
        last = (tb, fit)
        # pushed out on two sides of a narrow gap (the bunny's ears) the solid's boundary can pass through
        # itself: positive Jacobian everywhere, yet not one-to-one, and a scaffold mapped through it crosses
        # itself wherever the body lies in the overlap. The points near the overlap are held, and it is fitted
        # again.
        near = _overlap_points(tb, uvw)
        env = {k: (round(v_, 6) if isinstance(v_, float) else v_) for k, v_ in env.items()}
        env.update(held=int(hold.sum()), rounds=attempt + 1)
        if near is None:
            return tb, {**fit, "envelope": env}, False
        last_env = env
        if not np.any(near & ~hold):
            break
        hold |= near
    return last[0], {**last[1], "envelope": last_env}, True


#: fits of :func:`_envelope_fitted`, each holding the points near where the last one's boundary overlapped itself
ENVELOPE_ROUNDS = 4
#: how near (knot spans, per axis) a point must lie to an overlap of the boundary to be held
OVERLAP_SPANS = 1.0


def _boundary_crossings(tb):
    """The parameters (k, 3) of the triangles where the TBSS's boundary surface
    (:func:`porecad.maps.domain_surface.tbss_surface`) passes through itself, or None where it does not."""
    from ..maps.domain_surface import tbss_surface
    from ..mesh.intersections import self_intersections
    sv, sf, pv = tbss_surface(tb, return_params=True)
    pairs, total = self_intersections(sv, sf, max_report=1 << 16)
    if total == 0:
        return None
    bad = np.unique(np.asarray(pairs, dtype=np.int64).ravel())
    return pv[sf[bad]].mean(axis=1)


def _overlap_points(tb, uvw):
    """Which of the parameters ``uvw`` lie near where the TBSS's boundary passes through itself (None: nowhere):
    within :data:`OVERLAP_SPANS` knot spans, per axis, of a crossing triangle's parameters."""
    from scipy.spatial import cKDTree
    centres = _boundary_crossings(tb)
    if centres is None:
        return None
    dom = np.asarray(tb.domain, dtype=np.float64)
    span = np.array([OVERLAP_SPANS * (dom[a, 1] - dom[a, 0]) / max(tb.n_ctrl[a] - tb.degrees[a], 1) for a in range(3)])
    d, _ = cKDTree(centres / span).query(np.asarray(uvw, dtype=np.float64) / span, p=np.inf,
                                         distance_upper_bound=1.0)
    return np.isfinite(d)


# ---------------------------------------------------------------- slicing
def _slice_loops(v, f, axis, h):
    """Closed loops (lists of 3-D points) of the section ``x · axis = h`` of a closed mesh."""
    s = v @ axis - h
    ext = float(np.ptp(s))
    eps = 1e-9 * max(ext, 1.0)
    if np.any(np.abs(s) < eps):         # move the plane off vertices
        s = s - 2 * eps
    sf = s[f]
    pos = sf > 0
    npos = pos.sum(axis=1)
    tri = np.flatnonzero((npos == 1) | (npos == 2))
    if tri.size == 0:
        return []
    ft, st, pt = f[tri], sf[tri], pos[tri]
    keys, pts = [], []
    for e0, e1 in ((0, 1), (1, 2), (2, 0)):
        a, b = ft[:, e0], ft[:, e1]
        cross = pt[:, e0] != pt[:, e1]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        keys.append(np.where(cross, lo * len(v) + hi, -1))
        sa, sb = st[:, e0], st[:, e1]
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = np.where(cross, sa / (sa - sb), 0.0)
        pts.append(v[a] + tt[:, None] * (v[b] - v[a]))
    keys = np.stack(keys, axis=1)
    pts = np.stack(pts, axis=1)
    # the two crossing edges of every triangle
    order = np.argsort(keys < 0, axis=1, kind="stable")[:, :2]
    ka = np.take_along_axis(keys, order, axis=1)
    pa = np.take_along_axis(pts, order[:, :, None], axis=1)
    uk, inv = np.unique(ka.ravel(), return_inverse=True)
    inv = inv.reshape(-1, 2)
    node_pt = np.zeros((len(uk), 3))
    node_pt[inv[:, 0]] = pa[:, 0]
    node_pt[inv[:, 1]] = pa[:, 1]
    deg = np.bincount(inv.ravel(), minlength=len(uk))
    if np.any(deg != 2):
        raise InputError("the body mesh is not closed (a section has open ends)")
    # adjacency: two neighbours per node
    nb = np.full((len(uk), 2), -1, np.int64)
    fill = np.zeros(len(uk), np.int64)
    for a_, b_ in inv:
        nb[a_, fill[a_]] = b_
        fill[a_] += 1
        nb[b_, fill[b_]] = a_
        fill[b_] += 1
    seen = np.zeros(len(uk), bool)
    loops = []
    for start in range(len(uk)):
        if seen[start]:
            continue
        loop = [start]
        seen[start] = True
        prev, cur = -1, start
        while True:
            nxt = nb[cur, 0] if nb[cur, 0] != prev else nb[cur, 1]
            if nxt == start or seen[nxt]:
                break
            loop.append(nxt)
            seen[nxt] = True
            prev, cur = cur, nxt
        loops.append(node_pt[loop])
    return loops


def _star_about_centroid(loop, axis, e1, e2):
    xy, area, c = polygon_frame(loop, axis, e1, e2)
    return area != 0.0 and star_about(xy, c)


def _fit_sliced(v, f, n_ctrl, degree, grid, levels=None):
    vol_body, cen = _volume_centroid(v, f)
    X = v - cen
    _, vec = np.linalg.eigh(X.T @ X)
    ax = vec[:, -1] * np.sign(vec[np.argmax(np.abs(vec[:, -1])), -1])   # largest component > 0
    ax, e1, e2 = axis_frame(ax)
    proj = v @ ax
    lo, hi = proj.min(), proj.max()
    nl = int(levels) if levels is not None else max(4 * grid, 8 * n_ctrl[2])
    hs = lo + (hi - lo) * (np.arange(nl) + 0.5) / nl
    good = np.zeros(nl, bool)
    loops = [None] * nl
    for k, h in enumerate(hs):
        ls = _slice_loops(v, f, ax, h)
        if len(ls) == 1 and len(ls[0]) >= 3 and _star_about_centroid(ls[0], ax, e1, e2):
            good[k] = True
            loops[k] = ls[0]
    # longest run of good levels
    best, bs, run, rs = 0, 0, 0, 0
    for k in range(nl):
        if good[k]:
            if run == 0:
                rs = k
            run += 1
            if run > best:
                best, bs = run, rs
        else:
            run = 0
    if best < max(n_ctrl[2], 4):
        raise InputError(f"only {best} consecutive sections along the body's long axis are single "
                         "star-shaped loops; cannot loft a TBSS (try the `fit` radial)")
    idx = np.unique(np.round(np.linspace(bs, bs + best - 1, min(best, max(grid, n_ctrl[2])))).astype(int))
    curves = [loops[k] for k in idx]
    tb = loft_tbss(curves, heights=hs[idx], n_ctrl=n_ctrl, degree=degree, axis=ax)
    info = tb.check_jacobian()
    rms, dmax = _surface_distance(tb, v, f, faces=("u0", "u1", "v0", "v1"))
    return tb, {"method": "sliced", "axis": tuple(float(x) for x in ax),
                "levels": (float(hs[idx[0]]), float(hs[idx[-1]])), "sections": int(len(idx)),
                "length_fraction": float((hs[idx[-1]] - hs[idx[0]]) / (hi - lo)),
                "rms_distance": rms, "max_distance": dmax,
                "covered_fraction": tb.volume() / abs(vol_body),
                "min_det": info["min_det"], "mean_det": info["mean_det"]}


def fit_tbss_to_mesh(vertices, faces, method: str = "auto", n_ctrl=(8, 8, 8), centre=None,
                     grid: int = 32, degree=3, untangle=None, progress=None, inflate: float = 0.0,
                     cover: bool = False, balance: int = STRETCH_BALANCE):
    """Fit a TBSS to a closed triangle mesh (a body), in the mesh's units (mm).

    ``method="radial"`` (star-shaped bodies): the boundary nodes ``q`` of an
    ``grid³`` grid on ``[-1, 1]^3`` go to the surface point on the ray from
    ``centre`` (default: the volume centroid) toward ``q/|q|`` (ray-triangle
    intersection, Möller & Trumbore 1997; every ray must cross the surface
    exactly once), the interior nodes by discrete Laplace smoothing with the
    boundary fixed, the control points by least squares.

    ``method="sliced"`` (elongated bodies): sections perpendicular to the
    principal (largest-variance) axis at ``max(4 grid, 8 n3)`` levels; the
    longest run of levels whose section is one closed loop, star-shaped about
    its centroid, is kept (the ends are trimmed) and lofted
    (:func:`loft_tbss`) through ``grid`` of them.

    ``method="hex"`` (any closed genus-0 body): the hexahedral cube
    parameterisation of the body (000 ch.3, :func:`porecad.param.hex_parameterisation`)
    sampled on ``2 n + 2`` cells per axis, fitted by least squares: the whole
    body is covered.

    ``method="auto"``: radial when the body is star-shaped about its
    centroid, else hex; a plain fit folded through more than
    :data:`FOLDED_SHARE_MAX` of its volume (:func:`folded_share`) is not
    untangled: the radial one gives way to the hex fit (``radial_refused``
    says why), which must then need no untangling (else :class:`FoldedFit`).

    ``cover`` (hex): fit every vertex of the surface too, at its cube
    parameters, and push the fit out where it passes inside one
    (:func:`_envelope_fitted`, :func:`porecad.splines.lspia.fit_envelope`),
    so that the TBSS covers the body without a uniform margin; the TBSS
    then reaches past the surface between the vertices it pushes out for,
    which a scaffold cut to the body (:func:`porecad.maps.tbss.tbss_scaffold`
    with ``clip``) does not see. Where its boundary would pass through
    itself (the gap between the bunny's ears), the points near the overlap
    are held and, failing that, only part of the push is taken
    (``envelope``: ``held``, ``rounds``, ``pushed_share``). Of the push
    strengths :data:`ENVELOPE_STRENGTHS` the fit covering most of the body
    is kept (``envelope``: ``pushes``, ``relax``, ``covered_fraction``).
    Measured at ``n_ctrl=8`` (vol(body ∩ TBSS) / vol(body), extents of
    body ∩ TBSS), with harmonic patch maps (``balance=0``): the femur 99.2 %
    against 97.05 % plain, extents 0.5 % against 4.3 %; the bunny 99.6 %
    against 98.5 %, extents 2.1 % against 3.5 %; with the default balanced
    maps the femur 99.8 % (extents 0.09 %), the bunny 99.9 % (1.1 %). Where that fit cannot be
    made (its untangling fails), or it folds where the plain fit does not
    (a limb the cube map does not reach), the plain fit is kept and
    ``envelope`` says why.

    ``balance`` (hex): rounds of stretch balancing of the cube map's patch
    maps (:data:`STRETCH_BALANCE`; 0: the harmonic maps of 000 §3.5). A
    harmonic map squeezes a protrusion toward a face's corner, where no
    grid node and no spline span reaches it and pushing the fit out for it
    folds the fit's boundary; balanced, the bunny's ear tip is in the fit
    (extents 2.07 % -> 1.1 %, no points held).

    ``inflate`` (mm, radial and hex): the sample grid's boundary is pushed
    that far outwards before the fit (radial: along its rays, so a
    star-shaped body stays star-shaped; hex: along the grid's boundary
    normals; the interior following by the Laplace equation;
    ``"auto"``: :func:`cover_margin` for a radial fit, none for a hex fit.
    Measured with the bench's scaffold (gyroid sheet, 4 periods, resolution
    12): a hex fit covers more with a margin (the femur 98.9 % of the body at
    1 mm against 97.1 %; the bunny 99.4 % at 2 mm against 98.5 %), but its
    offset along the normals overlaps itself in concave parts: the bunny at
    4 mm and the segmented body at 0.38 mm gave mapped scaffolds whose
    crossings could not be refined away within 5 minutes. Give ``margin`` to
    trade that risk for coverage), so that the TBSS covers the body
    and a scaffold can be cut to the body itself
    (:func:`porecad.maps.tbss.tbss_scaffold` with ``clip``); the distances
    and extents reported are then those of the inflated fit.

    A radial or hex fit that folds (noise, or the cube's edges on a smooth
    surface) is untangled against its Jacobian
    (:func:`porecad.splines.untangle.untangle_tbss`, options in ``untangle``:
    ``max_iterations``, ``time_limit``, ...; ``untangle=False`` refuses instead).

    Returns
    -------
    tbss : TBSS
    diagnostics : dict
        ``method``, ``rms_distance`` / ``max_distance`` (mm, TBSS boundary
        samples to the surface; for "sliced" the side faces only),
        ``covered_fraction`` (TBSS volume / body volume), ``extent_error``
        (largest relative difference of the bounding-box sides),
        ``min_det`` / ``mean_det``, ``min_scaled_jacobian``, ``untangled``
        (and ``untangle``: iterations, rounds, largest move in mean sample
        spacings, time); "radial" adds ``centre``, "sliced" ``axis``,
        ``levels``, ``sections``, ``length_fraction``, "hex" ``corner_choice``,
        ``sample_cells`` and with ``cover`` ``envelope`` (``undercut_before``
        / ``undercut``: mm by which the fit passes inside a surface vertex,
        ``iterations``, ``points``; or ``refused`` with the reason).
    """
    v, f = _mesh_arrays(vertices, faces)
    n = as3(n_ctrl, "n_ctrl")
    grid = int(grid)
    if grid < max(n) or grid < 4:
        raise InputError(f"grid {grid} is too coarse for {n} control points")
    auto = method == "auto"
    if auto:
        method = "radial" if star_shaped(v, f, centre, rays=max(grid, 16)) else "hex"
    margin = inflate

    def inflation(method):
        out = margin
        if out == "auto":  # a cube map's offset along its normals overlaps itself in concave parts
            out = cover_margin(v, f) if method == "radial" else 0.0
        out = float(out)
        if not (np.isfinite(out) and out >= 0):
            raise InputError(f"inflate must be a non-negative distance (mm), got {out!r}")
        return out

    inflate = inflation(method)
    refused = None
    if method == "radial":
        try:
            tb, info = _fit_radial(v, f, n, degree, centre, grid, untangle, inflate,
                                   fold_limit=FOLDED_SHARE_MAX if auto else None)
        except FoldedFit as err:  # auto only: the cube map's fit instead
            refused, method = err.detail, "hex"
            inflate = inflation(method)
    if method == "sliced":
        if inflate:
            raise InputError("inflate applies to radial and hex fits, not to the sliced fit")
        tb, info = _fit_sliced(v, f, n, degree, grid)
    elif method == "hex":
        try:
            tb, info = _fit_hex(v, f, n, degree, untangle, progress, inflate=inflate, envelope=bool(cover),
                                balance=balance, fold_limit=None if refused is None else 0.0)
        except FoldedFit as err:
            raise FoldedFit(f"{refused}; {err.detail}") from None
    elif method != "radial":
        raise InputError(f"unknown TBSS fitting method {method!r}; use 'auto', 'radial', 'sliced' or 'hex'")
    info["inflate"] = inflate
    if refused is not None:
        info["radial_refused"] = refused
    return tb, info
