"""The studio form's fields made from the recipe schema (:func:`porecad.recipes.schema.json_schema`).

The form's main fields (:func:`porecad.studio.design.fields`) are a design
layer: one field may stand for several recipe keys (``control`` and
``value`` for a threshold, a porosity or a grading). Each main field that
is one recipe key names it (:data:`FIELD_KEYS`) and takes its options and
bounds from the schema. Every other scalar key of a job's recipe becomes a
"more settings" field of that job, made from the job's JSON Schema: named
``JOB.TABLE.KEY``, its label, kind, default, bounds, options and help from
the key's schema. A key added to the schema is in the form with no other
edit, unless it is local-only (a path, a scheduler, worker processes or a
store of the server: ``Key.local_only``, ``docs/security.md``), which the
form neither shows nor accepts. :func:`apply_more` puts those fields' values into a recipe (checked
by the key's declaration, as the job will), :func:`more_of` reads them back.
"""

from __future__ import annotations

#: the main form fields that are one recipe key: field → {job: dotted key}
FIELD_KEYS = {
    "type": {"tpms": "tpms.type", "infill": "tpms.type", "tbss": "tpms.type", "hex": "tpms.type"},
    "tis_type": {"tis": "tis.type"},
    "structure": {"tpms": "tpms.structure", "infill": "tpms.structure", "tbss": "tpms.structure",
                  "hex": "tpms.structure"},
    "tis_structure": {"tis": "tis.structure"},
    "cell_size": {"tpms": "tpms.cell_size", "infill": "tpms.cell_size"},
    "cells": {"tpms": "domain.cells"},
    "periods": {"tbss": "tpms.periods"},
    "grid": {"hex": "grid"},
    "element": {"hex": "element"},
    "boundary": {"infill": "domain.boundary"},
    "skin": {"infill": "domain.skin"},
    "lambda": {"tis": "tis.lambda"},
    "relative": {"tis": "tis.relative"},
    "tets": {"tis": "domain.tets"},
    "size": {"tis": "domain.size"},
    "wall": {"vessel": "wall"},
    "porous_cell": {"vessel": "porous.cell_size"},
    "resolution": {"tpms": "sampling.resolution", "tbss": "mesh.resolution", "hex": "mesh.resolution",
                   "tis": "mesh.resolution"},
    "voxel": {"infill": "sampling.voxel", "vessel": "voxel"},
    "allow_closed_pores": {j: "tpms.allow_closed_pores" for j in ("tpms", "infill", "tbss", "hex")},
    "body_label": {"infill": "domain.label"},
    "body_threshold": {"infill": "domain.threshold"},
}

#: keys the main fields set together (the body, the amount of material, gradings): never "more settings"
DESIGNED = {
    "tpms": ("domain", "tpms.threshold", "tpms.porosity", "grading"),
    "infill": ("domain.kind", "domain.path", "tpms.threshold", "tpms.porosity", "grading"),
    "tbss": ("body.kind", "body.path", "body.params", "tdf", "tpms.cell_size"),
    "hex": ("body.kind", "body.path", "tpms.threshold", "tpms.porosity"),
    "tis": ("domain.kind", "domain.path", "tis.threshold"),
    "vessel": ("input.path", "input.kind", "porous.type", "porous.layer"),  # porous_layer: 0 is none
}

#: the check that shows the "more settings" fields
MORE = "more_settings"

_KINDS = {"integer": "int", "number": "number", "boolean": "check"}


def schema_of(job: str, dotted: str) -> dict | None:
    """The JSON Schema of ``job``'s recipe key ``dotted`` (``"mesh.resolution"``), or None."""
    from ..recipes.schema import json_schema
    node = json_schema(job)
    for part in dotted.split("."):
        node = (node.get("properties") or {}).get(part)
        if node is None:
            return None
    return node


def scalar_keys(job: str):
    """``(dotted key, its JSON Schema)`` of every scalar key of ``job``'s tables (not ``[output]``)."""
    from ..recipes.schema import json_schema

    def walk(node, prefix):
        for k, s in (node.get("properties") or {}).items():
            dotted = f"{prefix}.{k}" if prefix else k
            if s.get("x-local-only"):
                continue
            if s.get("type") == "object":
                yield from walk(s, dotted)
            elif s.get("type") in _KINDS or s.get("type") == "string" and "enum" in s:
                yield dotted, s
    props = json_schema(job)["properties"]
    for table, node in props.items():
        if node.get("x-local-only"):
            continue
        if node.get("type") == "object" and table != "output":
            yield from walk(node, table)
        elif table not in ("format", "job", "porecad_version") and (node.get("type") in _KINDS or "enum" in node):
            yield table, node


