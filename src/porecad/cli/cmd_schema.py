"""``porecad schema [JOB]``: the JSON Schema of a job's recipe (:mod:`porecad.recipes.schema`)."""

from __future__ import annotations

import json

import click


@click.command()
@click.argument("job", required=False)
def schema(job):
    """Print the JSON Schema (draft 2020-12) of JOB's recipe, or of every job's.

    Every recipe key with its type, default, range, units and meaning: the
    one declaration that the job's checks, the command options, the studio's
    form and docs/recipes.md all derive from.

    \b
    Examples:
      porecad schema tis
      porecad schema > recipes.schema.json
    """
    from ..recipes.schema import job_names, json_schema
    if job is not None and job not in job_names():
        raise click.ClickException(f"unknown job {job!r}; use one of {', '.join(job_names())}")
    click.echo(json.dumps(json_schema(job), indent=2, ensure_ascii=False))
