"""The ``porecad`` command group and its entry point.

Errors a user can cause print one line (``porecad: error: ...``) on stderr and
exit non-zero; progress goes to stderr; ``--json`` prints exactly one JSON
object on stdout. SIGTERM and SIGINT stop the job within moments, remove
every unfinished output and print one line saying what was written
(:mod:`porecad.cli.watch`).
"""

from __future__ import annotations

import functools
import importlib
import os
import signal
import sys
from collections.abc import MutableMapping
from gettext import gettext

import click

from ..errors import PorecadError, RecipeError, ResourceError
from ..version import __version__
from .console import as_flag_error
from .options import with_flags

#: Every command: name -> ("module:function" in ``porecad.cli``, its one line in the ``porecad --help`` list).
#: A command's module is imported when that command runs or shows its own help, never for the list, so
#: ``porecad --help`` starts fast and a command imports only what it needs. The line is the first sentence
#: of the command's docstring (``tests/cli/test_startup.py`` checks that they agree). A new command is one entry.
COMMANDS = {
    "analyze": ("cmd_analyze:analyze",
                "Analyse a mesh: volume, area, porosity, topology, validity; with --pores sizes and connectivity."),
    "arbf": ("cmd_arbf:arbf", "Build a porous solid from an anisotropic-RBF pore network (000 ch.5) over a tet or "
             "hex mesh or a point cloud."),
    "build": ("cmd_lattice:build", "Run a recipe (TOML) written by any porecad command (--recipe) or by hand."),
    "demo": ("cmd_lattice:demo", "Graded gyroid-sheet scaffold in the bundled analytic lumbar disc."),
    "export": ("cmd_export:export",
               "Write a tpms or infill recipe's design as an implicit 3MF (a function graph and its level set)."),
    "hex": ("cmd_hex:hex_command", "Map one TPMS cell into every hexahedron of a hex mesh (BODY: frustum, "
            "cylinder, a closed surface mesh parameterised as a deformed cube (000 ch.3), or a hex-mesh file "
            "(.vtu .vtk .msh .inp .mesh; cube-symmetric types P, IWP, FRD, neovius, tubular_P))."),
    "infill": ("cmd_lattice:infill", "Fill a body (a mesh, or an image) with a TPMS scaffold."),
    "ivd": ("cmd_ivd:ivd", "Segment the discs of IMAGE_DIR and build one closed porous scaffold per disc and method."),
    "phantom": ("cmd_ivd:phantom", "Generated test images (000 ch.6 phantoms)."),
    "properties": ("cmd_simulate:properties",
                   "Effective stiffness and permeability of a design (a recipe or a closed mesh)."),
    "schema": ("cmd_schema:schema", "Print the JSON Schema (draft 2020-12) of JOB's recipe, or of every job's."),
    "seg": ("cmd_ivd:seg",
            "Disc segmentation (000 §6.2): U-Nets (train, predict: need porecad[seg]), classical, evaluate."),
    "slice": ("cmd_slice:slice_command", "Slice a recipe (tpms/infill: from its field; other jobs: their mesh) or a "
              "mesh file for a printer."),
    "studio": ("cmd_studio:studio", "Design scaffolds in the browser, with a live 3D preview (needs `pip install "
               "'porecad[studio]'`)."),
    "tbss": ("cmd_tbss:tbss", "Build a heterogeneous TPMS scaffold in a trivariate B-spline solid (BODY: disc, box, "
             "cylinder, tube or a mesh file to fit), or regenerate one from a TDF file."),
    "tis": ("cmd_tis:tis", "Build a porous solid from tetrahedral implicit surfaces (TIS) over a tet mesh."),
    "tpms": ("cmd_lattice:tpms",
             "Build a TPMS scaffold (pore, rod, sheet solid or bare surface) in a box of cells."),
    "vessel": ("cmd_vessel:vessel", "Build a vessel model (lumen solid, or a layered porous wall) from a CENTRELINE "
               "graph with radii (.vtp VMTK centreline, .swc, .json) or a segmented --image (document 003)."),
    "volmesh": ("cmd_simulate:volmesh",
                "Tetrahedral volume mesh of a closed solid (a mesh file, or a recipe that builds one)."),
}


class LazyCommands(MutableMapping):
    """``cli.commands``: name -> command, each imported from its module (:data:`COMMANDS`) on first use.

    Listing the names (``list_commands``, "did you mean") imports nothing;
    reading a command imports its module and wraps it (:func:`_errors_name_flags`).
    """

    def __init__(self, table: dict):
        self.table = dict(table)
        self.loaded: dict[str, click.Command] = {}

    def __getitem__(self, name: str) -> click.Command:
        if name not in self.loaded:
            if name not in self.table:
                raise KeyError(name)
            module, _, attr = self.table[name][0].partition(":")
            command = getattr(importlib.import_module(f"{__package__}.{module}"), attr)
            self.loaded[name] = _errors_name_flags(command)
        return self.loaded[name]

    def __setitem__(self, name: str, command: click.Command) -> None:
        self.loaded[name] = command

    def __delitem__(self, name: str) -> None:
        if name not in self:
            raise KeyError(name)
        self.table.pop(name, None)
        self.loaded.pop(name, None)

    def __contains__(self, name) -> bool:
        return name in self.table or name in self.loaded

    def __iter__(self):
        return iter(dict.fromkeys([*self.table, *self.loaded]))

    def __len__(self) -> int:
        return len(set(self.table) | set(self.loaded))

    def for_listing(self, name: str) -> click.Command:
        """A stand-in for command ``name`` that knows its line of the list (the command itself if loaded)."""
        if name in self.loaded or name not in self.table:
            return self[name]
        return click.Command(name, help=self.table[name][1])


