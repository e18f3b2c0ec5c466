"""Discrete threshold distribution fields (TDF) on the parametric grid of a TBSS (document 001, §3.2).

The cubic parameter domain ``[0, 1]^3`` of a trivariate B-spline solid is
sampled on an ``N1 x N2 x N3`` *parametric grid*; vertex ``(i, j, k)`` has the
parameters ``(i / (N1 - 1), j / (N2 - 1), k / (N3 - 1))`` (001: "the subscripts
of the grid vertices are the natural parametrization, normalized into [0, 1]").
A discrete TDF assigns a value to every vertex, by one of 001's three methods:

* **layer** (:func:`layer_values`): vertices are grouped into layers — by one
  parameter (001 Fig. 9: same ``w`` → same layer) or by their index distance
  from the boundary faces (001 Fig. 8: the side faces are the first layer, their
  neighbours the second, ...) — and every vertex of a layer gets the same value;
* **filling** (:func:`fill_values`): the mean or Gaussian curvature of the TBSS
  boundary surface at the boundary vertices, diffused into the interior by
  Laplace smoothing (here solved exactly: the discrete harmonic interpolant);
* **prescribed function** (:func:`function_values`): a numpy expression in
  ``u, v, w`` (and the physical ``x, y, z`` of the TBSS).

Then "the values at the grid vertices are linearly transformed into the valid
threshold range" (:func:`to_threshold_range`), and the result is fitted by a
trivariate B-spline with LSPIA (:mod:`porecad.splines.lspia`).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

PARAM_AXES = {"u": 0, "v": 1, "w": 2}
#: a default inset of the valid threshold range: the B-spline fit of a stepped
#: layer field overshoots a little, and the range's edges are borderline structures
RANGE_INSET = 0.1


def grid_params(shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parameters ``i / (N - 1)`` of the parametric grid along u, v, w."""
    shape = _check_shape(shape)
    return tuple(np.linspace(0.0, 1.0, n) for n in shape)


def _check_shape(shape) -> tuple[int, int, int]:
    s = tuple(int(n) for n in np.broadcast_to(np.asarray(shape), (3,)))
    if min(s) < 2:
        raise InputError(f"the parametric grid needs at least 2 vertices per axis, got {s}")
    if np.prod(s, dtype=np.int64) > 64_000_000:
        raise InputError(f"parametric grid {s} is too large (at most 64 million vertices)")
    return s


