"""The recipe schema: every key of every job's recipe tables declared once.

A :class:`Key` declares one recipe key: its kind, default, bounds, choices,
units, a one-line help text and the keys it excludes. The declarations of
all jobs live in :mod:`porecad.recipes.keys`; everything else derives
from them:

- the job specs read their tables with :meth:`Table.get
  <porecad.recipes.table.Table.get>`, which takes the key's kind, bounds
  and default from its declaration (the command line's options set recipe
  keys, so their checks are these too);
- :func:`json_schema` gives a job's JSON Schema (draft 2020-12), printed by
  ``porecad schema [JOB]``;
- :func:`docs_markdown` writes the reference section of ``docs/recipes.md``
  (``python -m porecad.recipes.schema --docs`` rewrites it; a test keeps it in
  sync);
- the studio's form (:func:`porecad.studio.design.fields`) takes its fields'
  labels, defaults and bounds from :func:`json_schema`.

A small declarative layer rather than pydantic models: pydantic is not a
dependency, and the checked reads of :class:`~porecad.recipes.table.Table`
keep their error messages (naming the dotted key), path confinement and
unknown-key refusals, which the declarations only parametrize.
"""

from __future__ import annotations

import json
import sys

from .key import KINDS, REQUIRED, Key  # noqa: F401 - the declaration's parts, used here and re-exported

def job_keys(job: str) -> dict:
    """The declared top-level keys of ``job`` (name → :class:`Key`); a :class:`RecipeError` for an unknown job."""
    from ..errors import RecipeError
    from .keys import JOBS
    if job not in JOBS:
        raise RecipeError("job", f"unknown job {job!r}; use one of {', '.join(JOBS)}")
    return JOBS[job]


def job_names() -> list[str]:
    """The jobs with a declared schema."""
    from .keys import JOBS
    return list(JOBS)


def declared(job: str, key: str) -> Key | None:
    """The declaration of ``job``'s recipe key ``key`` (dotted: ``"tpms.cell_size"``), or None if it has none."""
    keys = job_keys(job)
    *tables, name = key.split(".")
    for t in tables:
        if t not in keys or keys[t].keys is None:
            return None
        keys = keys[t].keys
    return keys.get(name)


def default_of(job: str, key: str):
    """The declared default of ``job``'s recipe key ``key`` (None: it has none, or it must be given).

    The one place the command line's option defaults, the studio form's and
    the Python API's signatures take their defaults from.
    """
    d = declared(job, key)
    return None if d is None or d.default is REQUIRED else d.default


def walk(keys: dict, prefix: str = ""):
    """``(dotted name, Key)`` of every key of a table and its sub-tables, depth first."""
    for name, key in keys.items():
        dotted = f"{prefix}.{name}" if prefix else name
        yield dotted, key
        if key.keys is not None:
            yield from walk(key.keys, dotted + ("[]" if key.kind == "tables" else ""))


# ------------------------------------------------------------------------------------------------ JSON Schema

def _value_schema(key: Key) -> dict:
    """The JSON Schema of one key's value (no annotations)."""
    num = {}
    if key.lo is not None:
        num["exclusiveMinimum" if key.open_lo else "minimum"] = key.lo
    if key.hi is not None:
        num["exclusiveMaximum" if key.open_hi else "maximum"] = key.hi
    if key.positive:
        num["exclusiveMinimum"] = max(0, num.get("exclusiveMinimum", 0))
    if key.nonneg:
        num.setdefault("minimum", 0)
    k = key.kind
    if k in ("int", "number"):
        return {"type": "integer" if k == "int" else "number", **num}
    if k == "bool":
        return {"type": "boolean"}
    if k in ("string", "path", "output"):
        return {"type": "string", "maxLength": key.max_len or 4096}
    if k == "choice":
        return {"type": "string", "enum": list(key.choices)}
    if k in ("numbers", "integers"):
        out = {"type": "array", "items": {"type": "number" if k == "numbers" else "integer", **num}}
        counts = (key.length,) if isinstance(key.length, int) else key.length
        out["minItems"] = min(counts) if counts else key.min_len if k == "numbers" else 0
        out["maxItems"] = max(counts) if counts else key.max_len or 64
        forms = [out]
        if key.scalar or k == "numbers" and (not counts or 1 in counts):
            forms.insert(0, out["items"])
        if k == "numbers" and key.keys is not None:
            forms.append(table_schema(key.keys))
        return out if len(forms) == 1 else {"anyOf": forms}
    if k == "table":
        return table_schema(key.keys or {})
    if k == "tables":
        return {"type": "array", "items": table_schema(key.keys or {}), "maxItems": key.max_len or 256}
    out = {"type": key.json} if key.json else {}
    return {"anyOf": [out, table_schema(key.keys)]} if key.keys is not None else out


def key_schema(key: Key) -> dict:
    """The JSON Schema of one key: its value's, with ``description``, ``default`` and ``x-units``."""
    out = _value_schema(key)
    if key.help:
        out["description"] = key.help
    if key.default is not None and key.default is not REQUIRED:
        d = key.default
        out["default"] = list(d) if isinstance(d, tuple) else d
    if key.units:
        out["x-units"] = key.units
    if key.excludes:
        out["x-excludes"] = list(key.excludes)
    if key.local_only:
        out["x-local-only"] = True
    return out


