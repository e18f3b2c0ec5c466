"""Check the package layout: import cycles, private imports, module sizes and names.

Rules (issue 21):

1. no import cycle between modules of ``porecad``, counting imports inside
   functions (every ``import``/``from ... import`` statement anywhere in a
   module is an edge; ``from pkg import name`` is an edge to ``pkg.name``
   when that is a module, else to ``pkg``);
2. no private name (``_name``, not dunder) imported from another module;
3. no module longer than 600 lines, and no function longer than 80 (from ``def``
   to its last line, docstring included; compiled numba kernels excepted: they are
   written flat for the compiler, and a split costs compile time on a user's first run);
4. no two modules with the same file name (``__init__.py``, ``__main__.py``
   and ``conftest.py`` excepted);
5. the layers import only downward (issue 38): the library below ``jobs``
   imports none of ``printing``, ``jobs``, ``cli`` or ``studio``; ``printing``
   (which plans a design's field from its recipe) only ``jobs`` of them;
   ``jobs`` imports neither ``cli`` nor ``studio``; ``studio`` does not
   import ``cli``; only ``cli`` and ``studio`` use the public API module;
6. no command-line flag (``--name``) in an error raised outside ``cli/``:
   the library names the parameter (in backquotes, `resolution`) and the
   command line shows its option (:func:`porecad.cli.options.with_flags`);
7. no warning as plain text: nothing appends or adds a string (literal or
   f-string) to a list named ``*warn*`` or ``*finding*``; a warning is a
   :class:`porecad.findings.Finding` with a code of ``CODES``.

Run ``python tools/check_layout.py [SRC]``; prints the violations and exits 1
if there are any. ``tests/docs/test_layout_docs.py`` runs it.
"""

from __future__ import annotations

import ast
import re
import sys
from collections import defaultdict
from pathlib import Path

MAX_LINES = 600
#: the longest function (``def`` to its last line, docstring included)
MAX_FUNCTION_LINES = 80
SAME_NAME_OK = {"__init__.py", "__main__.py", "conftest.py"}


def modules(src: Path, package: str = "porecad") -> dict[str, Path]:
    """Dotted module name → file, for every module of ``package`` under ``src``."""
    root = src / package
    out = {}
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(src).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _resolve(mod: str, is_pkg: bool, level: int, target: str | None) -> str:
    """The absolute module of a (possibly relative) import in module ``mod``."""
    if level == 0:
        return target or ""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def imports(mods: dict[str, Path]):
    """Edges ``(importer, imported module, names, line)`` of every import statement inside the package."""
    edges = []
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] == "porecad":
                        edges.append((mod, a.name, [], node.lineno))
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(mod, is_pkg, node.level, node.module)
                if target.split(".")[0] != "porecad":
                    continue
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in mods:  # importing a submodule
                        edges.append((mod, sub, [], node.lineno))
                    else:
                        edges.append((mod, target, [a.name], node.lineno))
    return edges


def cycles(mods, edges) -> list[list[str]]:
    """Strongly connected components with more than one module (or a self-import)."""
    graph = defaultdict(set)
    for a, b, _, _ in edges:
        if b in mods and a != b:
            graph[a].add(b)
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def strong(v):  # Tarjan, iterative enough for this size
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))
    for v in list(mods):
        if v not in index:
            strong(v)
    return out


def private_imports(mods, edges) -> list[str]:
    """``importer:line imports _name from module`` for private names crossing a module border."""
    out = []
    for a, b, names, line in edges:
        for n in names:
            if n.startswith("_") and not (n.startswith("__") and n.endswith("__")) and a != b:
                out.append(f"{a}:{line} imports {n} from {b}")
    for a, b, names, line in edges:  # importing a private module
        last = b.split(".")[-1]
        if not names and last.startswith("_") and not last.startswith("__") and b.rsplit(".", 1)[0] != \
                a.rsplit(".", 1)[0]:
            out.append(f"{a}:{line} imports the private module {b} from another package")
    return out


def long_modules(mods) -> list[str]:
    out = []
    for mod, path in mods.items():
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES:
            out.append(f"{mod}: {n} lines (at most {MAX_LINES})")
    return out


