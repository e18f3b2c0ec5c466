"""What the command line prints: progress bars (rich) and warnings on stderr, the report on stdout.

``--json`` prints exactly one JSON object on stdout; otherwise a short
summary. Progress shows only when stderr is a terminal.
"""

from __future__ import annotations

import sys

import click

from ..errors import RecipeError
from .options import with_flags

#: report keys printed by every build command (after the job's own summary keys)
COMMON_SUMMARY = ("porosity", "porosity_voxel", "volume", "surface_area", "triangles", "closed", "manifold",
                  "self_intersections", "mesh_file", "tets_file", "tdf_file", "report_file", "report_dir",
                  "recipe_file")


class Progress:
    """``progress(stage, done, total)`` drawn as one rich bar per stage on stderr (a terminal only)."""

    def __init__(self, enabled: bool | None = None):
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.bar = None
        self.task = None
        self.stage = None

    def __call__(self, stage, done, total):
        if not self.enabled:
            return
        if stage != self.stage or self.bar is None:
            self.close()
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress as Bar, TimeElapsedColumn
            self.bar = Bar("[progress.description]{task.description:>10}", BarColumn(), MofNCompleteColumn(),
                           TimeElapsedColumn(), console=Console(stderr=True), transient=False)
            self.bar.start()
            self.task = self.bar.add_task(str(stage), total=max(int(total), 1))
            self.stage = stage
        self.bar.update(self.task, completed=int(done), total=max(int(total), 1))
        if done >= total:
            self.close()

    def log(self, message: str) -> None:
        """A progress line (long jobs that report steps rather than counts)."""
        if self.enabled:
            self.close()
            click.echo(f"porecad: {message}", err=True)

    def close(self):
        if self.bar is not None:
            self.bar.stop()
        self.bar = None
        self.stage = None

    def __del__(self):  # pragma: no cover - interpreter shutdown
        try:
            self.close()
        except Exception:
            pass


def warn(report: dict) -> None:
    """Print the report's warnings on stderr, one line each (a recipe key they name, as the command's option)."""
    for w in report.get("warnings") or []:
        line = " ".join(str(w).split())
        ctx = click.get_current_context(silent=True)
        if ctx is not None:  # a recipe key in backquotes, as the running command's option
            line = with_flags(line, ctx.command, ctx.params)
        click.echo(f"porecad: warning: {line}", err=True)


def emit(report: dict, as_json: bool, keys=()) -> None:
    """The report: one JSON object (``--json``) or ``key: value`` lines of the summary keys."""
    if as_json:
        from ..io.jsonable import dumps  # numpy: not loaded for a command's help or an early error
        click.echo(dumps(report))
        return
    for k in tuple(keys) + tuple(k for k in COMMON_SUMMARY if k not in keys):
        v = report.get(k)
        if v is None or isinstance(v, (dict, list)):
            continue
        click.echo(f"{k:>18}: {v:.6g}" if isinstance(v, float) else f"{k:>18}: {v}")
    if report.get("timings"):
        click.echo(f"{'time':>18}: {report['timings'].get('total_s', 0):.2f} s")


def run_job(recipe: dict, force: bool, as_json: bool, threads=None, check_intersections=None, base=None,
            source=None, confine=None) -> dict:
    """Run a recipe built by a command; print warnings and the report.

    A :class:`RecipeError` is reported against the option of the running
    command that set the key (``--voxel: must be positive``).
    """
    from ..analysis.report import set_progress
    from ..first_run import precompile_in_background
    from ..jobs import get_job, run_recipe
    from .options import memory_limit, with_promise, with_settings
    recipe = with_settings(with_promise(recipe))
    precompile_in_background()
    progress = Progress()
    set_progress(progress.log)      # the report's stages (analysis, plots, page) as progress lines
    try:
        report = run_recipe(recipe, force=force, progress=progress, threads=threads,
                            check_intersections=check_intersections, memory_limit=memory_limit(), base=base,
                            source=source, confine=confine)
    except RecipeError as exc:
        raise as_flag_error(exc, given_only=source is not None) from None
    finally:
        set_progress(None)
        progress.close()
    warn(report)
    emit(report, as_json, get_job(report["job"]).summary)
    return report


def as_flag_error(exc: RecipeError, given_only: bool = False):
    """The error with the recipe key replaced by the current command's option for it (if any).

    ``given_only``: by an option that was given only (a recipe file's own key keeps its name).
    """
    from .options import flag_for
    ctx = click.get_current_context(silent=True)
    flag = flag_for(ctx.command, exc.key, ctx.params) if ctx is not None else None
    if flag is None or given_only and not any(flag in p.opts and ctx.params.get(p.name) is not None
                                              for p in ctx.command.params):
        return exc
    return RecipeError(flag, exc.detail)
