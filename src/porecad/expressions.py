"""Safe numeric expressions: the one evaluator for grading, TDF expressions and edit conditions.

Porosity and threshold expressions (``--porosity "0.5 + 0.3 * dn"``), TDF
expressions (``--tdf "0.5 + 0.5 * w"``) and local-edit conditions
(``--edit "(w > 0.75) & (u < 0.5)" 0.9``) come from command lines and from
recipes that other people wrote, so they are untrusted. They are never given
to :func:`eval`: the text is parsed by :func:`ast.parse` and every node is
checked against a small grammar before anything runs, then evaluated by a
tree of numpy operations.

Allowed
    numbers (``2``, ``0.5``, ``1e-3``); the caller's variables (``x, y, z,
    d, dn`` for grading; ``u, v, w, x, y, z`` for a TDF); the constants
    ``pi`` and ``e``; ``+ - * / // % **`` and unary ``+ -``; comparisons
    ``< <= > >= == !=`` (chains like ``0.2 < w < 0.5`` included); logical
    ``&  |  ^  ~`` and ``and  or  not`` (element-wise; non-zero is true);
    calls of the functions in :data:`FUNCTIONS` with their number of
    arguments.
Refused
    everything else: attribute access, subscripts, strings, lists, tuples,
    dicts, sets, lambdas, comprehensions, conditional expressions (use
    ``where(c, a, b)``), assignments, keyword or starred arguments, calls of
    anything but a listed function, and names that are not variables,
    constants or functions. Exponents whose value is known before evaluation
    are bounded (``|p| <= MAX_EXPONENT``); the text, its node count and its
    nesting depth are bounded. Sub-expressions without variables are
    evaluated once up front, so ``1/0`` or ``log(-1)`` is refused before any
    work.

Every value is a float64 numpy array (comparisons give 0.0 or 1.0), so no
operation can build a Python integer of unbounded size or a sequence, and
the result is at most as large as the broadcast of the variables given.
Errors are :class:`ExpressionError` (an :class:`~porecad.errors.InputError`)
in one line with the 1-based column: ``"column 5: attribute access (.) is
not allowed"``.

Examples
--------
>>> import numpy as np
>>> f = compile_expression("0.5 + 0.3 * clip(z / 10, 0, 1)", ("x", "y", "z"))
>>> f(x=np.zeros(2), y=np.zeros(2), z=np.array([0.0, 20.0])).tolist()
[0.5, 0.8]
>>> compile_expression("().__class__", ("x",))
Traceback (most recent call last):
...
porecad.expressions.ExpressionError: column 1: attribute access (.) is not allowed
"""

from __future__ import annotations

import ast

import numpy as np

from .errors import InputError

__all__ = ["ExpressionError", "Expression", "compile_expression", "check_expression", "FUNCTIONS", "CONSTANTS",
           "MAX_CHARS", "MAX_NODES", "MAX_DEPTH", "MAX_EXPONENT"]

#: longest expression text (characters)
MAX_CHARS = 2000
#: most AST nodes in one expression
MAX_NODES = 1000
#: deepest nesting of the AST
MAX_DEPTH = 100
#: largest magnitude of an exponent known before evaluation (``x ** 64`` is fine, ``9 ** 9 ** 9`` is not)
MAX_EXPONENT = 64.0

#: name -> (numpy function, least and most arguments)
FUNCTIONS = {
    **{name: (getattr(np, name), 1, 1) for name in (
        "sin", "cos", "tan", "arcsin", "arccos", "arctan", "sinh", "cosh", "tanh", "exp", "log", "log10",
        "log2", "sqrt", "abs", "floor", "ceil", "sign")},
    **{name: (getattr(np, name), 2, 2) for name in ("arctan2", "hypot", "minimum", "maximum", "fmod")},
    "min": (np.minimum, 2, 2),
    "max": (np.maximum, 2, 2),
    "clip": (lambda a, lo, hi: np.minimum(np.maximum(a, lo), hi), 3, 3),
    "where": (lambda c, a, b: np.where(c != 0, a, b), 3, 3),
}
#: named constants
CONSTANTS = {"pi": float(np.pi), "e": float(np.e)}


class ExpressionError(InputError):
    """An expression that is not allowed or cannot be evaluated (one line, with the column)."""


_WHAT = {
    ast.Attribute: "attribute access (.)", ast.Subscript: "subscripts ([...])", ast.Lambda: "lambdas",
    ast.ListComp: "comprehensions", ast.SetComp: "comprehensions", ast.DictComp: "comprehensions",
    ast.GeneratorExp: "comprehensions", ast.List: "lists", ast.Tuple: "tuples", ast.Dict: "dicts",
    ast.Set: "sets", ast.IfExp: "conditional expressions (a if c else b; use where(c, a, b))",
    ast.NamedExpr: "assignments (:=)", ast.Starred: "starred arguments", ast.JoinedStr: "strings",
    ast.FormattedValue: "strings", ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield",
    ast.Slice: "slices",
}
_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.true_divide,
           ast.FloorDiv: np.floor_divide, ast.Mod: np.mod, ast.Pow: np.power}
