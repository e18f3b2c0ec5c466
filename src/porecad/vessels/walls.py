"""Thin implicit patches: layered, porous vessel walls on a sampled lumen field (003 ch. 4).

**Approximate distance** (003 Def. 4.5, Eq. 4.10, Taubin 1991)::

    d̃(X) = f(X) / |∇f(X)|

with ``∇f`` by central differences on the grid (003 Eqs. 4.11–4.12) and,
where ``|∇f| = 0``, the mean gradient magnitude of the neighbouring samples.

**Shells.** 003 writes the TIP as ``Ξ = S̄_{d0} \\ S̄_{d1}`` (Eq. 4.13) with
``S̄_d = Z(d̃) + d`` (Def. 4.6), but its ``\\`` operand order for shells is
inconsistent (notes §3.1 errata: Eq. 4.15 as printed is empty under
Eq. 2.8). porecad uses the unambiguous band between two signed offsets
``a < b`` (outward positive)::

    band_{a,b}(X) = max(d̃(X) − b, a − d̃(X))        (≤ 0  ⇔  a ≤ d̃ ≤ b)

A wall with layer thicknesses ``t_1 .. t_m`` outside the lumen surface has
offsets ``d_0 = 0, d_i = t_1 + … + t_i``.

**Multi-layer wall with porous layers** (003 Eqs. 4.16–4.18, with the
corrected indices of the notes §3.7: the printed general form of Eq. 4.17 is
off by one; its own 3-layer case Eq. 4.18 uses ``d1–d2, d3–d4, d5–d6``)::

    Ξ⁺   = band_{d_0, d_m}                          (the whole wall)
    Ξ_k# = band_{d_{k-1}, d_k} \\ ℵ_k               (layer k's voids)
    Ξ    = Ξ⁺ \\ Ξ_k# \\ …                          (sharp g_sub, 003 Eq. 2.8)

where ``ℵ_k = {φ_k ≤ 0}`` is the porous structure kept as material in layer
``k``: in field form ``Ξ = max(Ξ⁺, min(−band_k, φ_k), …)``. Porous fields: any
TPMS of :mod:`porecad.fields.tpms` (``G``, ``P``, ``D``, … with cell size L;
material ``φ ≤ 0``, one of the two labyrinths) or 003's periodic fields
(003 §4.3, Fig. 4.17), rescaled so one period is ``L``:

``ellipsoids``  ``cos(2u)·sin(3v)·cos(4w) − 1/2`` (Fig. 4.17b; ``u = πx/L`` …)
``irregular``   ``2 − cos(2u + πv) − cos(2u − πv) − cos(2v + πw) − cos(2v − πw)
                − cos(2w − πu) − cos(2w + πu)`` (Fig. 4.17c; ``u = x/L``…)
``boxes``       ``sign(sin(u/2)) + sign(sin(v/2)) + sign(sin(w/2)) + 1/2``
                (Fig. 4.17a; ``u = 2πx/L``…)

For 4.17b the region ``{f > 0}`` is the isolated ellipsoid-like blobs, so in
003's use (``Ξ_k# = Ξ_k⁻ \\ ℵ``) those become closed **voids** in the layer;
porecad keeps that meaning: material of the layer is ``{φ ≤ 0}``.

**Open ends** are trimmed by planes (003 §4.5: open patches are trimmed): at
each end node ``p`` with outward tangent ``n``, the solid beyond the plane
``n·(x − p) = 0`` within a ball of radius ``2 (r + T)`` is removed.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage

PERIODIC_003 = ("ellipsoids", "irregular", "boxes")


@dataclasses.dataclass(frozen=True)
class PorousLayer:
    """A porous wall layer: its number (1 = innermost), its porous field (a TPMS type or one of
    :data:`PERIODIC_003`, :func:`porous_values`) and the field's period (mm)."""

    layer: int
    type: str
    cell_size: float


