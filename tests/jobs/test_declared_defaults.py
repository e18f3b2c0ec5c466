"""Each default stated once (issue 53, item 1): the recipe schema's, shown by the CLI, the studio and the API.

The command line's options, the studio form's fields and the Python API's
signatures take their defaults from :mod:`porecad.recipes.keys`; these tests
read what each shows (the help text, the form's field list, the signature)
and compare it with :func:`porecad.recipes.schema.default_of`, so a default
restated by hand with another value fails here.
"""

import importlib
import inspect

import click
import pytest

import porecad as pc
from porecad.cli.main import COMMANDS
from porecad.cli.options import KeyedOption, keyed_in
from porecad.recipes.schema import default_of, job_names
from porecad.studio.design import fields, recipe_of
from porecad.studio.form_schema import FIELD_KEYS


def _command(name):
    target = COMMANDS[name][0]
    mod, fn = target.split(":")
    return getattr(importlib.import_module("porecad.cli." + mod), fn)


def _as_list(v):
    return list(v) if isinstance(v, (list, tuple)) else [v]


@pytest.mark.parametrize("name", [n for n in COMMANDS if n in job_names()])
def test_every_job_option_shows_the_declared_default(name):
    """Every option of a job's command with a declared default has that default (or None: the job picks it)."""
    command = _command(name)
    checked = 0
    for p in command.params:
        if not isinstance(p, KeyedOption) or p.declared is None or p.is_flag:
            continue
        declared = default_of(name, p.recipe_keys[0])
        if declared is None or p.default is None:
            continue
        assert _as_list(p.default) == _as_list(declared), (name, p.opts, p.default, declared)
        checked += 1
    assert checked >= 1 or name == "ivd" or name == "vessel"


@pytest.mark.parametrize("name, flag, key, shown", [
    ("tpms", "--cell-size", "tpms.cell_size", "default: 1.0"),
    ("infill", "--cell-size", "tpms.cell_size", "default: 5.0"),
    ("infill", "--structure", "tpms.structure", "default: pore"),
    ("tpms", "--resolution", "sampling.resolution", "default: 40"),
    ("tbss", "--resolution", "mesh.resolution", "default: 16"),
    ("hex", "--resolution", "mesh.resolution", "default: 16"),
    ("arbf", "--resolution", "mesh.resolution", "default: 24"),
])
def test_help_shows_the_schema_default_and_range(name, flag, key, shown):
    command = _command(name)
    ctx = click.Context(command, info_name=name, terminal_width=400)
    option = next(p for p in command.params if flag in p.opts)
    _, text = option.get_help_record(ctx)
    assert shown in text
    assert str(default_of(name, key)) in shown
    if key.endswith("resolution") or key.endswith("cell_size"):
        assert "range:" in text  # the declared bounds, which the option's type does not carry


def test_an_option_may_not_restate_a_declared_default():
    option = keyed_in("tpms")
    with pytest.raises(TypeError, match="declared"):
        option("sampling.resolution", "--resolution", type=int, default=40)(lambda resolution: None)
    # None: the job picks the value when the option is not given (allowed)
    option("sampling.resolution", "--resolution", type=int, default=None)(lambda resolution: None)


def test_studio_fields_show_the_schema_defaults_per_job():
    by_name = {f["name"]: f for f in fields(["G", "P"])}
    for name in ("cell_size", "resolution", "skin", "tets", "size", "lambda", "element", "boundary", "structure",
                 "periods"):
        f = by_name[name]
        for job, key in FIELD_KEYS[name].items():
            if job in f["jobs"]:
                assert f["defaults"][job] == default_of(job, key), (name, job)
    assert by_name["cell_size"]["defaults"] == {"tpms": 1.0, "infill": 5.0}
    assert by_name["structure"]["defaults"] == {"tpms": "sheet", "infill": "pore", "tbss": "sheet", "hex": "pore"}


def test_studio_recipe_without_a_value_takes_the_schema_default():
    recipe = recipe_of({"job": "tpms", "type": "G", "structure": "sheet", "control": "porosity", "value": 0.6})
    assert recipe["tpms"]["cell_size"] == default_of("tpms", "tpms.cell_size")
    infill = recipe_of({"job": "infill", "type": "G", "control": "porosity", "value": 0.6})
    assert infill["tpms"]["structure"] == default_of("infill", "tpms.structure") == "pore"
    assert infill["tpms"]["cell_size"] == default_of("infill", "tpms.cell_size")
    assert recipe["sampling"]["resolution"] == default_of("tpms", "sampling.resolution")


@pytest.mark.parametrize("function, job, parameter, key", [
    (pc.infill, "infill", "cell_size", "tpms.cell_size"),
    (pc.infill, "infill", "structure", "tpms.structure"),
    (pc.infill, "infill", "boundary", "domain.boundary"),
    (pc.tbss, "tbss", "resolution", "mesh.resolution"),
    (pc.tbss, "tbss", "periods", "tpms.periods"),
    (pc.hex_scaffold, "hex", "resolution", "mesh.resolution"),
    (pc.hex_scaffold, "hex", "element", "element"),
    (pc.arbf, "arbf", "resolution", "mesh.resolution"),
    (pc.arbf, "arbf", "shape", "arbf.shape"),
    (pc.vessel, "vessel", "blend", "blend"),
])
def test_api_signatures_show_the_schema_defaults(function, job, parameter, key):
    shown = inspect.signature(function).parameters[parameter].default
    assert shown == default_of(job, key) and shown is not None


@pytest.mark.parametrize("job, table, keys", [
    ("tpms", "tpms", ("threshold", "porosity")), ("infill", "tpms", ("threshold", "porosity")),
    ("hex", "tpms", ("threshold", "porosity")), ("tis", "tis", ("relative", "threshold")),
])
def test_the_one_of_rule_is_declared_once_and_read_by_every_job(job, table, keys):
    """Exactly one of a pair: declared on the key (``one_of``), checked by ``Table.one_of`` for every job."""
    from porecad.errors import RecipeError
    from porecad.recipes.schema import declared
    from porecad.recipes.table import Table
    first = declared(job, f"{table}.{keys[0]}")
    assert first.one_of and first.excludes == keys[1:]
    schema = __import__("porecad.recipes.schema", fromlist=["job_keys"]).job_keys(job)[table].keys
    for given, ok in (({}, False), ({keys[0]: 0.1}, True), ({keys[1]: 0.2}, True), ({keys[0]: 0.1, keys[1]: 0.2}, False)):
        t = Table(given, table, schema=schema)
        if ok:
            assert t.one_of(keys[0]) in keys
        else:
            with pytest.raises(RecipeError, match="exactly one of"):
                t.one_of(keys[0])
    assert Table({}, table, schema=schema).one_of(keys[0], waived=True) is None


def test_no_job_module_restates_the_one_of_rule():
    from pathlib import Path
    import porecad
    src = Path(porecad.__file__).parent
    for module in [*(src / "jobs").glob("*.py"), src / "cli" / "cmd_lattice.py"]:
        text = module.read_text(encoding="utf-8")
        assert "exactly one of" not in text, module.name