_LOGICAL = {ast.BitAnd: np.logical_and, ast.BitOr: np.logical_or, ast.BitXor: np.logical_xor,
            ast.And: np.logical_and, ast.Or: np.logical_or}
_COMPARE = {ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal,
            ast.Eq: np.equal, ast.NotEq: np.not_equal}
_OP_NAMES = {ast.MatMult: "@", ast.LShift: "<<", ast.RShift: ">>", ast.Is: "is", ast.IsNot: "is not",
             ast.In: "in", ast.NotIn: "not in"}


def _column(text: str, node) -> int:
    """1-based character column of ``node`` (``col_offset`` counts UTF-8 bytes)."""
    off = getattr(node, "col_offset", 0) or 0
    return len(text.encode("utf-8")[:off].decode("utf-8", errors="ignore")) + 1


def _short(name: str, n: int = 32) -> str:
    return name if len(name) <= n else name[:n] + "..."


class Expression:
    """A checked expression; call it with the variables' arrays to evaluate it.

    Attributes
    ----------
    text : str
        The expression as given.
    variables : tuple of str
        The variables it may use.
    names : frozenset of str
        The variables it does use.
    """

    def __init__(self, text: str, variables, fn, names, constant):
        self.text = text
        self.variables = tuple(variables)
        self.names = frozenset(names)
        self._fn = fn
        self.constant = constant  # the value when no variable is used, else None

    def __call__(self, **values) -> np.ndarray:
        """The value (float64 array, broadcast of the variables' arrays); non-finite values are the caller's to check."""
        missing = self.names - set(values)
        if missing:
            raise ExpressionError(f"no value for {', '.join(sorted(missing))}")
        env = {k: np.asarray(v, dtype=np.float64) for k, v in values.items() if k in self.names}
        with np.errstate(all="ignore"):
            return np.asarray(self._fn(env), dtype=np.float64)

    def __repr__(self):
        return f"Expression({self.text!r})"


class _Compiler:
    def __init__(self, text: str, variables):
        self.text = text
        self.variables = frozenset(variables)
        self.used: set[str] = set()

    def fail(self, node, what: str) -> ExpressionError:
        return ExpressionError(f"column {_column(self.text, node)}: {what}")

    # each visit returns (fn(env) -> array, constant value or None)
    def visit(self, node):
        kind = type(node)
        if kind is ast.Constant:
            v = node.value
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                what = "strings are" if isinstance(v, (str, bytes)) else f"{type(v).__name__} values are"
                raise self.fail(node, f"{what} not allowed (numbers only)")
            if isinstance(v, int) and abs(v) > 10 ** 308:
                raise self.fail(node, "number too large")
            return self.const(float(v), node)
        if kind is ast.Name:
            return self.name(node)
        if kind is ast.UnaryOp:
            fn, c = self.visit(node.operand)
            if isinstance(node.op, ast.USub):
                return self.fold(lambda env: np.negative(fn(env)), c is not None, node)
            if isinstance(node.op, ast.UAdd):
                return fn, c
            # not / ~ : logical negation (non-zero is true)
            return self.fold(lambda env: (fn(env) == 0).astype(np.float64), c is not None, node)
        if kind is ast.BinOp:
            return self.binop(node)
        if kind is ast.BoolOp:
            op = _LOGICAL[type(node.op)]
            parts = [self.visit(v) for v in node.values]
            fns = [p[0] for p in parts]

            def boolop(env, fns=fns, op=op):
                acc = fns[0](env) != 0
                for f in fns[1:]:
                    acc = op(acc, f(env) != 0)
                return acc.astype(np.float64)
            return self.fold(boolop, all(p[1] is not None for p in parts), node)
        if kind is ast.Compare:
            return self.compare(node)
        if kind is ast.Call:
            return self.call(node)
        what = _WHAT.get(kind, f"{kind.__name__} expressions")
        raise self.fail(node, f"{what} {'is' if kind is ast.Attribute else 'are'} not allowed")

    def const(self, value: float, node):
        if not np.isfinite(value):
            raise self.fail(node, "number too large")
        arr = np.float64(value)
        return (lambda env: arr), arr

    def fold(self, fn, constant: bool, node):
        """``fn`` as is, or evaluated now when all its inputs are constants (refused if not finite)."""
        if not constant:
            return fn, None
        with np.errstate(all="ignore"):
            value = np.float64(fn({}))
        if not np.isfinite(value):
            raise self.fail(node, "this part evaluates to a non-finite number (division by zero, overflow, or "
                                  "a logarithm or square root of a negative number)")
        return (lambda env: value), value

    def name(self, node):
        n = node.id
        if n in self.variables:
            self.used.add(n)
            return (lambda env: env[n]), None
        if n in CONSTANTS:
            return self.const(CONSTANTS[n], node)
        if n in FUNCTIONS:
            raise self.fail(node, f"{n} is a function: call it, e.g. {n}(...)")
        raise self.fail(node, f"unknown name {_short(n)!r}; use {', '.join(sorted(self.variables))}, "
                              f"pi, e and the functions {', '.join(sorted(FUNCTIONS))}")

    def binop(self, node):
        op = type(node.op)
        if op in _OP_NAMES:
            raise self.fail(node, f"the operator {_OP_NAMES[op]} is not allowed")
        lf, lc = self.visit(node.left)
        rf, rc = self.visit(node.right)
        both = lc is not None and rc is not None
        if op in _LOGICAL:
            lop = _LOGICAL[op]
            return self.fold(lambda env: lop(lf(env) != 0, rf(env) != 0).astype(np.float64), both, node)
        if op is ast.Pow and rc is not None and abs(float(rc)) > MAX_EXPONENT:
            raise self.fail(node, f"the exponent {float(rc):.4g} is out of range (at most {MAX_EXPONENT:g} in "
                                  "magnitude)")
        f = _BINARY[op]
        return self.fold(lambda env: f(lf(env), rf(env)), both, node)

    def compare(self, node):
        for op in node.ops:
            if type(op) in _OP_NAMES:
                raise self.fail(node, f"the operator {_OP_NAMES[type(op)]!s} is not allowed")
        parts = [self.visit(node.left)] + [self.visit(c) for c in node.comparators]
        ops = [_COMPARE[type(op)] for op in node.ops]
        fns = [p[0] for p in parts]

        def chain(env, fns=fns, ops=ops):
            vals = [f(env) for f in fns]
            acc = ops[0](vals[0], vals[1])
            for k in range(1, len(ops)):
                acc = np.logical_and(acc, ops[k](vals[k], vals[k + 1]))
            return acc.astype(np.float64)
        return self.fold(chain, all(p[1] is not None for p in parts), node)

    def call(self, node):
        if not isinstance(node.func, ast.Name):
            what = _WHAT.get(type(node.func), "calling the result of an expression")
            raise self.fail(node.func, f"{what} is not allowed (only the listed functions can be called)")
        name = node.func.id
        if name not in FUNCTIONS:
            if name in self.variables or name in CONSTANTS:
                raise self.fail(node, f"{name} is not a function")
            raise self.fail(node, f"unknown name {_short(name)!r} (not a function here); use "
                                  f"{', '.join(sorted(FUNCTIONS))}")
        if node.keywords:
            raise self.fail(node, f"{name}() takes no keyword arguments")
        fn, lo, hi = FUNCTIONS[name]
        if any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, "starred arguments are not allowed")
        if not lo <= len(node.args) <= hi:
            want = f"{lo}" if lo == hi else f"{lo} to {hi}"
            raise self.fail(node, f"{name}() takes {want} argument{'s' if hi > 1 else ''}, got {len(node.args)}")
        parts = [self.visit(a) for a in node.args]
        fns = [p[0] for p in parts]
        return self.fold(lambda env: fn(*[f(env) for f in fns]), all(p[1] is not None for p in parts), node)