def _covered(job: str, dotted: str) -> bool:
    mains = {keys[job] for keys in FIELD_KEYS.values() if job in keys}
    return dotted in mains or any(dotted == d or dotted.startswith(d + ".") for d in DESIGNED.get(job, ()))


def bounds(schema: dict) -> dict:
    """``lo``/``hi`` of a key's JSON Schema (exclusive ends as given: the job refuses them)."""
    out = {}
    for name, keys in (("lo", ("minimum", "exclusiveMinimum")), ("hi", ("maximum", "exclusiveMaximum"))):
        vals = [schema[k] for k in keys if k in schema]
        if vals:
            out[name] = max(vals) if name == "lo" else min(vals)
    return out


def field_of(job: str, dotted: str, schema: dict) -> dict:
    """The form field of one recipe key, from its JSON Schema."""
    kind = "select" if "enum" in schema else _KINDS[schema["type"]]
    units = schema.get("x-units")
    label = dotted.rsplit(".", 1)[-1].replace("_", " ").capitalize() + (f" ({units})" if units else "")
    table = dotted.rsplit(".", 1)[0] if "." in dotted else ""
    return {"name": f"{job}.{dotted}", "label": f"{label} [{table}]" if table else label, "kind": kind,
            "default": schema.get("default"), "jobs": [job], "when": {MORE: [True]},
            "options": ([""] if schema.get("default") is None else []) + list(schema["enum"]) if kind == "select"
            else None, "help": schema.get("description", ""), "key": dotted, **bounds(schema)}


def more_fields(jobs) -> list[dict]:
    """The "more settings" fields of ``jobs``: every scalar key no main field sets, and the check showing them."""
    out = [{"name": MORE, "label": "More settings", "kind": "check", "default": False, "jobs": list(jobs),
            "when": {}, "options": None, "help": "every other setting of the job's recipe (porecad schema JOB)"}]
    for job in jobs:
        out += [field_of(job, k, s) for k, s in scalar_keys(job) if not _covered(job, k)]
    return out


def main_field(field: dict) -> dict:
    """A main field with the schema's options, help and bounds of the key it is (bounds: the tighter)."""
    keys = FIELD_KEYS.get(field["name"])
    if not keys:
        return field
    schemas = [schema_of(job, k) for job, k in keys.items() if job in field["jobs"]]
    s = next((x for x in schemas if x), None)
    if s is None:
        return field
    from ..recipes.schema import default_of
    field = {**field, "keys": keys}
    if field.get("default") is None:  # the schema's default, per job (a cell size is 1 mm in a box, 5 mm in a body)
        field["defaults"] = {job: default_of(job, k) for job, k in keys.items() if job in field["jobs"]}
        field["default"] = next(iter(field["defaults"].values()), None)
    if field["kind"] == "select" and "enum" in s:
        field["options"] = list(s["enum"])
    if not field.get("help") and s.get("description"):
        field["help"] = s["description"]
    for name, v in bounds(s).items():
        if name in field:
            field[name] = max(field[name], v) if name == "lo" else min(field[name], v)
    return field


def apply_more(design: dict, job: str, recipe: dict, error) -> None:
    """Put the design's "more settings" values of ``job`` into ``recipe`` (those given and not the default).

    Each is checked by its declaration (:meth:`~porecad.recipes.table.Table.get`);
    ``error(field, detail)`` makes the exception for a refused value.
    """
    from ..errors import RecipeError
    from ..recipes.table import Table
    from ..recipes.schema import job_keys
    prefix = job + "."
    for name, v in design.items():
        if not name.startswith(prefix) or v is None or v == "":
            continue
        dotted = name[len(prefix):]
        *tables, k = dotted.split(".")
        keys = job_keys(job)
        for t in tables:
            keys = keys[t].keys if t in keys and keys[t].keys is not None else {}
        if k in keys and keys[k].local_only:
            raise error(name, "is local-only: it names a path, a scheduler or worker processes of the machine "
                              "running the studio, which the page may not choose; set it in a recipe for porecad build")
        if k not in keys or _covered(job, dotted) or v == keys[k].default:
            continue
        try:
            value = Table({k: v}, ".".join(tables), schema=keys).get(k)
        except RecipeError as exc:
            raise error(name, exc.detail) from None
        node = recipe
        for t in tables:
            node = node.setdefault(t, {})
        node[k] = value


def more_of(recipe: dict, job: str) -> dict:
    """The "more settings" form values of a recipe: those not the default (the reverse of :func:`apply_more`)."""
    out = {}
    for dotted, schema in scalar_keys(job):
        if _covered(job, dotted):
            continue
        node = recipe
        for part in dotted.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if node is not None and node != schema.get("default"):
            out[f"{job}.{dotted}"] = node
    if out:
        out[MORE] = True
    return out
