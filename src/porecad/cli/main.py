"""The ``porecad`` command group and its entry point.

Errors a user can cause print one line (``porecad: error: ...``) on stderr and
exit non-zero; progress goes to stderr; ``--json`` prints exactly one JSON
object on stdout. SIGTERM and SIGINT stop the job within moments, remove
every unfinished output and print one line saying what was written
(:mod:`porecad.cli.watch`).
"""

from __future__ import annotations

import os
import signal
import sys

import click

from ..errors import PorecadError, RecipeError, ResourceError
from ..version import __version__
from . import (
    cmd_analyze,
    cmd_arbf,
    cmd_hex,
    cmd_ivd,
    cmd_lattice,
    cmd_schema,
    cmd_simulate,
    cmd_slice,
    cmd_studio,
    cmd_tbss,
    cmd_tis,
    cmd_vessel,
)
from .console import as_flag_error
from .options import with_flags


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
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
    """Wrap ``command`` (and a group's subcommands) so that its library errors name its options, not recipe keys."""
    import functools
    for sub in getattr(command, "commands", {}).values():
        _errors_name_flags(sub)
    callback = command.callback
    if callback is None:
        return command

    @functools.wraps(callback)
    def run(*args, **kwargs):
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


for _command in (cmd_lattice.demo, cmd_lattice.tpms, cmd_lattice.infill, cmd_lattice.build, cmd_analyze.analyze,
                 cmd_tbss.tbss, cmd_hex.hex_command, cmd_tis.tis, cmd_arbf.arbf, cmd_vessel.vessel, cmd_ivd.ivd,
                 cmd_ivd.phantom, cmd_ivd.seg, cmd_simulate.volmesh, cmd_simulate.properties, cmd_slice.slice_command,
                 cmd_studio.studio, cmd_schema.schema):
    cli.add_command(_errors_name_flags(_command))


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
    if sys.stderr.isatty():
        from ..first_run import install_notice
        install_notice()
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
