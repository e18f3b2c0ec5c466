"""A TPMS design as a 3MF Volumetric & Implicit level set (3MF Volumetric & Implicit Extensions v1.0).

Instead of a triangle mesh, the file holds the design's *function*: an
``<i:implicitfunction>`` node graph (sin, cos, products, sums, constants,
min/max, abs) of the TPMS, its structure, its threshold (a number or a
linear/radial ramp) and, for a box of cells, the box cut with ``max()``,
and a ``<v:levelset>`` object whose evaluation mesh bounds it: the box
(``meshbboxonly``) or the body of an infill (the level set is clipped to
the mesh). Written with lib3mf (2.5 or newer, the ``3mf`` extra).

Sign: the spec's level set is the zero surface of the function; its
signed-distance node is "positive outside the mesh and negative inside",
and its example sphere is ``length(pos) - radius``: negative inside
material, as in every porecad field, so the function is porecad's field
with no change of sign.

Precision: lib3mf writes a ``<i:constant>`` with 6 significant digits.
Every constant is therefore stored as a sum of up to four constants, each
with at most 6 significant digits, that adds up to the double exactly (or to
within 1e-22 of it): the graph evaluates to porecad's field to rounding.

No fallback mesh: lib3mf declares the implicit namespace in
``requiredextensions``, so a reader without the extension must refuse the
file rather than fall back to a mesh beside the level set, and a reader with
it would print both. The triangle mesh of the same recipe is
``porecad build``'s STL or 3MF.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math

import numpy as np

from ..errors import InputError

#: the optional dependency and how to get it
EXTRA = "lib3mf (install porecad[3mf], or pip install 'lib3mf>=2.5,<3')"
#: the function's output (the level set's channel) and input
CHANNEL, POSITION = "shape", "pos"
#: significant digits lib3mf 2.5 writes for a constant
CONSTANT_DIGITS = 6


@dataclasses.dataclass(frozen=True)
class Ramp:
    """``v0 + (v1 - v0) * clamp((s - s0) / (s1 - s0), 0, 1)``; ``s`` a coordinate (``centre`` None) or the
    distance from ``centre`` in ``axes``."""

    v0: float
    v1: float
    s0: float
    s1: float
    axes: tuple
    centre: tuple | None = None


@dataclasses.dataclass(frozen=True)
class ImplicitDesign:
    """What the function graph is built from (all in mm).

    ``terms``: ``((coef, ((fn, k), (fn, k), (fn, k))), ...)``, ``fn`` in ``{'1', 'sin', 'cos'}``, per axis x, y,
    z: ``phi = constant + sum coef * prod fn(k * 2 pi (p - origin) / cell_size)``. ``structure``: pore
    (``C - phi``), rod (``phi - C``), sheet (``|phi - sheet_level| - C``). ``threshold``: a number or a
    :class:`Ramp`. ``box``: ``(lo, hi)`` the lattice is cut to with ``max`` in the function, or None.
    ``mesh``: the evaluation mesh ``(vertices, faces)``; ``bbox_only``: evaluate in its bounding box
    (a box of cells) instead of clipping to it (a body).
    """

    name: str
    terms: tuple
    constant: float
    cell_size: tuple
    origin: tuple
    structure: str
    sheet_level: float
    threshold: object
    mesh: tuple
    box: tuple | None = None
    bbox_only: bool = True


@contextlib.contextmanager
def kept_locale():
    """Put the process's C locale back after lib3mf (its writer and reader set ``LC_ALL`` to ``C`` and leave it:
    Python's preferred encoding would turn ASCII for the rest of the process)."""
    import locale
    saved = locale.setlocale(locale.LC_ALL, None)
    try:
        yield
    finally:
        locale.setlocale(locale.LC_ALL, saved)


def load_lib3mf():
    """The lib3mf module (2.5 or newer), or an InputError naming the extra to install."""
    try:
        import lib3mf
    except ImportError:
        raise InputError(f"an implicit 3MF needs {EXTRA}") from None
    version = tuple(lib3mf.get_wrapper().GetLibraryVersion())
    if version < (2, 5, 0):
        raise InputError(f"an implicit 3MF needs lib3mf 2.5 or newer (found {'.'.join(map(str, version))}): "
                         f"install porecad[3mf]")
    return lib3mf


def split_constant(value: float, digits: int = CONSTANT_DIGITS) -> list:
    """``value`` as up to four numbers of ``digits`` significant digits that add up to it (in double)."""
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"a function constant must be finite, got {value}")
    parts = []
    rest = value
    for _ in range(4):
        part = float(f"{rest:.{digits}g}")
        parts.append(part)
        rest = rest - part
        if rest == 0.0 or abs(rest) < 1e-300:
            break
    return parts


