"""The recipe schema (porecad.recipes.schema, issue 38 "One schema"): declared once, everything derives from it."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

from porecad.errors import RecipeError
from porecad.recipes import keys as recipe_keys
from porecad.recipes.table import Table
from porecad.recipes.schema import REQUIRED, Key, docs_markdown, docs_synced, job_keys, job_names, json_schema, walk

ROOT = Path(__file__).resolve().parents[2]
SPECS = ["tpms_spec", "tbss_job", "hex_job", "tis_job", "arbf_job", "vessel_job", "ivd_job", "runner", "promise"]


def _resolve(keys: dict, dotted: str):
    """The Key at ``dotted`` (``tpms.cell_size.axis``, ``tdf.edits``), or None."""
    key = None
    for part in dotted.split("."):
        if keys is None or part not in keys:
            return None
        key = keys[part]
        keys = key.keys
    return key


def test_every_job_has_a_valid_json_schema():
    from porecad.jobs.registry import names
    assert job_names() == names()
    for job in job_names():
        s = json.loads(json.dumps(json_schema(job)))
        assert s["$schema"].endswith("2020-12/schema")
        assert s["properties"]["job"]["const"] == job
        assert s["additionalProperties"] is False
        for name, key in walk(job_keys(job)):
            assert key.help, f"{job}: {name} has no help text"
    whole = json_schema()
    assert set(whole["$defs"]) == set(job_names())


def test_json_schema_carries_bounds_defaults_units_and_exclusions():
    tis = json_schema("tis")["properties"]
    res = tis["mesh"]["properties"]["resolution"]
    assert (res["type"], res["minimum"], res["maximum"], res["default"]) == ("integer", 3, 4096, 17)
    size = tis["domain"]["properties"]["size"]
    assert size["x-units"] == "mm" and size["exclusiveMinimum"] == 0
    assert {"not": {"required": ["relative", "threshold"]}} in tis["tis"]["allOf"]
    hexp = json_schema("hex")["properties"]["tpms"]["properties"]["porosity"]
    assert hexp["exclusiveMinimum"] == 0.0 and hexp["exclusiveMaximum"] == 1.0
    assert json_schema("vessel")["required"] == ["input", "voxel"]


def test_output_keys_are_the_jobs_outputs():
    from porecad.jobs.registry import get
    for job in job_names():
        assert tuple(job_keys(job)["output"].keys) == get(job).outputs


def _spec_reads(module: str):
    """``(line, key)`` of every literal key a spec module reads from a table with ``.get("key")``."""
    tree = ast.parse((ROOT / "src/porecad/jobs" / f"{module}.py").read_text(encoding="utf-8"))
    readers = [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and (
        f.name in ("from_recipe", "parse", "_three") or f.name.endswith(("_table", "_params")))]
    for n in (n for f in readers for n in ast.walk(f)):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "get" and n.args \
                and isinstance(n.args[0], ast.Constant) and isinstance(n.args[0].value, str) \
                and isinstance(n.func.value, ast.Name) and (len(n.func.value.id) == 1 or n.func.value.id == "table"):
            # the specs name their tables with one letter (r, t, d, m, ...)
            yield n.lineno, n.args[0].value


def test_every_key_a_spec_reads_is_declared():
    declared = {name.rsplit(".", 1)[-1] for job in job_names() for name, _ in walk(job_keys(job))}
    for module in SPECS:
        for line, k in _spec_reads(module):
            assert k in declared, f"{module}.py:{line} reads {k!r}, declared nowhere"


def test_an_undeclared_read_is_a_programming_error():
    t = Table({"resolution": 5}, "mesh", schema=job_keys("tis")["mesh"].keys)
    with pytest.raises(LookupError, match="not declared"):
        t.integer("resolutoin", 3, lo=1, hi=9)


def test_done_refuses_a_key_the_schema_does_not_declare():
    t = Table({"resolution": 5, "colour": "red"}, "mesh", schema=job_keys("tis")["mesh"].keys)
    assert t.get("resolution") == 5
    with pytest.raises(RecipeError, match="unknown key 'colour'"):
        t.done("colour")


def _bounded():
    for job in job_names():
        for name, key in walk(job_keys(job)):
            if key.kind in ("int", "number") and key.hi is not None and "[]" not in name:
                yield job, name, key


@pytest.mark.parametrize("job,name,key", list(_bounded()), ids=lambda v: v if isinstance(v, str) else "")
def test_declared_bounds_are_enforced_naming_the_key(job, name, key):
    parent, _, k = name.rpartition(".")
    keys = _resolve(job_keys(job), parent).keys if parent else job_keys(job)
    step = 1 if key.kind == "int" else max(abs(key.hi) * 1e-9, 1e-9)
    t = Table({k: key.hi + step if key.kind == "int" or not key.open_hi else key.hi}, parent, schema=keys)
    with pytest.raises(RecipeError) as err:
        t.get(k)
    assert err.value.key == name
    assert Table({k: key.hi - (0 if not key.open_hi else step)}, parent, schema=keys).get(k) is not None


@pytest.mark.parametrize("recipe,key", [
    ({"job": "tis", "tis": {"relative": 0.2}, "mesh": {"resolution": 4097}}, "mesh.resolution"),
    ({"job": "tis", "tis": {"relative": 1.01}}, "tis.relative"),
    ({"job": "tpms", "tpms": {"type": "G", "threshold": 0}, "sampling": {"resolution": 1}}, "sampling.resolution"),
    ({"job": "arbf", "mesh": {"resolution": 2}}, "mesh.resolution"),
    ({"job": "hex", "body": {"kind": "cylinder"}, "grid": [1, 1, 1], "tpms": {"porosity": 1.0}}, "tpms.porosity"),
])
def test_a_value_just_outside_the_schema_is_refused_by_the_job(recipe, key):
    from porecad.jobs import parse
    from porecad.recipes.schema import json_schema as js
    # the refused value is outside the bounds the schema publishes
    top, _, k = key.partition(".")
    prop = js(recipe["job"])["properties"][top]["properties"][k]
    assert any(b in prop for b in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"))
    with pytest.raises(RecipeError) as err:
        parse(recipe)
    assert err.value.key == key


def _keyed_commands():
    from porecad.cli.main import cli
    from porecad.cli.options import KeyedOption
    for name, command in cli.commands.items():
        keys = [k for p in command.params if isinstance(p, KeyedOption) for k in p.recipe_keys]
        if keys:
            yield name, keys


def test_every_keyed_cli_option_sets_a_declared_key():
    commands = dict(_keyed_commands())
    assert {"tpms", "infill", "tbss", "hex", "tis", "arbf", "vessel", "ivd"} <= set(commands)
    for name, keys in commands.items():
        jobs = [name] if name in job_names() else job_names()  # build: any job's keys
        for k in keys:
            assert any(_resolve(job_keys(j), k) is not None for j in jobs), f"porecad {name}: {k} not declared"


def test_docs_page_is_in_sync_with_the_schema():
    page = (ROOT / "docs/recipes.md").read_text(encoding="utf-8")
    assert docs_synced(page) == page, "docs/recipes.md is out of date: run `python -m porecad.recipes.schema --docs`"


def test_schema_command_prints_json_schema_and_refuses_unknown_jobs(capsys):
    from porecad.cli.main import _invoke
    assert _invoke(["schema", "tis"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(json_schema("tis")))
    assert _invoke(["schema", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown job 'nope'" in err and len(err.strip().splitlines()) == 1


def test_a_key_added_to_the_schema_appears_everywhere(monkeypatch, capsys):
    from porecad.cli.main import _invoke
    from porecad.studio.design import FieldError, design_of, fields, recipe_of
    new = Key("int", 7, "A key added in one place.", units="mm", lo=1, hi=9)
    monkeypatch.setitem(recipe_keys.JOBS["tis"]["mesh"].keys, "wobble", new)
    assert _invoke(["schema", "tis"]) == 0
    shown = json.loads(capsys.readouterr().out)["properties"]["mesh"]["properties"]["wobble"]
    assert shown == {"type": "integer", "minimum": 1, "maximum": 9, "description": "A key added in one place.",
                     "default": 7, "x-units": "mm"}
    assert "| `[mesh]` | `wobble` | integer | `7` | [1, 9] | mm | A key added in one place. |" in docs_markdown()
    field = [f for f in fields(["G", "P"]) if f["name"] == "tis.mesh.wobble"]
    assert field and field[0]["kind"] == "int" and field[0]["default"] == 7 and field[0]["jobs"] == ["tis"]
    assert (field[0]["lo"], field[0]["hi"], field[0]["label"]) == (1, 9, "Wobble (mm) [mesh]")
    recipe = recipe_of({"job": "tis", "tis.mesh.wobble": 8})
    assert recipe["mesh"]["wobble"] == 8 and design_of(recipe)["tis.mesh.wobble"] == 8
    assert "wobble" not in recipe_of({"job": "tis", "tis.mesh.wobble": 7})["mesh"]  # the default: not written
    with pytest.raises(FieldError) as err:
        recipe_of({"job": "tis", "tis.mesh.wobble": 10})
    assert err.value.field == "tis.mesh.wobble" and "at most 9" in err.value.detail
    # the command line checks it by its declaration (--set), before any work
    assert _invoke(["tis", "--regular-tet", "--relative-threshold", "0.2", "--set", "mesh.wobble=10"]) == 2
    assert "--set mesh.wobble: wobble must be at most 9, got 10" in capsys.readouterr().err
    # and the job reads it through its declaration
    t = Table({"wobble": 10}, "mesh", schema=recipe_keys.JOBS["tis"]["mesh"].keys)
    with pytest.raises(RecipeError, match="mesh.wobble"):
        t.get("wobble")


def test_required_keys_and_old_formats():
    assert job_keys("vessel")["voxel"].default is REQUIRED
    from porecad.jobs import parse
    job, spec, _, _ = parse({"job": "tpms", "format": 1, "tpms": {"type": "G", "threshold": 0.0}})
    from porecad.lattice.spec import Sampling
    assert job.name == "tpms" and spec.sampling == Sampling(resolution=40)


def test_studio_main_fields_take_options_and_help_from_the_schema():
    from porecad.studio.design import fields
    by_name = {f["name"]: f for f in fields(["G", "P"])}
    assert by_name["element"]["options"] == list(job_keys("hex")["element"].choices)
    assert by_name["boundary"]["options"] == list(job_keys("infill")["domain"].keys["boundary"].choices)
    assert by_name["element"]["help"] == job_keys("hex")["element"].help
    # every scalar key no main field sets is a "more settings" field of its job
    more = {f["name"] for f in by_name.values() if f.get("key")}
    assert {"tis.mesh.smooth", "hex.cut", "vessel.segment_angle", "tpms.post.smooth"} <= more
    assert "vessel.workers" not in more  # local-only (docs/security.md)


def test_cli_choices_are_the_schemas():
    """An option that sets a choice key offers that key's choices (some of them: a command may offer fewer)."""
    import click

    from porecad.cli.main import cli
    from porecad.cli.options import KeyedOption
    checked = 0
    for name, command in cli.commands.items():
        if name not in job_names():
            continue
        for p in command.params:
            if not isinstance(p, KeyedOption) or not isinstance(p.type, click.Choice):
                continue
            for k in p.recipe_keys:
                key = _resolve(job_keys(name), k)
                if key is not None and key.kind == "choice":
                    fold = key.fold_case or not p.type.case_sensitive
                    norm = (lambda xs: {x.lower() for x in xs}) if fold else set
                    assert norm(p.type.choices) <= norm(key.choices), f"porecad {name} {p.opts[0]} vs {k}"
                    checked += 1
    assert checked >= 10


