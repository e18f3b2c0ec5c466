"""Post-processing of a 6 × 6 elasticity tensor: engineering constants, directional modulus, bounds, fits.

Voigt order ``(11, 22, 33, 23, 13, 12)`` with engineering shear strains
throughout, so the compliance is ``S = C⁻¹`` and the engineering constants
follow Nye, *Physical Properties of Crystals* (1957), ch. VIII:
``E_i = 1 / S_ii``, ``G_23 = 1 / S_44``, ``G_13 = 1 / S_55``,
``G_12 = 1 / S_66`` and ``ν_ij = -S_ij / S_ii`` (lateral strain ``j`` under
stress along ``i``). The Young's modulus along a unit direction ``d`` is
``1 / E(d) = sᵀ S s`` with ``s = (d1², d2², d3², d2 d3, d1 d3, d1 d2)``
(Nye ch. VIII §4, written in Voigt form).
"""

from __future__ import annotations

import numpy as np

from porecad.errors import InputError

__all__ = ["engineering_constants", "directional_modulus", "directional_modulus_extremes",
           "zener_ratio", "hashin_shtrikman_upper", "laminate_stiffness", "gibson_ashby_fit",
           "fibonacci_directions", "GIBSON_ASHBY_PUBLISHED"]

#: Published Gibson–Ashby exponents ``n`` in ``E*/E_s = C (ρ*/ρ_s)^n`` for comparison (with source).
GIBSON_ASHBY_PUBLISHED = {
    "open-cell foam (bending dominated)": {
        "n": 2.0, "C": 1.0,
        "source": "Gibson & Ashby, Cellular Solids, 2nd ed. (1997), eq. 5.6"},
    "stretching-dominated lattice": {
        "n": 1.0, "C": 1 / 3,
        "source": "Deshpande, Ashby & Fleck, Acta Mater. 49 (2001) 1035, Fig. 1 (octet truss)"},
}


def _as_tensor(C) -> np.ndarray:
    C = np.asarray(C, dtype=np.float64)
    if C.shape != (6, 6) or not np.all(np.isfinite(C)):
        raise InputError(f"an elasticity tensor must be a finite 6 x 6 matrix, got shape {C.shape}")
    return 0.5 * (C + C.T)


def _compliance(C: np.ndarray) -> np.ndarray:
    w = np.linalg.eigvalsh(C)
    if w.min() <= 1e-12 * max(w.max(), 1e-300):
        raise InputError("the elasticity tensor is not positive definite (a mechanism or no load path): "
                         "its engineering constants are undefined")
    return np.linalg.inv(C)


def engineering_constants(C) -> dict:
    """Young's moduli, shear moduli, Poisson ratios, bulk modulus and Zener ratio of a tensor.

    Parameters
    ----------
    C : (6, 6) array_like
        Stiffness, Voigt order 11, 22, 33, 23, 13, 12 (engineering shears).

    Returns
    -------
    dict
        ``E1, E2, E3, G23, G13, G12, nu12, nu13, nu21, nu23, nu31, nu32``,
        ``bulk_modulus`` (Reuss, ``1 / Σ_{i,j≤3} S_ij``: the response to
        hydrostatic stress), ``zener_ratio`` (:func:`zener_ratio`).

    Examples
    --------
    >>> from porecad.simulate.hex8 import isotropic_stiffness
    >>> c = engineering_constants(isotropic_stiffness(2.0, 0.25))
    >>> round(c["E1"], 6), round(c["nu12"], 6), round(c["G12"], 6)
    (2.0, 0.25, 0.8)
    """
    C = _as_tensor(C)
    S = _compliance(C)
    out = {f"E{i + 1}": float(1 / S[i, i]) for i in range(3)}
    out.update({"G23": float(1 / S[3, 3]), "G13": float(1 / S[4, 4]), "G12": float(1 / S[5, 5])})
    for i in range(3):
        for j in range(3):
            if i != j:
                out[f"nu{i + 1}{j + 1}"] = float(-S[i, j] / S[i, i])
    out["bulk_modulus"] = float(1 / S[:3, :3].sum())
    out["zener_ratio"] = zener_ratio(C)
    return out


def zener_ratio(C) -> float:
    """Zener anisotropy ratio ``A = 2 C44 / (C11 - C12)`` (1 for an isotropic solid).

    For a tensor that is not exactly cubic the cubic averages
    ``C11 = mean(C11, C22, C33)``, ``C12 = mean(C12, C13, C23)`` and
    ``C44 = mean(C44, C55, C66)`` are used. Zener, *Elasticity and Anelasticity
    of Metals* (1948), p. 16.
    """
    C = _as_tensor(C)
    c11 = np.mean(np.diag(C)[:3])
    c12 = np.mean([C[0, 1], C[0, 2], C[1, 2]])
    c44 = np.mean(np.diag(C)[3:])
    return float(2 * c44 / (c11 - c12)) if c11 != c12 else float("inf")