class Graph:
    """A node graph in one lib3mf ImplicitFunction: nodes by kind, constants split and cached."""

    def __init__(self, lib3mf, function):
        self.lib, self.fn = lib3mf, function
        self.scalar = lib3mf.ImplicitNodeConfiguration.ScalarToScalar
        self.count = 0
        self.constants = {}

    def _id(self, kind: str) -> str:
        self.count += 1
        return f"{kind}{self.count}"  # identifiers: alphanumeric only (spec, chapter 4)

    def constant(self, value: float):
        """The output port of a constant ``value`` (a sum of constant nodes when 6 digits do not hold it)."""
        key = float(value)
        if key not in self.constants:
            ports = []
            for part in split_constant(key):
                node = self.fn.AddConstantNode(self._id("c"), f"{part:g}", "")
                node.SetConstant(part)
                ports.append(node.GetOutputValue())
            port = ports[-1]
            for p in reversed(ports[:-1]):  # c1 + (c2 + (c3 + c4)): the small parts first
                port = self.binary("add", p, port)
            self.constants[key] = port
        return self.constants[key]

    def binary(self, kind: str, a, b):
        """``kind`` in add, sub, mul, min, max: the output port of ``kind(a, b)``."""
        add = {"add": self.fn.AddAdditionNode, "sub": self.fn.AddSubtractionNode,
               "mul": self.fn.AddMultiplicationNode, "min": self.fn.AddMinNode, "max": self.fn.AddMaxNode}[kind]
        node = add(self._id(kind), self.scalar, kind, "")
        self.fn.AddLink(a, node.GetInputA())
        self.fn.AddLink(b, node.GetInputB())
        return node.GetOutputResult()

    def unary(self, kind: str, a):
        """``kind`` in sin, cos, abs, sqrt: the output port of ``kind(a)``."""
        add = {"sin": self.fn.AddSinNode, "cos": self.fn.AddCosNode, "abs": self.fn.AddAbsNode,
               "sqrt": self.fn.AddSqrtNode}[kind]
        node = add(self._id(kind), self.scalar, kind, "")
        self.fn.AddLink(a, node.GetInputA())
        return node.GetOutputResult()

    def total(self, kind: str, ports: list):
        """``kind`` (add, mul, min, max) folded over ``ports``."""
        out = ports[0]
        for p in ports[1:]:
            out = self.binary(kind, out, p)
        return out


def tpms_value(g: Graph, xyz: list, design: ImplicitDesign):
    """The port of the TPMS value ``phi`` at the coordinates ``xyz`` (three scalar ports)."""
    angles = {}
    factors = {}

    def factor(axis, fn, k):
        if (axis, fn, k) not in factors:
            if axis not in angles:  # 2 pi (p - origin) / L
                shifted = xyz[axis] if design.origin[axis] == 0 else g.binary(
                    "sub", xyz[axis], g.constant(design.origin[axis]))
                angles[axis] = shifted
            scale = 2.0 * math.pi * k / float(design.cell_size[axis])
            factors[(axis, fn, k)] = g.unary(fn, g.binary("mul", angles[axis], g.constant(scale)))
        return factors[(axis, fn, k)]

    terms = []
    for coef, funcs in design.terms:
        ports = [factor(a, fn, int(k)) for a, (fn, k) in enumerate(funcs) if fn != "1"]
        if float(coef) != 1.0 or not ports:
            ports.append(g.constant(coef))
        terms.append(g.total("mul", ports))
    phi = g.total("add", terms)
    if design.constant:
        phi = g.binary("add", phi, g.constant(design.constant))
    return phi


def threshold_value(g: Graph, xyz: list, threshold):
    """The port of the threshold ``C``: a constant or a clamped :class:`Ramp`."""
    if not isinstance(threshold, Ramp):
        return g.constant(float(threshold))
    r = threshold
    if r.centre is None:
        s = xyz[r.axes[0]]
    else:
        squares = []
        for a in r.axes:
            d = g.binary("sub", xyz[a], g.constant(r.centre[a]))
            squares.append(g.binary("mul", d, d))
        s = g.unary("sqrt", g.total("add", squares))
    t = g.binary("mul", g.binary("sub", s, g.constant(r.s0)), g.constant(1.0 / (r.s1 - r.s0)))
    t = g.binary("max", g.binary("min", t, g.constant(1.0)), g.constant(0.0))
    return g.binary("add", g.constant(r.v0), g.binary("mul", t, g.constant(r.v1 - r.v0)))