def test_api_keywords_are_declared_keys():
    """The keyword arguments of the API's job functions name keys of their job's schema."""
    import inspect

    from porecad import api
    jobs = {"infill": "infill", "tbss": "tbss", "hex_scaffold": "hex", "tis": "tis", "arbf": "arbf",
            "vessel": "vessel"}
    not_keys = {"body", "domain", "centreline", "tables", "keys"}  # the body (a kind or a path), extra tables
    for fn, job in jobs.items():
        declared = {name.rsplit(".", 1)[-1] for name, _ in walk(job_keys(job))}
        for p in inspect.signature(getattr(api, fn)).parameters:
            assert p in not_keys or p in declared, f"porecad.api.{fn}({p}=...) is not a {job} recipe key"


def _conforms(value, schema, where=""):
    """Problems of ``value`` against a JSON Schema (the parts porecad's schemas use)."""
    if "anyOf" in schema:
        return [] if any(not _conforms(value, s, where) for s in schema["anyOf"]) else [f"{where}: no form fits"]
    kinds = {"object": dict, "array": list, "string": str, "boolean": bool, "integer": int, "number": (int, float)}
    t = schema.get("type")
    if t and (not isinstance(value, kinds[t]) or t in ("integer", "number") and isinstance(value, bool)):
        return [f"{where}: not {t}"]
    bad = []
    if "enum" in schema and value not in schema["enum"]:
        bad.append(f"{where}: not one of {schema['enum']}")
    if "const" in schema and value != schema["const"]:
        bad.append(f"{where}: not {schema['const']}")
    if "minimum" in schema and value < schema["minimum"] or "maximum" in schema and value > schema["maximum"]:
        bad.append(f"{where}: out of range")
    if t == "object":
        props = schema.get("properties", {})
        bad += [f"{where}.{k}: not declared" for k in value if k not in props]
        bad += [f"{where}.{k}: required" for k in schema.get("required", []) if k not in value]
        for k, v in value.items():
            if k in props:
                bad += _conforms(v, props[k], f"{where}.{k}")
    if t == "array":
        for i, v in enumerate(value):
            bad += _conforms(v, schema.get("items", {}), f"{where}[{i}]")
    return bad