def _compiled(node) -> bool:
    """Whether a function is a numba kernel (decorated ``njit`` / ``jit``, called or not)."""
    for d in node.decorator_list:
        f = d.func if isinstance(d, ast.Call) else d
        name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


def long_functions(mods) -> list[str]:
    """Functions and methods longer than :data:`MAX_FUNCTION_LINES` (numba kernels excepted)."""
    out = []
    for mod, path in mods.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _compiled(node):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    out.append(f"{mod}:{node.lineno} {node.name}: {n} lines (at most {MAX_FUNCTION_LINES})")
    return out


def same_names(mods) -> list[str]:
    by_name = defaultdict(list)
    for mod, path in mods.items():
        if path.name not in SAME_NAME_OK:
            by_name[path.name].append(mod)
    return [f"{name}: {', '.join(ms)}" for name, ms in sorted(by_name.items()) if len(ms) > 1]


#: the top layers, each importing only from the layers after it; everything else is the library below them
UPPER = ("porecad.cli", "porecad.studio", "porecad.printing", "porecad.jobs")
#: modules above the layers (the package's names, the program's entry point) that may import any of them
TOP = {"porecad", "porecad.__main__", "porecad.entry", "porecad.api", "porecad.pipeline"}


def _layer(mod: str) -> int:
    for i, top in enumerate(UPPER):
        if mod == top or mod.startswith(top + "."):
            return i
    return len(UPPER)


def upward_imports(edges) -> list[str]:
    """Imports of a higher layer from a lower one (rule 5)."""
    return [f"{mod}:{line} imports {target}" for mod, target, _, line in edges
            if mod not in TOP and ((target in TOP and _layer(mod) > 1) or _layer(target) < _layer(mod))]


_FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]+")


def flags_in_errors(mods) -> list[str]:
    """``raise`` statements outside ``cli`` whose message text names a flag (rule 6)."""
    out = []
    for mod, path in mods.items():
        if mod.startswith("porecad.cli"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and node.exc is not None:
                for c in ast.walk(node.exc):
                    if isinstance(c, ast.Constant) and isinstance(c.value, str) and _FLAG.search(c.value):
                        out.append(f"{mod}:{node.lineno} names {', '.join(_FLAG.findall(c.value))}")
    return out


def _warning_list(node) -> bool:
    name = node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")
    return "warn" in name.lower() or "finding" in name.lower()


def _text(node) -> bool:
    return isinstance(node, ast.JoinedStr) or (isinstance(node, ast.Constant) and isinstance(node.value, str))


def text_warnings(mods) -> list[str]:
    """Strings appended to (or added to) a list of warnings (rule 7)."""
    out = []
    for mod, path in mods.items():
        lines = []
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            items = []
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("append", "extend", "insert") and _warning_list(node.func.value)):
                items = node.args[-1:]
                if node.func.attr == "extend" and items and isinstance(items[0], (ast.List, ast.Tuple)):
                    items = items[0].elts
            elif isinstance(node, ast.AugAssign) and _warning_list(node.target) and isinstance(node.value, ast.List):
                items = node.value.elts
            if any(_text(i) for i in items):
                lines.append(node.lineno)
        out += [f"{mod}:{n} adds a warning as plain text" for n in sorted(lines)]
    return out


def check(src: Path) -> dict[str, list]:
    """All violations by rule."""
    mods = modules(src)
    edges = imports(mods)
    return {"import cycles": [" -> ".join(c) for c in cycles(mods, edges)],
            "private names imported across modules": private_imports(mods, edges),
            f"modules over {MAX_LINES} lines": long_modules(mods),
            f"functions over {MAX_FUNCTION_LINES} lines": long_functions(mods),
            "modules sharing a file name": same_names(mods),
            "imports from a higher layer": upward_imports(edges),
            "flags named in library errors": flags_in_errors(mods),
            "warnings as plain text": text_warnings(mods)}


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    src = Path(args[0]) if args else Path(__file__).resolve().parents[1] / "src"
    found = check(src)
    bad = 0
    for rule, items in found.items():
        print(f"{rule}: {len(items)}")
        for item in items:
            print(f"  {item}")
        bad += len(items)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
