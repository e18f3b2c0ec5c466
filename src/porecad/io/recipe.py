"""Recipes: the TOML description of a job that regenerates its outputs.

Every porecad command builds a recipe (a plain dict) and runs it with
:func:`porecad.pipeline.run_recipe`; ``porecad build RECIPE`` runs a recipe
file. Paths inside a recipe are relative to the recipe file.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import tomli_w

from ..errors import InputError
from .atomic import atomic_write

FORMAT_VERSION = 1


def load_recipe(path) -> dict:
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such recipe file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: not a valid TOML recipe: {exc}") from None
    if not isinstance(data.get("job"), str):
        raise InputError(f"{p}: a recipe needs a 'job' key (e.g. job = \"tpms\")")
    base = p.resolve().parent
    out = data.get("output", {})
    for key in ("mesh", "report", "recipe"):
        if isinstance(out.get(key), str) and not Path(out[key]).is_absolute():
            out[key] = str(base / out[key])
    return data


def _clean(obj):
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item"):
        return obj.item()
    return obj


def dump_recipe(recipe: dict) -> str:
    body = dict(_clean(recipe))
    body.setdefault("format", FORMAT_VERSION)
    return "# porecad recipe: run with `porecad build THIS_FILE`\n" + tomli_w.dumps(body)


def save_recipe(recipe: dict, path, force: bool = False) -> Path:
    text = dump_recipe(recipe).encode()
    with atomic_write(path, force=force) as fh:
        fh.write(text)
    return Path(path)