def test_written_recipes_conform_to_the_json_schema(tmp_path):
    import tomllib

    from porecad.cli.main import _invoke
    page = (ROOT / "docs/recipes.md").read_text(encoding="utf-8")
    example = tomllib.loads(page.split("```toml\n", 1)[1].split("```", 1)[0])
    assert _conforms(example, json_schema("tis")) == []
    out = tmp_path / "g.toml"
    assert _invoke(["tpms", "G", "--structure", "sheet", "--porosity", "0.6", "--cells", "1", "1", "1",
                    "--resolution", "12", "-o", str(tmp_path / "g.stl"), "--recipe", str(out)]) == 0
    recipe = tomllib.loads(out.read_text(encoding="utf-8"))
    assert _conforms(recipe, json_schema("tpms")) == []
    recipe["sampling"]["resolutoin"] = 3
    assert _conforms(recipe, json_schema("tpms")) == [".sampling.resolutoin: not declared"]


def test_the_jobs_own_names_of_kinds_are_the_schemas():
    from porecad.jobs import arbf_job, tis_job, tpms_spec
    from porecad.maps.tbss_design import BODY_KINDS
    assert job_keys("tis")["domain"].keys["kind"].choices == tis_job.DOMAIN_KINDS
    assert job_keys("arbf")["domain"].keys["kind"].choices == arbf_job.DOMAIN_KINDS
    assert job_keys("tbss")["body"].keys["kind"].choices == BODY_KINDS + ("mesh",)
    assert job_keys("tpms")["grading"].keys["kind"].choices == tpms_spec.GRADING_KINDS