def _shape_check(text: str, tree) -> None:
    """Bound the node count and depth (iteratively, before any recursive walk)."""
    count = 0
    stack = [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        count += 1
        if count > MAX_NODES:
            raise ExpressionError(f"the expression is too long (more than {MAX_NODES} parts)")
        if depth > MAX_DEPTH:
            raise ExpressionError(f"column {_column(text, node)}: the expression nests too deeply "
                                  f"(more than {MAX_DEPTH} levels)")
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))


def compile_expression(text, variables) -> Expression:
    """Parse and check an expression in the given variables.

    Parameters
    ----------
    text : str
        The expression.
    variables : iterable of str
        The variable names it may use.

    Returns
    -------
    Expression
        Callable with the variables' arrays as keyword arguments.

    Raises
    ------
    ExpressionError
        Not a string, empty, too long or deep, a syntax error, or anything
        not allowed (one line with the column).
    """
    if not isinstance(text, str):
        raise ExpressionError(f"an expression must be a string, got {type(text).__name__}")
    if not text.strip():
        raise ExpressionError("the expression is empty")
    if len(text) > MAX_CHARS:
        raise ExpressionError(f"the expression is longer than {MAX_CHARS} characters")
    if any(ord(ch) < 32 and ch not in " \t" for ch in text):
        raise ExpressionError("the expression contains control characters (it must be one line)")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        col = f"column {exc.offset}: " if exc.offset else ""
        msg = " ".join(str(exc.msg).split())
        raise ExpressionError(f"{col}{msg if msg.startswith('invalid syntax') else 'invalid syntax: ' + msg}") \
            from None
    except (ValueError, RecursionError, MemoryError):
        raise ExpressionError("the expression cannot be parsed (too deeply nested or not text)") from None
    stripped = text.strip()
    _shape_check(stripped, tree)
    comp = _Compiler(stripped, variables)
    fn, constant = comp.visit(tree.body)
    return Expression(text, variables, fn, comp.used, constant)


def check_expression(text, variables) -> str:
    """``text`` if it is an allowed expression in ``variables``, else :class:`ExpressionError`."""
    compile_expression(text, variables)
    return text