def table_schema(keys: dict) -> dict:
    """The JSON Schema of a table: an object of its declared keys (no others), exclusions as ``not``."""
    out = {"type": "object", "properties": {k: key_schema(v) for k, v in keys.items()},
           "additionalProperties": False}
    required = [k for k, v in keys.items() if v.default is REQUIRED and not v.when]
    if required:
        out["required"] = required
    pairs = sorted({tuple(sorted((k, x))) for k, v in keys.items() for x in v.excludes})
    if pairs:
        out["allOf"] = [{"not": {"required": list(p)}} for p in pairs]
    return out


def json_schema(job: str | None = None) -> dict:
    """The JSON Schema (draft 2020-12) of ``job``'s recipe, or of every job's (``{"$defs": {job: ...}}``)."""
    if job is None:
        return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "porecad recipe",
                "$defs": {name: {k: v for k, v in json_schema(name).items() if k != "$schema"}
                          for name in job_names()},
                "oneOf": [{"$ref": f"#/$defs/{name}"} for name in job_names()]}
    out = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": f"porecad recipe: job {job}",
           **table_schema(job_keys(job))}
    out["properties"]["job"]["const"] = job
    return out


# ------------------------------------------------------------------------------------------------------ docs

DOCS_BEGIN = "<!-- recipe keys: generated by `python -m porecad.recipes.schema --docs`; do not edit -->"
DOCS_END = "<!-- end of recipe keys -->"


def range_text(key: Key) -> str:
    """A key's range or choices in words (``(0, 1]``, ``> 0``, ``x, y, z``)."""
    if key.choices:
        return ", ".join(f"`{c}`" for c in key.choices)
    lo = 0 if (key.positive or key.nonneg) and key.lo is None else key.lo
    open_lo = key.open_lo or (key.positive and key.lo is None)
    if lo is not None and key.hi is not None:
        return f"{'(' if open_lo else '['}{lo:g}, {key.hi:g}{')' if key.open_hi else ']'}"
    if lo is not None:
        return f"{'>' if open_lo else '≥'} {lo:g}"
    if key.hi is not None:
        return f"{'<' if key.open_hi else '≤'} {key.hi:g}"
    return ""


def _type(key: Key) -> str:
    counts = (key.length,) if isinstance(key.length, int) else key.length
    n = f" ×{'/'.join(map(str, counts))}" if counts else ""
    return {"int": "integer", "number": "number", "bool": "true/false", "string": "text", "choice": "choice",
            "path": "input path", "output": "output path", "numbers": f"numbers{n}", "integers": f"integers{n}",
            "table": "table", "tables": "list of tables", "any": key.json or "value"}[key.kind]


def _default(key: Key) -> str:
    if key.default is REQUIRED:
        return f"required ({key.when})" if key.when else "required"
    if key.default is None:
        return ""
    return f"`{json.dumps(list(key.default) if isinstance(key.default, tuple) else key.default)}`"


def docs_markdown() -> str:
    """The reference of every job's recipe keys (markdown, between :data:`DOCS_BEGIN` and :data:`DOCS_END`)."""
    lines = [DOCS_BEGIN, ""]
    for job in job_names():
        lines += [f"### Job `{job}`", "", "| table | key | type | default | range | units | meaning |",
                  "|---|---|---|---|---|---|---|"]
        for name, key in walk(job_keys(job)):
            text = key.help + (f" Not with {', '.join(f'`{x}`' for x in key.excludes)}." if key.excludes else "")
            text += " One of them is required." if key.one_of else ""
            text += " [Local-only](security.md)." if key.local_only else ""
            table, _, k = name.rpartition(".")
            lines.append(f"| {f'`[{table}]`' if table else ''} | `{k}` | {_type(key)} | {_default(key)} | "
                         f"{range_text(key)} | {key.units} | {text.replace('|', '/')} |")
        lines.append("")
    lines.append(DOCS_END)
    return "\n".join(lines)


def docs_synced(text: str) -> str:
    """``text`` (a docs page) with its generated section replaced by :func:`docs_markdown`."""
    head, sep, rest = text.partition(DOCS_BEGIN)
    if not sep:
        raise ValueError("the page has no generated recipe-key section")
    tail = rest.partition(DOCS_END)[2]
    return head + docs_markdown() + tail


def main(argv=None) -> int:
    """``python -m porecad.recipes.schema --docs [PAGE]``: rewrite the generated section of docs/recipes.md."""
    from pathlib import Path
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] != "--docs":
        print(json.dumps(json_schema(), indent=2, ensure_ascii=False))
        return 0
    page = Path(argv[1] if len(argv) > 1 else "docs/recipes.md")
    page.write_text(docs_synced(page.read_text(encoding="utf-8")), encoding="utf-8")
    return 0


if __name__ == "__main__":  # pragma: no cover - run as a script: the package's module (one REQUIRED)
    from porecad.recipes import schema as _schema
    sys.exit(_schema.main())