def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) nearly uniform unit vectors on the sphere (Fibonacci lattice; González, Math. Geosci. 42, 2010)."""
    n = int(n)
    if n < 2 or n > 1_000_000:
        raise InputError(f"number of directions must lie in 2..1000000, got {n}")
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def directional_modulus(C, directions) -> np.ndarray:
    """Young's modulus along each unit direction: ``1 / E(d) = sᵀ S s``.

    Parameters
    ----------
    C : (6, 6) array_like
    directions : (n, 3) array_like
        Normalised here.

    Returns
    -------
    (n,) float64
    """
    S = _compliance(_as_tensor(C))
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    s = np.stack([d[:, 0] ** 2, d[:, 1] ** 2, d[:, 2] ** 2, d[:, 1] * d[:, 2], d[:, 0] * d[:, 2],
                  d[:, 0] * d[:, 1]], axis=1)
    return 1.0 / np.einsum("ni,ij,nj->n", s, S, s)


def directional_modulus_extremes(C, n_theta: int = 37, n_phi: int = 73, refine: int = 2000) -> dict:
    """Extremes of ``E(d)`` and a plot-ready sampling on a (θ, φ) grid.

    The minimum and maximum are searched on ``refine`` Fibonacci directions
    plus the grid, then polished by a local search (scipy Nelder–Mead).

    Returns
    -------
    dict
        ``E_max``, ``E_max_direction``, ``E_min``, ``E_min_direction``,
        ``anisotropy`` (``E_max / E_min``), ``theta_deg`` (n_theta,),
        ``phi_deg`` (n_phi,), ``E`` (n_theta × n_phi nested lists, polar
        angle θ from z, azimuth φ from x).
    """
    from scipy.optimize import minimize

    C = _as_tensor(C)
    th = np.linspace(0, np.pi, n_theta)
    ph = np.linspace(0, 2 * np.pi, n_phi)
    T, P = np.meshgrid(th, ph, indexing="ij")
    grid_dirs = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1).reshape(-1, 3)
    Eg = directional_modulus(C, grid_dirs).reshape(T.shape)
    cand = np.concatenate([grid_dirs, fibonacci_directions(refine)])
    Ec = directional_modulus(C, cand)

    def polish(sign, d0):
        def f(a):
            d = np.array([np.sin(a[0]) * np.cos(a[1]), np.sin(a[0]) * np.sin(a[1]), np.cos(a[0])])
            return sign * directional_modulus(C, d[None])[0]
        a0 = [np.arccos(np.clip(d0[2], -1, 1)), np.arctan2(d0[1], d0[0])]
        r = minimize(f, a0, method="Nelder-Mead", options={"xatol": 1e-8, "fatol": 1e-12})
        d = np.array([np.sin(r.x[0]) * np.cos(r.x[1]), np.sin(r.x[0]) * np.sin(r.x[1]), np.cos(r.x[0])])
        return sign * r.fun, d

    emax, dmax = polish(-1, cand[np.argmax(Ec)])
    emin, dmin = polish(1, cand[np.argmin(Ec)])
    emax, emin = max(emax, Ec.max()), min(emin, Ec.min())
    return {"E_max": float(emax), "E_max_direction": np.round(dmax, 6).tolist(),
            "E_min": float(emin), "E_min_direction": np.round(dmin, 6).tolist(),
            "anisotropy": float(emax / emin), "theta_deg": np.degrees(th).tolist(),
            "phi_deg": np.degrees(ph).tolist(), "E": Eg.tolist()}


def hashin_shtrikman_upper(E: float, nu: float, solid_fraction: float) -> dict:
    """Hashin–Shtrikman upper bounds on the bulk and shear moduli of a porous isotropic solid.

    With void as the second phase (zero moduli) the lower bounds are zero;
    the upper bounds are (Hashin & Shtrikman, *J. Mech. Phys. Solids* 11
    (1963) 127, eqs. 3.36–3.37, with phase 2 = void)

    .. math:: K_U = K + \\frac{1 - f}{-1/K + 3 f / (3K + 4G)}, \\qquad
              G_U = G + \\frac{1 - f}{-1/G + 6 f (K + 2G) / (5 G (3K + 4G))}

    where ``f`` is the solid fraction.

    Returns
    -------
    dict
        ``bulk_upper``, ``shear_upper``, ``young_upper`` (the isotropic
        Young's modulus of the two bounds, ``9KG / (3K + G)``).
    """
    K = E / (3 * (1 - 2 * nu))
    G = E / (2 * (1 + nu))
    f = float(solid_fraction)
    if not 0 < f <= 1:
        raise InputError(f"solid fraction must lie in (0, 1], got {f}")
    ku = K + (1 - f) / (-1 / K + 3 * f / (3 * K + 4 * G))
    gu = G + (1 - f) / (-1 / G + 6 * f * (K + 2 * G) / (5 * G * (3 * K + 4 * G)))
    return {"bulk_upper": float(ku), "shear_upper": float(gu), "young_upper": float(9 * ku * gu / (3 * ku + gu))}


def laminate_stiffness(materials, fractions) -> np.ndarray:
    """Exact effective stiffness of a laminate of isotropic layers normal to z.

    Continuity of the in-plane strains and of the traction ``σ_i3`` across
    the layers gives, with ``⟨·⟩`` the volume average over the layers
    (Backus, *J. Geophys. Res.* 67 (1962) 4427, eqs. 10–13; Milton, *The
    Theory of Composites* (2002), §9.5):
    ``C33 = ⟨1/C33⟩⁻¹``, ``C13 = C33 ⟨C13/C33⟩``,
    ``C11 = ⟨C11 - C13²/C33⟩ + C13²/C33`` (effective values on the right),
    ``C12 = ⟨C12 - C13²/C33⟩ + C13²/C33``, ``C44 = C55 = ⟨1/C44⟩⁻¹``,
    ``C66 = ⟨C66⟩``.

    Parameters
    ----------
    materials : sequence of (E, nu)
    fractions : sequence of float
        Volume fractions (summing to 1).

    Returns
    -------
    (6, 6) float64
    """
    from porecad.simulate.hex8 import isotropic_stiffness

    f = np.asarray(fractions, dtype=float)
    if len(f) != len(materials) or abs(f.sum() - 1) > 1e-9 or np.any(f < 0):
        raise InputError("laminate fractions must be non-negative, one per material, summing to 1")
    Cs = [isotropic_stiffness(E, nu) for E, nu in materials]

    def avg(fn):
        return sum(fi * fn(c) for fi, c in zip(f, Cs))

    c33 = 1 / avg(lambda c: 1 / c[2, 2])
    c13 = c33 * avg(lambda c: c[0, 2] / c[2, 2])
    c11 = avg(lambda c: c[0, 0] - c[0, 2] ** 2 / c[2, 2]) + c13 ** 2 / c33
    c12 = avg(lambda c: c[0, 1] - c[0, 2] ** 2 / c[2, 2]) + c13 ** 2 / c33
    c44 = 1 / avg(lambda c: 1 / c[3, 3])
    c66 = avg(lambda c: c[5, 5])
    C = np.zeros((6, 6))
    C[0, 0] = C[1, 1] = c11
    C[0, 1] = C[1, 0] = c12
    C[0, 2] = C[2, 0] = C[1, 2] = C[2, 1] = c13
    C[2, 2] = c33
    C[3, 3] = C[4, 4] = c44
    C[5, 5] = c66
    return C


def gibson_ashby_fit(relative_density, relative_modulus) -> dict:
    """Least-squares fit of ``E*/E_s = C (ρ*/ρ_s)^n`` in log–log coordinates.

    Parameters
    ----------
    relative_density, relative_modulus : array_like
        At least two points with positive values.

    Returns
    -------
    dict
        ``n`` (exponent), ``C`` (prefactor), ``r2`` (coefficient of
        determination in log space), ``points``.

    References
    ----------
    L. J. Gibson, M. F. Ashby, *Cellular Solids*, 2nd ed., Cambridge 1997,
    eq. 5.6 (``E*/E_s = C1 (ρ*/ρ_s)^2`` for open-cell foams).
    """
    rho = np.asarray(relative_density, dtype=float)
    e = np.asarray(relative_modulus, dtype=float)
    ok = (rho > 0) & (e > 0) & np.isfinite(rho) & np.isfinite(e)
    if ok.sum() < 2 or np.ptp(np.log(rho[ok])) == 0:
        raise InputError("a Gibson-Ashby fit needs at least two points with different positive densities and moduli")
    x, y = np.log(rho[ok]), np.log(e[ok])
    n, logc = np.polyfit(x, y, 1)
    pred = n * x + logc
    ss = float(((y - y.mean()) ** 2).sum())
    r2 = 1 - float(((y - pred) ** 2).sum()) / ss if ss > 0 else 1.0
    return {"n": float(n), "C": float(np.exp(logc)), "r2": r2, "points": int(ok.sum())}
