"""The job registry: a job's name → its :class:`~porecad.jobs.contract.Job`.

Job modules are imported on first use (a command that runs ``tis`` does not
import the vessel code). A new job is one module with a ``JOB`` attribute and
one line here.
"""

from __future__ import annotations

import importlib

from ..errors import RecipeError

#: job name → module defining ``JOB``
MODULES = {
    "tpms": "porecad.jobs.tpms_job",
    "infill": "porecad.jobs.tpms_job",
    "tbss": "porecad.jobs.tbss_job",
    "hex": "porecad.jobs.hex_job",
    "tis": "porecad.jobs.tis_job",
    "arbf": "porecad.jobs.arbf_job",
    "vessel": "porecad.jobs.vessel_job",
    "ivd": "porecad.jobs.ivd_job",
}


def names() -> list[str]:
    """The registered job names."""
    return list(MODULES)


def get(name: str):
    """The :class:`~porecad.jobs.contract.Job` called ``name`` (a :class:`RecipeError` naming ``job`` otherwise)."""
    if not isinstance(name, str) or name not in MODULES:
        raise RecipeError("job", f"unknown job {name!r}; use one of {', '.join(MODULES)}")
    module = importlib.import_module(MODULES[name])
    jobs = getattr(module, "JOBS", None) or {module.JOB.name: module.JOB}
    return jobs[name]