def approximate_distance(F: np.ndarray, spacing) -> np.ndarray:
    """``d̃ = F / |∇F|`` on a grid array ``F[z, y, x]`` (003 Eq. 4.10–4.12)."""
    hx, hy, hz = (float(s) for s in spacing)
    F = np.asarray(F, dtype=np.float32)
    gz, gy, gx = np.gradient(F, hz, hy, hx)
    g = np.sqrt(gx * gx + gy * gy + gz * gz)
    bad = g < 1e-6
    if np.any(bad):
        mean = ndimage.uniform_filter(np.where(bad, 0.0, g), size=3)
        cnt = ndimage.uniform_filter((~bad).astype(np.float32), size=3)
        fix = np.where(cnt > 0, mean / np.maximum(cnt, 1e-12), 1.0)
        g = np.where(bad, np.maximum(fix, 1e-6), g)
    return (F / g).astype(np.float32)


def band(d, a: float, b: float):
    """``max(d − b, a − d)``: negative where ``a ≤ d ≤ b``."""
    return np.maximum(d - b, a - d)


def porous_values(kind: str, cell_size: float, xs, ys, zs) -> np.ndarray:
    """Porous field φ on the tensor grid, material where ``φ ≤ 0`` (module docstring)."""
    L = float(cell_size)
    x = np.asarray(xs, float)[None, None, :]
    y = np.asarray(ys, float)[None, :, None]
    z = np.asarray(zs, float)[:, None, None]
    if kind == "ellipsoids":
        u, v, w = np.pi * x / L, np.pi * y / L, np.pi * z / L  # cos(2u) has period L
        val = np.cos(2 * u) * np.sin(3 * v) * np.cos(4 * w) - 0.5
    elif kind == "irregular":
        u, v, w = x / L, y / L, z / L
        val = (2 - np.cos(2 * u + np.pi * v) - np.cos(2 * u - np.pi * v) - np.cos(2 * v + np.pi * w)
               - np.cos(2 * v - np.pi * w) - np.cos(2 * w - np.pi * u) - np.cos(2 * w + np.pi * u))
    elif kind == "boxes":
        u, v, w = 2 * np.pi * x / L, 2 * np.pi * y / L, 2 * np.pi * z / L
        val = np.sign(np.sin(u / 2)) + np.sign(np.sin(v / 2)) + np.sign(np.sin(w / 2)) + 0.5
    else:
        from ..fields.tpms import TPMSField
        return TPMSField(kind, cell_size=L).sample_grid(xs, ys, zs)
    return np.ascontiguousarray(np.broadcast_to(val, (len(zs), len(ys), len(xs))), dtype=np.float32)


def wall_field(d: np.ndarray, thicknesses, porous: dict | None = None) -> np.ndarray:
    """Multi-layer wall (003 Eqs. 4.16–4.18, corrected) from the approximate distance ``d``.

    ``porous`` maps a layer number (1-based, from the lumen out) to its
    porous field values φ on the same grid.
    """
    off = np.concatenate([[0.0], np.cumsum(thicknesses)])
    out = band(d, off[0], off[-1])
    for k, phi in (porous or {}).items():
        lk = band(d, off[k - 1], off[k])
        out = np.maximum(out, np.minimum(-lk, phi))
    return out.astype(np.float32)


def trim_ends(F: np.ndarray, xs, ys, zs, ends, wall: float) -> np.ndarray:
    """Cut the solid ``F`` flat at every open end (module docstring)."""
    x = np.asarray(xs, float)[None, None, :]
    y = np.asarray(ys, float)[None, :, None]
    z = np.asarray(zs, float)[:, None, None]
    out = F
    for p, n, r in ends:
        rho = 2.0 * (r + wall)
        plane = n[0] * (x - p[0]) + n[1] * (y - p[1]) + n[2] * (z - p[2])
        ball = np.sqrt((x - p[0]) ** 2 + (y - p[1]) ** 2 + (z - p[2]) ** 2) - rho
        cut = np.maximum(-plane, ball)  # ≤ 0 in the removed region
        out = np.maximum(out, -cut)
    return out.astype(np.float32)