def test_set_option_takes_any_declared_key(tmp_path, capsys):
    from porecad.cli.main import _invoke, cli
    with_set = {name for name, c in cli.commands.items() if any(p.name == "settings" for p in c.params)}
    assert {"tpms", "infill", "tbss", "hex", "tis", "arbf", "vessel"} <= with_set
    base = ["tis", "--regular-tet", "--relative-threshold", "0.2", "-n", "20", "-o", str(tmp_path / "t.stl")]
    assert _invoke(base + ["--set", "mesh.smooht=3"]) == 2
    assert "--set: takes KEY=VALUE with a key of job tis's recipe" in capsys.readouterr().err
    assert _invoke(base + ["--set", "mesh.smooth=1001"]) == 2
    assert "--set mesh.smooth: smooth must be at most 1,000, got 1001" in capsys.readouterr().err
    assert _invoke(base + ["--set", "mesh.method=grid", "--recipe", str(tmp_path / "t.toml")]) == 0
    assert 'method = "grid"' in (tmp_path / "t.toml").read_text(encoding="utf-8")


def test_specs_read_keys_only_through_their_declarations():
    """No spec restates a key's kind, bounds or default: the typed getters are Table.get's, not the specs'."""
    import re
    getters = re.compile(r"\b[a-z]\.(integer|number|choice|flag|string|path|numbers|integers|checked|raw|output)\(")
    for module in SPECS:
        text = (ROOT / "src/porecad/jobs" / f"{module}.py").read_text(encoding="utf-8")
        assert not getters.findall(text), f"{module}.py reads a key past its declaration"