def structure_value(g: Graph, phi, c, design: ImplicitDesign):
    """The material field of the structure: negative inside material."""
    if design.structure == "pore":
        return g.binary("sub", c, phi)
    if design.structure == "rod":
        return g.binary("sub", phi, c)
    if design.structure == "sheet":
        centred = phi if not design.sheet_level else g.binary("sub", phi, g.constant(design.sheet_level))
        return g.binary("sub", g.unary("abs", centred), c)
    raise InputError(f"structure {design.structure!r} is not a solid: an implicit 3MF needs pore, rod or sheet")


def box_value(g: Graph, xyz: list, box):
    """``max_a max(lo_a - p_a, p_a - hi_a)``: negative inside the box."""
    lo, hi = box
    sides = []
    for a in range(3):
        sides.append(g.binary("sub", g.constant(lo[a]), xyz[a]))
        sides.append(g.binary("sub", xyz[a], g.constant(hi[a])))
    return g.total("max", sides)


def build_function(lib3mf, model, design: ImplicitDesign):
    """Add the design's ImplicitFunction (input ``pos``, output ``shape``) to ``model``; return it."""
    fn = model.AddImplicitFunction()
    fn.SetDisplayName(design.name)
    pos = fn.AddInput(POSITION, "position", lib3mf.ImplicitPortType.Vector)
    out = fn.AddOutput(CHANNEL, "shape", lib3mf.ImplicitPortType.Scalar)
    g = Graph(lib3mf, fn)
    split = fn.AddDecomposeVectorNode("xyz", "position", "")
    fn.AddLink(pos, split.GetInputA())
    xyz = [split.GetOutputX(), split.GetOutputY(), split.GetOutputZ()]
    value = structure_value(g, tpms_value(g, xyz, design), threshold_value(g, xyz, design.threshold), design)
    if design.box is not None:
        value = g.binary("max", value, box_value(g, xyz, design.box))
    fn.AddLink(value, out)
    return fn


def add_mesh(lib3mf, model, vertices, faces, name: str):
    """A mesh object of ``vertices`` (V, 3) and ``faces`` (F, 3)."""
    mesh = model.AddMeshObject()
    mesh.SetName(name)
    points = []
    for v in np.asarray(vertices, dtype=float):
        p = lib3mf.Position()
        p.Coordinates[0], p.Coordinates[1], p.Coordinates[2] = (float(x) for x in v)
        points.append(p)
    triangles = []
    for f in np.asarray(faces, dtype=np.int64):
        t = lib3mf.Triangle()
        t.Indices[0], t.Indices[1], t.Indices[2] = (int(i) for i in f)
        triangles.append(t)
    mesh.SetGeometry(points, triangles)
    return mesh


def box_mesh(lo, hi) -> tuple:
    """The 12 outward triangles of the box ``[lo, hi]``: ``(vertices (8, 3), faces (12, 3))``."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    v = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]]
                  for i in range(8)])
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return v, f


def implicit_model(design: ImplicitDesign):
    """The lib3mf model of ``design``: the function, the evaluation mesh, the level set as the build item."""
    lib3mf = load_lib3mf()
    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    model.SetUnit(lib3mf.ModelUnit.MilliMeter)
    fn = build_function(lib3mf, model, design)
    mesh = add_mesh(lib3mf, model, *design.mesh, name=f"{design.name} evaluation domain")
    level = model.AddLevelSet()
    level.SetName(design.name)
    level.SetFunction(fn)
    level.SetChannelName(CHANNEL)
    level.SetMesh(mesh)
    level.SetMeshBBoxOnly(bool(design.bbox_only))
    level.SetFallBackValue(1.0)  # an undefined value is outside the material
    model.AddBuildItem(level, wrapper.GetIdentityTransform())
    return model


def write_implicit_3mf(design: ImplicitDesign, path, force: bool = False) -> dict:
    """Write ``design`` as an implicit 3MF at ``path`` (atomically; an existing file only with ``force``).

    Returns ``{"file", "bytes", "nodes", "mesh_triangles"}``.
    """
    import os

    from .atomic import atomic_path, check_output_path
    check_output_path(path, force=force)
    model = implicit_model(design)
    writer = model.QueryWriter("3mf")
    writer.SetDecimalPrecision(9)  # the evaluation mesh's coordinates (float32 in lib3mf)
    with atomic_path(path, force=force, suffix=".3mf") as tmp, kept_locale():
        writer.WriteToFile(str(tmp))
        size = os.path.getsize(tmp)
    nodes = model.GetFunctions()
    count = 0
    while nodes.MoveNext():
        count += nodes.GetCurrentFunction().GetNodes().Count()
    return {"file": str(path), "bytes": int(size), "nodes": int(count), "mesh_triangles": int(len(design.mesh[1]))}