def layer_index(shape, by: str = "w", n_layers: int | None = None) -> tuple[np.ndarray, int]:
    """Layer number of every grid vertex and the number of layers.

    Parameters
    ----------
    shape : (3,) int
        Parametric grid size ``(N1, N2, N3)``.
    by : {'u', 'v', 'w', 'sides', 'boundary'}
        ``u``/``v``/``w``: layers of constant parameter (001 Fig. 9).
        ``sides``: index distance from the four side faces (``u`` and ``v``
        faces; 001 Fig. 8); ``boundary``: from all six faces.
    n_layers : int, optional
        Group the planes (or distance shells) into this many equal layers;
        default: every plane (shell) is a layer.
    """
    shape = _check_shape(shape)
    if by in PARAM_AXES:
        a = PARAM_AXES[by]
        idx = np.arange(shape[a])
        raw = idx.reshape([-1 if b == a else 1 for b in range(3)])
        count = shape[a]
    elif by in ("sides", "boundary"):
        axes = (0, 1) if by == "sides" else (0, 1, 2)
        raw = None
        for a in axes:
            i = np.arange(shape[a])
            d = np.minimum(i, shape[a] - 1 - i).reshape([-1 if b == a else 1 for b in range(3)])
            raw = d if raw is None else np.minimum(raw, d)
        count = int(max(min(shape[a] for a in axes) + 1, 2) // 2)
    else:
        raise InputError(f"unknown layer direction {by!r}; use u, v, w, sides or boundary")
    raw = np.broadcast_to(raw, shape)
    if n_layers is None:
        return np.ascontiguousarray(raw, dtype=np.int64), int(count)
    n_layers = int(n_layers)
    if not 1 <= n_layers <= count:
        raise InputError(f"`layers` must be between 1 and {count} for this grid, got {n_layers}")
    return np.ascontiguousarray((raw * n_layers) // count, dtype=np.int64), n_layers


def layer_values(shape, by: str = "w", n_layers: int | None = None, values=None) -> np.ndarray:
    """Layer method (001 §3.2): every vertex of a layer gets the same value.

    ``values`` (one per layer) defaults to ``0, 1/(L-1), ..., 1`` — a stepped
    ramp that :func:`to_threshold_range` then maps into the threshold range.
    """
    layer, count = layer_index(shape, by, n_layers)
    if values is None:
        values = np.linspace(0.0, 1.0, count) if count > 1 else np.zeros(1)
    values = np.asarray(values, dtype=np.float64).ravel()
    if values.size != count:
        raise InputError(f"{count} layers need {count} values, got {values.size}")
    return values[layer]


#: the variables of a TDF expression or edit condition (``x, y, z`` need a TBSS)
TDF_VARIABLES = ("u", "v", "w", "x", "y", "z")


def function_values(expr: str, shape, tbss=None) -> np.ndarray:
    """Prescribed-function method: a numpy expression in ``u, v, w`` (and ``x, y, z`` with a TBSS).

    Example: ``"0.5 + 0.5 * sin(2 * pi * w)"``. Parsed and checked by the
    safe evaluator :mod:`porecad.expressions` (nothing is ``eval``-ed).
    """
    from ..expressions import ExpressionError, compile_expression
    try:
        compiled = compile_expression(expr, TDF_VARIABLES)
    except ExpressionError as exc:
        raise InputError(f"TDF expression: {exc}") from None
    if tbss is None and compiled.names & {"x", "y", "z"}:
        raise InputError("TDF expression uses x, y or z: those need a TBSS; use u, v, w")
    shape = _check_shape(shape)
    us, vs, ws = grid_params(shape)
    env = {"u": us[:, None, None], "v": vs[None, :, None], "w": ws[None, None, :]}
    if compiled.names & {"x", "y", "z"}:
        xyz = tbss.evaluate_grid(us, vs, ws)
        env.update(x=xyz[..., 0], y=xyz[..., 1], z=xyz[..., 2])
    val = compiled(**env)
    out = np.array(np.broadcast_to(val, tuple(len(a) for a in (us, vs, ws))))
    if not np.all(np.isfinite(out)):
        raise InputError("TDF expression gives non-finite values on the parametric grid")
    return out


def boundary_mesh(shape) -> tuple[np.ndarray, np.ndarray]:
    """The closed quad-split triangle mesh of the boundary of the parametric grid.

    Returns ``(index, faces)``: ``index`` (n, 3) grid indices of the boundary
    vertices, ``faces`` (m, 3) into them, oriented outward of the unit cube.
    """
    shape = _check_shape(shape)
    ids = -np.ones(shape, dtype=np.int64)
    on = np.zeros(shape, dtype=bool)
    for a in range(3):
        sl = [slice(None)] * 3
        for end in (0, -1):
            sl[a] = end
            on[tuple(sl)] = True
    index = np.argwhere(on)
    ids[tuple(index.T)] = np.arange(len(index))
    faces = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        for end, outward in ((0, False), (shape[a] - 1, True)):
            sl = [slice(None)] * 3
            sl[a] = end
            plane = ids[tuple(sl)]           # axes (b, c) in increasing order of axis number
            if b > c:
                plane = plane.T              # now indexed [b, c]
            q00, q10 = plane[:-1, :-1], plane[1:, :-1]
            q01, q11 = plane[:-1, 1:], plane[1:, 1:]
            # (b, c, a) is right-handed: quads b→c wind about +a
            t1 = np.stack([q00, q10, q11], axis=-1).reshape(-1, 3)
            t2 = np.stack([q00, q11, q01], axis=-1).reshape(-1, 3)
            tri = np.concatenate([t1, t2])
            faces.append(tri if outward else tri[:, ::-1])
    return index, np.concatenate(faces)


def fill_values(tbss, shape, quantity: str = "mean", clip_percentile: float = 2.0) -> np.ndarray:
    """Filling method (001 §3.2, Fig. 7): boundary curvature diffused inward.

    The boundary vertices of the parametric grid are mapped onto the TBSS
    boundary surface; the discrete mean (cotangent Laplacian) or Gaussian
    (angle deficit) curvature of that closed surface is assigned to them
    (clipped to the ``[p, 100 - p]`` percentiles, so the creases where cube
    edges map do not dominate), and the interior is the discrete harmonic
    interpolant — the fixed point of 001's Laplace smoothing — solved
    exactly with a type-I discrete sine transform (:func:`harmonic_fill`).
    """
    from ..analysis.curvature import vertex_curvatures
    if quantity not in ("mean", "gaussian"):
        raise InputError(f"fill quantity must be 'mean' or 'gaussian', got {quantity!r}")
    shape = _check_shape(shape)
    index, faces = boundary_mesh(shape)
    params = np.stack([index[:, a] / (shape[a] - 1) for a in range(3)], axis=1)
    points = tbss.map_points(params)
    H, K, _ = vertex_curvatures(points, faces)
    q = H if quantity == "mean" else K
    q = np.where(np.isfinite(q), q, np.nanmedian(q))
    lo, hi = np.percentile(q, [clip_percentile, 100.0 - clip_percentile])
    q = np.clip(q, lo, hi)
    boundary = np.zeros(shape)
    boundary[tuple(index.T)] = q
    return harmonic_fill(boundary)


def harmonic_fill(values: np.ndarray) -> np.ndarray:
    """Fill the interior of a 3D grid from its boundary values by the discrete Laplace equation.

    The fixed point of 001's Laplace smoothing, solved exactly
    (:func:`porecad.splines.construct.laplace_fill`, a type-I sine transform).
    """
    from ..splines.loft import laplace_fill
    f = np.asarray(values, dtype=np.float64)
    return f.copy() if min(f.shape) < 3 else laplace_fill(f, 3)


def default_threshold_range(tpms_type: str, structure: str, inset: float = RANGE_INSET) -> tuple[float, float]:
    """The valid threshold range of a type and structure, shrunk by ``inset`` of its width at each end."""
    from ..calibration import checked_range
    lo, hi = checked_range(tpms_type, structure, "threshold")
    d = (hi - lo) * inset
    return float(lo + d), float(hi - d)


def to_threshold_range(raw: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Linear map of a discrete TDF onto ``[lo, hi]`` (001: "linearly transformed into the valid range").

    ``C = lo + (hi - lo) (t - min t) / (max t - min t)``; a constant field maps to the middle.
    """
    t = np.asarray(raw, dtype=np.float64)
    tmin, tmax = float(t.min()), float(t.max())
    if tmax - tmin <= 1e-12 * max(1.0, abs(tmax)):
        return np.full_like(t, 0.5 * (lo + hi))
    return lo + (hi - lo) * (t - tmin) / (tmax - tmin)
