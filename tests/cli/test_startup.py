"""Start-up (issue 54): ``porecad --help`` and a command's help import no command module they do not show.

Checked by what is imported, never by timing: the command list comes from
``cli/main.py``'s ``COMMANDS`` table, a command's module loads when that
command runs or shows its own help, and numba loads when a kernel first runs.
"""

import importlib
import inspect
import json
import os
import pkgutil
import subprocess
import sys

import click
import pytest

import porecad.cli
from porecad.cli.main import COMMANDS, LazyCommands, LazyGroup, cli, main

#: modules that a help text must not load (numerics, the mesh formats, the jobs)
HEAVY = ("numba", "llvmlite", "numpy", "scipy", "trimesh", "skimage", "porecad.cli.cmd_", "porecad.io.meshfiles",
         "porecad.io._stl_kernel", "porecad.jobs", "porecad.api")


def _loaded_after(code: str) -> tuple[list[str], str]:
    """Run ``code`` in a fresh interpreter; the heavy modules it loaded, and what it printed."""
    script = (f"import sys\n{code}\n"
              f"print('MODULES=' + __import__('json').dumps(sorted(m for m in sys.modules if m.startswith({HEAVY!r}))))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, encoding="utf-8", timeout=120,
                          env={**os.environ, "PYTHONIOENCODING": "utf-8"})
    assert done.returncode == 0, done.stderr
    out, _, modules = done.stdout.rpartition("MODULES=")
    return json.loads(modules), out


def test_help_imports_no_command_module():
    """``porecad --help``: the full list of commands, and no command module, numpy or numba loaded."""
    loaded, out = _loaded_after("from porecad.cli.main import main\nassert main(['--help']) == 0")
    assert loaded == []
    listed = [line.split()[0] for line in out.split("Commands:")[1].splitlines() if line.startswith("  ")]
    assert listed == sorted(COMMANDS)


def test_program_help_imports_no_command_module():
    """The ``porecad`` program itself (``python -m porecad --help``, the watched path) loads no command module."""
    code = ("import runpy\nsys.argv = ['porecad', '--help']\n"
            "try:\n    runpy.run_module('porecad', run_name='__main__')\nexcept SystemExit as e:\n    assert not e.code\n")
    loaded, out = _loaded_after(code)
    assert loaded == []
    assert "Commands:" in out


def test_a_command_help_imports_its_module_only():
    """``porecad tpms --help`` loads ``cmd_lattice`` and nothing numerical."""
    loaded, out = _loaded_after("from porecad.cli.main import main\nassert main(['tpms', '--help']) == 0")
    assert loaded == ["porecad.cli.cmd_lattice"]
    assert "--structure" in out


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_listed_command_loads_and_shows_its_help(name, capsys):
    """Each entry of the table names its command, its list line is the command's own, and its help works."""
    command = cli.commands[name]
    assert isinstance(command, click.Command) and command.name == name and not command.hidden
    assert COMMANDS[name][1] == command.get_short_help_str(10 ** 6), "update COMMANDS in cli/main.py"
    assert main([name, "--help"]) == 0
    assert f"Usage: porecad {name}" in capsys.readouterr().out


@pytest.mark.parametrize("width", [50, 80, 120])
def test_the_list_is_what_click_would_print(width):
    """The list from the table is the list click prints from the loaded commands, at any terminal width."""
    lazy = LazyGroup("porecad", commands=LazyCommands(COMMANDS), help=cli.help, params=cli.params)
    plain = click.Group("porecad", commands={name: cli.commands[name] for name in COMMANDS}, help=cli.help,
                        params=cli.params)
    text = lazy.get_help(click.Context(lazy, info_name="porecad", terminal_width=width))
    assert text == plain.get_help(click.Context(plain, info_name="porecad", terminal_width=width))
    assert not lazy.commands.loaded


def test_every_command_module_is_in_the_table():
    """A command defined in a ``cmd_*`` module (not a group's subcommand) is listed: one entry in COMMANDS."""
    registered = {target for target, _ in COMMANDS.values()}
    defined = set()
    for info in pkgutil.iter_modules(porecad.cli.__path__):
        if not info.name.startswith("cmd_"):
            continue
        module = importlib.import_module(f"porecad.cli.{info.name}")
        commands = {attr: c for attr, c in inspect.getmembers(module) if isinstance(c, click.Command)}
        subs = {id(s) for c in commands.values() if isinstance(c, click.Group) for s in c.commands.values()}
        defined |= {f"{info.name}:{attr}" for attr, c in commands.items() if id(c) not in subs}
    assert defined <= registered, sorted(defined - registered)


def test_unknown_command_still_suggests(run_cli):
    """Did-you-mean and the unknown-command error read the table (no module loaded for them)."""
    code, _, err = run_cli("tpm")
    assert code == 2 and "No such command 'tpm'. Did you mean 'tpms'?" in err
