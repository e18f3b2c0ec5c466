"""Recipe files: the TOML description of a job that regenerates its outputs.

Every porecad command builds a recipe (a plain dict) and runs it through the
job registry (:func:`porecad.jobs.run_recipe`); ``porecad build RECIPE`` runs
a recipe file. Input and output paths inside a recipe are relative to the
recipe file. A recipe names its format version (``format``) and the porecad
version that wrote it (``porecad_version``).

Format history:

1. ``job = "tpms"`` only (box lattices and body infills).
2. Every job (``tpms``, ``infill``, ``tbss``, ``hex``, ``tis``, ``arbf``,
   ``vessel``, ``ivd``, ...); unknown keys are errors. Format-1 recipes read
   unchanged.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import tomli_w

from ..errors import InputError
from .atomic import atomic_write

FORMAT_VERSION = 2
#: largest recipe file read (bytes): a design is a few hundred bytes
MAX_RECIPE_BYTES = 1 << 20


def read_recipe(path) -> dict:
    """Parse a recipe file (TOML) into a dict; one-line errors for a missing, huge or malformed file."""
    from .confine import regular_file
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such recipe file")
    size = regular_file(p, "a recipe")
    if size > MAX_RECIPE_BYTES:
        raise InputError(f"{p}: {size:,} bytes is too large for a recipe (at most {MAX_RECIPE_BYTES:,})")
    try:
        data = tomllib.loads(p.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a text (UTF-8) TOML recipe") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: not a valid TOML recipe: {' '.join(str(exc).split())}") from None
    except RecursionError:
        raise InputError(f"{p}: not a valid TOML recipe: nested too deeply") from None
    except ValueError:  # an integer past Python's digit limit (tomllib raises it unwrapped)
        raise InputError(f"{p}: not a valid TOML recipe: a number is too long to read") from None
    _check_shape(data, p)
    if not isinstance(data.get("job"), str):
        raise InputError(f"{p}: a recipe needs a 'job' key (e.g. job = \"tpms\")")
    return data


#: deepest nesting of tables and arrays in a recipe (recipes nest 3 or 4 levels)
MAX_RECIPE_DEPTH = 16
#: most values in a recipe (a point-grading table of 100,000 rows has 500,000)
MAX_RECIPE_VALUES = 1_000_000


def _check_shape(data, p) -> None:
    """Refuse a recipe nested deeper than :data:`MAX_RECIPE_DEPTH` or holding too many values (iterative walk)."""
    stack = [(data, 1)]
    count = 0
    while stack:
        node, depth = stack.pop()
        count += 1
        if depth > MAX_RECIPE_DEPTH:
            raise InputError(f"{p}: the recipe nests tables or arrays more than {MAX_RECIPE_DEPTH} levels deep")
        if count > MAX_RECIPE_VALUES:
            raise InputError(f"{p}: the recipe holds more than {MAX_RECIPE_VALUES:,} values")
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)


def load_recipe(path) -> dict:
    """:func:`read_recipe` (kept for scripts written against format 1)."""
    return read_recipe(path)


def _clean(obj):
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item"):
        return obj.item()
    return obj


def dump_recipe(recipe: dict) -> str:
    """The recipe as TOML text (None values dropped, the format version stamped)."""
    body = dict(_clean(recipe))
    body.setdefault("format", FORMAT_VERSION)
    head = {k: body.pop(k) for k in ("job", "format", "porecad_version") if k in body}
    return "# porecad recipe: run with `porecad build THIS_FILE`\n" + tomli_w.dumps({**head, **body})


def save_recipe(recipe: dict, path, force: bool = False) -> Path:
    """Write a recipe file atomically (refuses to overwrite without ``force``)."""
    text = dump_recipe(recipe).encode()
    with atomic_write(path, force=force) as fh:
        fh.write(text)
    return Path(path)
