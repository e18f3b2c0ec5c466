"""The job registry: a job's name → its :class:`~porecad.jobs.contract.Job`.

The jobs are those whose recipe keys :data:`porecad.recipes.keys.JOBS`
declares; job ``<name>`` lives in ``porecad.jobs.<name>_job`` (``infill``
shares ``tpms_job``), imported on first use (a command that runs ``tis``
does not import the vessel code). So a new job is its module and its keys:
no line here.
"""

from __future__ import annotations

import importlib

from ..errors import RecipeError
from ..recipes.keys import JOBS

#: jobs whose module is another job's
SHARED = {"infill": "tpms"}


def names() -> list[str]:
    """The registered job names."""
    return list(JOBS)


def module_name(name: str) -> str:
    """The module that defines job ``name``."""
    return f"porecad.jobs.{SHARED.get(name, name)}_job"


def get(name: str):
    """The :class:`~porecad.jobs.contract.Job` called ``name`` (a :class:`RecipeError` naming ``job`` otherwise)."""
    if not isinstance(name, str) or name not in JOBS:
        raise RecipeError("job", f"unknown job {name!r}; use one of {', '.join(JOBS)}")
    module = importlib.import_module(module_name(name))
    jobs = getattr(module, "JOBS", None) or {module.JOB.name: module.JOB}
    return jobs[name]
