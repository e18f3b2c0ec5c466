"""The TPMS catalogue: nodal (Fourier) approximations of triply periodic minimal surfaces.

Each type is a *sum of products of per-axis trigonometric terms*

.. math:: \\varphi(X, Y, Z) = c_0 + \\sum_t a_t\\, f_t(k_t X)\\, g_t(l_t Y)\\, h_t(m_t Z),

with ``f, g, h`` one of ``cos``, ``sin`` or ``1`` and angular coordinates
``X = 2 pi (x - x0) / L_x`` (one period per cell of size ``L_x`` mm; the
period coefficients of document 001 are ``rho = 1 / L`` in the parameter
domain). On a tensor grid every term factors, so :meth:`TPMSField.sample_grid`
precomputes the 1-D trigonometric rows once and spends a few multiply-adds
per sample (numba, float32) instead of several trigonometric calls.

Sources: 002 Table 1 (P, four-term D, G, I-WP); 000 Table 2.2 and 004 Table 1
(two-term D, F-RD, L, tubular P/G, I2-Y**); Schoen 1970 and Wohlgemuth et al.
2001 / Schnering & Nesper 1991 (Neovius, Fischer-Koch S, split P, Lidinoid).
Errata (``../shared/reference/seed-000-dissertation-notes.md`` section 2.2):
000 prints the two-term D, but its porosity table (002 Table 3) is reproduced
only by the four-term D, so ``D`` is the four-term form and the two-term form
is ``D2``; 000's Lidinoid prints ``cos Y`` in the last product where the
standard form has ``sin Y`` (used here); 004 puts the I2-Y** cosine sum inside
the ``-2[...]`` bracket, 000 outside (the standard form, used here).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InputError
from .base import Field

_TOKEN = re.compile(r"(sin|cos)(\d*)([XYZ])")


@dataclass(frozen=True)
class Term:
    """``coef * prod_axis f_axis(k_axis * angle_axis)``; ``f`` in ``{'1', 'cos', 'sin'}``."""

    coef: float
    funcs: tuple  # (('cos', 1), ('1', 0), ('sin', 2)) for x, y, z


def _terms(*spec) -> tuple:
    """Parse ``(coef, "sin2X cosY sinZ")`` pairs into :class:`Term` objects."""
    out = []
    for coef, product in spec:
        funcs = [("1", 0), ("1", 0), ("1", 0)]
        for fn, k, ax in _TOKEN.findall(product):
            funcs["XYZ".index(ax)] = (fn, int(k) if k else 1)
        out.append(Term(float(coef), tuple(funcs)))
    return tuple(out)


@dataclass(frozen=True)
class TPMSType:
    """One catalogue entry: name, aliases, formula text, source and its terms."""

    name: str
    title: str
    formula: str
    source: str
    terms: tuple
    constant: float = 0.0
    aliases: tuple = ()
    #: level the sheet solid is centred on: material where ``|φ - sheet_level| ≤ C``
    sheet_level: float = 0.0


_CYC = [("X", "Y", "Z"), ("Y", "Z", "X"), ("Z", "X", "Y")]


def _cyc(coef, pattern):
    """Cyclic sum of a product pattern in ``{a} {b} {c}`` (a->X, b->Y, c->Z and its cycles)."""
    return [(coef, pattern.format(a=x, b=y, c=z)) for x, y, z in _CYC]


CATALOGUE: dict[str, TPMSType] = {}


def _add(t: TPMSType):
    CATALOGUE[t.name] = t


_add(TPMSType(
    "P", "Schwarz Primitive", "cos X + cos Y + cos Z", "002 Table 1; 000 Table 2.2",
    _terms(*_cyc(1, "cos{a}")), aliases=("primitive", "schwarz_p", "schwarzp")))
_add(TPMSType(
    "D", "Schwarz Diamond (four-term)",
    "sin X sin Y sin Z + sin X cos Y cos Z + cos X sin Y cos Z + cos X cos Y sin Z",
    "002 Table 1 (reproduces 002 Table 3)",
    _terms((1, "sinX sinY sinZ"), (1, "sinX cosY cosZ"), (1, "cosX sinY cosZ"), (1, "cosX cosY sinZ")),
    aliases=("diamond", "schwarz_d", "schwarzd")))
_add(TPMSType(
    "D2", "Schwarz Diamond (two-term)", "cos X cos Y cos Z - sin X sin Y sin Z",
    "000 Table 2.2; 004 Table 1", _terms((1, "cosX cosY cosZ"), (-1, "sinX sinY sinZ"))))
_add(TPMSType(
    "G", "Schoen Gyroid", "sin X cos Y + sin Y cos Z + sin Z cos X", "002 Table 1; 000 Table 2.2",
    _terms(*_cyc(1, "sin{a} cos{b}")), aliases=("gyroid",)))
_add(TPMSType(
    "IWP", "Schoen I-WP", "2 (cos X cos Y + cos Y cos Z + cos Z cos X) - (cos 2X + cos 2Y + cos 2Z)",
    "002 Table 1; 000 Table 2.2", _terms(*_cyc(2, "cos{a} cos{b}"), *_cyc(-1, "cos2{a}")),
    aliases=("I-WP", "schoen_iwp", "iwp")))
_add(TPMSType(
    "FRD", "Schoen F-RD",
    "4 cos X cos Y cos Z - (cos 2X cos 2Y + cos 2Y cos 2Z + cos 2Z cos 2X)",
    "000 Table 2.2; 004 Table 1", _terms((4, "cosX cosY cosZ"), *_cyc(-1, "cos2{a} cos2{b}")),
    aliases=("F-RD", "schoen_frd", "frd")))
_add(TPMSType(
    "L", "Lidinoid",
    "0.5 (sin 2X cos Y sin Z + sin 2Y cos Z sin X + sin 2Z cos X sin Y)"
    " - 0.5 (cos 2X cos 2Y + cos 2Y cos 2Z + cos 2Z cos 2X) + 0.15",
    "000 Table 2.2 (last product corrected to sin Y, the standard form); the sheet is centred on "
    "φ = 0.15 (see sheet_level)",
    _terms(*_cyc(0.5, "sin2{a} cos{b} sin{c}"), *_cyc(-0.5, "cos2{a} cos2{b}")), constant=0.15,
    aliases=("lidinoid",),
    # The +0.15 of the nodal approximation leaves the side φ < 0 with only 35 % of the
    # cell, joined by thin necks: with |φ| ≤ C that labyrinth breaks into closed pockets
    # for every C > 0.18, so the sheet had no valid range. Centred on φ = 0.15 (the
    # median of φ is 0.144: the level that splits the cell into equal labyrinths) both
    # labyrinths stay open; see calibration.valid_range("L", "sheet").
    sheet_level=0.15))
_add(TPMSType(
    "tubular_P", "Tubular P",
    "10 (cos X + cos Y + cos Z) - 5.1 (cos X cos Y + cos Y cos Z + cos Z cos X) - 14.6",
    "000 Table 2.2", _terms(*_cyc(10, "cos{a}"), *_cyc(-5.1, "cos{a} cos{b}")), constant=-14.6,
    aliases=("tubularP", "tubular-p")))
_add(TPMSType(
    "tubular_G", "Tubular G",
    "10 (cos X sin Y + cos Y sin Z + cos Z sin X) - 0.5 (cos 2X cos 2Y + cos 2Y cos 2Z + cos 2Z cos 2X) - 14",
    "000 Table 2.2", _terms(*_cyc(10, "cos{a} sin{b}"), *_cyc(-0.5, "cos2{a} cos2{b}")), constant=-14.0,
    aliases=("tubularG", "tubular-g")))
_add(TPMSType(
    "I2Y", "I2-Y**",
    "-2 (sin 2X cos Y sin Z + sin X sin 2Y cos Z + cos X sin Y sin 2Z)"
    " + cos 2X cos 2Y + cos 2Y cos 2Z + cos 2Z cos 2X",
    "000 Table 2.2; 004 Table 1",
    _terms((-2, "sin2X cosY sinZ"), (-2, "sinX sin2Y cosZ"), (-2, "cosX sinY sin2Z"),
           *_cyc(1, "cos2{a} cos2{b}")), aliases=("I2-Y**", "I2-Y", "i2y")))
_add(TPMSType(
    "neovius", "Neovius", "3 (cos X + cos Y + cos Z) + 4 cos X cos Y cos Z",
    "Schoen 1970; Wohlgemuth et al. 2001", _terms(*_cyc(3, "cos{a}"), (4, "cosX cosY cosZ")),
    aliases=("C(P)", "N")))
_add(TPMSType(
    "fischer_koch_s", "Fischer-Koch S",
    "cos 2X sin Y cos Z + cos X cos 2Y sin Z + sin X cos Y cos 2Z",
    "Fischer & Koch 1987; Wohlgemuth et al. 2001",
    _terms((1, "cos2X sinY cosZ"), (1, "cosX cos2Y sinZ"), (1, "sinX cosY cos2Z")),
    aliases=("S", "FKS", "fks")))
_add(TPMSType(
    "split_P", "Split P",
    "1.1 (sin 2X sin Z cos Y + sin 2Y sin X cos Z + sin 2Z sin Y cos X)"
    " - 0.2 (cos 2X cos 2Y + cos 2Y cos 2Z + cos 2Z cos 2X) - 0.4 (cos 2X + cos 2Y + cos 2Z)",
    "Wohlgemuth et al. 2001",
    _terms(*_cyc(1.1, "sin2{a} sin{c} cos{b}"), *_cyc(-0.2, "cos2{a} cos2{b}"), *_cyc(-0.4, "cos2{a}")),
    aliases=("splitP", "split-p")))

_ALIASES = {}
for _t in CATALOGUE.values():
    for _n in (_t.name, *_t.aliases):
        _ALIASES[_n.lower().replace("-", "_").replace(" ", "_")] = _t.name
        _ALIASES[_n.lower()] = _t.name


def get_type(name: str | TPMSType) -> TPMSType:
    """Look a type up by name or alias (case-insensitive); raise InputError if unknown. A type is itself."""
    if isinstance(name, TPMSType):
        return name
    key = str(name).strip().lower()
    canon = _ALIASES.get(key) or _ALIASES.get(key.replace("-", "_"))
    if canon is None:
        raise InputError(f"unknown TPMS type {str(name)[:64]!r}; known types: {', '.join(CATALOGUE)}")
    return CATALOGUE[canon]


def list_types() -> list[dict]:
    """The catalogue as plain dicts (name, title, formula, source, aliases)."""
    return [{"name": t.name, "title": t.title, "formula": t.formula, "source": t.source,
             "aliases": list(t.aliases)} for t in CATALOGUE.values()]


def _axis_factor(fn: str, k: int, angle: np.ndarray) -> np.ndarray:
    if fn == "cos":
        return np.cos(k * angle)
    if fn == "sin":
        return np.sin(k * angle)
    return np.ones_like(angle)


@njit(cache=True, nogil=True, fastmath=True)
def _separable_sum(A, B, C, const, out):
    """``out[k, j, i] = const + sum_t A[t, i] B[t, j] C[t, k]`` (float32)."""
    T, nx = A.shape
    ny = B.shape[1]
    nz = C.shape[1]
    bc = np.empty(T, dtype=np.float32)
    for k in range(nz):
        for j in range(ny):
            for t in range(T):
                bc[t] = B[t, j] * C[t, k]
            row = out[k, j]
            for i in range(nx):
                row[i] = const
            for t in range(T):
                w = bc[t]
                if w != 0.0:
                    for i in range(nx):
                        row[i] += A[t, i] * w
    return out


class TPMSField(Field):
    """A TPMS level-set function φ in physical space (not a solid: see :mod:`porecad.solids`).

    Parameters
    ----------
    tpms_type : str
        Catalogue name or alias (``P``, ``D``, ``G``, ``gyroid``, ...).
    cell_size : float or (3,) float
        Period along x, y, z in mm.
    origin : (3,) float
        Where the phase angles are zero.
    """

    def __init__(self, tpms_type: str, cell_size=1.0, origin=(0.0, 0.0, 0.0)):
        self.type = get_type(tpms_type)
        L = np.broadcast_to(np.asarray(cell_size, dtype=np.float64), (3,)).copy()
        if not np.all(np.isfinite(L)) or np.any(L <= 0):
            raise InputError(f"cell size must be positive, got {cell_size}")
        self.cell_size = L
        self.origin = np.broadcast_to(np.asarray(origin, dtype=np.float64), (3,)).copy()

    @property
    def name(self) -> str:
        return self.type.name

    def angles(self, coords: np.ndarray, axis: int) -> np.ndarray:
        return 2.0 * np.pi * (np.asarray(coords, dtype=np.float64) - self.origin[axis]) / self.cell_size[axis]

    def evaluate(self, points):
        ang = [self.angles(points[:, a], a) for a in range(3)]
        cache = {}
        out = np.full(len(points), self.type.constant)
        for term in self.type.terms:
            prod = np.full(len(points), term.coef)
            for a, (fn, k) in enumerate(term.funcs):
                if fn == "1":
                    continue
                key = (a, fn, k)
                if key not in cache:
                    cache[key] = _axis_factor(fn, k, ang[a])
                prod *= cache[key]
            out += prod
        return out

    def _rows(self, coords, axis):
        ang = self.angles(coords, axis)
        rows = np.empty((len(self.type.terms), len(ang)), dtype=np.float32)
        for t, term in enumerate(self.type.terms):
            fn, k = term.funcs[axis]
            f = _axis_factor(fn, k, ang)
            rows[t] = f * term.coef if axis == 0 else f
        return rows

    def sample_grid(self, xs, ys, zs):
        out = np.empty((len(zs), len(ys), len(xs)), dtype=np.float32)
        return _separable_sum(self._rows(xs, 0), self._rows(ys, 1), self._rows(zs, 2),
                              np.float32(self.type.constant), out)