class LazyGroup(click.Group):
    """The ``porecad`` group: its commands load on first use (:class:`LazyCommands`).

    Its own help lists them from :data:`COMMANDS` (as :meth:`click.Group.format_commands`
    does, without importing a command module).
    """

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        commands = [(name, self.commands.for_listing(name)) for name in self.list_commands(ctx)]
        commands = [(name, command) for name, command in commands if not command.hidden]
        if commands:
            limit = formatter.width - 6 - max(len(name) for name, _ in commands)
            with formatter.section(gettext("Commands")):
                formatter.write_dl([(name, command.get_short_help_str(limit)) for name, command in commands])


@click.group(cls=LazyGroup, commands=LazyCommands(COMMANDS),
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="porecad")
def cli():
    """porecad: porous scaffolds and implicit vascular models as watertight, printable meshes.

    \b
    Quick start:
      porecad demo -o demo-out            # graded gyroid scaffold in a lumbar disc
      porecad tpms --list                 # the TPMS catalogue
      porecad tpms G --structure sheet --porosity 0.6 --cells 2 2 2 --cell-size 2 -o g.stl --recipe g.toml
      porecad build g.toml --force        # rerun any job from its recipe
      porecad analyze g.stl --json
      porecad studio                      # design in the browser (local, live 3D preview)
    """


def _errors_name_flags(command: click.Command) -> click.Command:
    """Wrap ``command`` (and a group's subcommands) so that its library errors name its options, not recipe keys.

    A command that runs (not a group, not only its help) first sets the notice
    that numba is compiling (:func:`porecad.first_run.install_notice`), on a terminal.
    """
    for sub in getattr(command, "commands", {}).values():
        _errors_name_flags(sub)
    callback = command.callback
    if callback is None:
        return command
    runs = not isinstance(command, click.Group)

    @functools.wraps(callback)
    def run(*args, **kwargs):
        if runs and sys.stderr.isatty():
            from ..first_run import install_notice
            install_notice()
        try:
            return callback(*args, **kwargs)
        except PorecadError as exc:
            ctx = click.get_current_context()
            if isinstance(exc, RecipeError):  # a recipe file's own key keeps its name
                exc = as_flag_error(exc, given_only="recipe_file" in ctx.params)
            text = str(exc)
            flagged = with_flags(text, ctx.command, ctx.params)
            if flagged != text:
                exc.args = (flagged,)
            raise exc from None
    command.callback = run
    return command


class Terminated(Exception):
    """SIGTERM arrived (raised in the main thread so that ``finally`` blocks clean up)."""


def _on_sigterm(signum, frame):
    raise Terminated()


#: the exit status of an unexpected exception (a bug; EX_SOFTWARE of sysexits.h)
INTERNAL_ERROR = 70

#: commands that run in this process (they serve until stopped and handle signals themselves)
IN_PROCESS = ("studio",)


def main(argv=None):
    """Entry point: run the CLI, turning user errors into one-line messages.

    Called as the ``porecad`` program (``argv`` None) the command runs in a
    watched child process (:func:`porecad.cli.watch.run_watched`), so that
    Ctrl-C stops it at once; ``PORECAD_WATCH=0`` or an ``argv`` (a call from
    Python) runs it here.
    """
    args = sys.argv[1:] if argv is None else list(argv)
    watched = (argv is None and os.environ.get("PORECAD_WATCH", "1") != "0" and hasattr(os, "fork")
               and not any(a in IN_PROCESS for a in args[:1]))
    if watched:
        from .watch import run_watched
        code = run_watched(lambda: _invoke(args))
        for sig in (signal.SIGINT, signal.SIGTERM):  # done and reported: a late signal changes nothing now
            signal.signal(sig, signal.SIG_IGN)
        return code
    if argv is None:  # the program, loaded (porecad.entry stopped it outright until now): Ctrl-C as usual
        signal.signal(signal.SIGINT, signal.default_int_handler)
    return _invoke(args)


def _invoke(argv):
    """Run the command line ``argv``; return its exit code."""
    if any("\x00" in str(a) for a in argv):  # no shell passes one; a script might (and os calls choke on it)
        click.echo("porecad: error: an argument contains a NUL character", err=True)
        return 2
    previous = None
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (embedded use): leave signals alone
        previous = None
    import warnings
    try:
        with warnings.catch_warnings():
            # numpy and third-party warnings are not for users (and would break the one-line errors);
            # porecad's own warnings travel in the report and are printed one line each
            warnings.simplefilter("ignore")
            cli.main(args=argv, prog_name="porecad", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("porecad: interrupted; nothing written", err=True)
        return 130
    except Terminated:
        click.echo("porecad: terminated; nothing written", err=True)
        return 143
    except click.ClickException as exc:
        msg = " ".join(exc.format_message().split())
        click.echo(f"porecad: error: {msg}", err=True)
        return 2
    except PorecadError as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        click.echo(f"porecad: error: {text}", err=True)
        return exc.exit_code
    except MemoryError:
        click.echo(f"porecad: error: {ResourceError('out of memory; lower the resolution')}", err=True)
        return 3
    except (Exception, SystemExit) as exc:  # a bug: still one true line and a non-zero exit, never a traceback
        text = type(exc).__name__ + (f": {str(exc).strip().splitlines()[0]}" if str(exc).strip() else "")
        click.echo(f"porecad: error: internal error: {text[:300]} (a bug in porecad; please report it)", err=True)
        return INTERNAL_ERROR
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
