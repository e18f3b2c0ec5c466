"""Format-1 entry points kept for scripts: :func:`run_recipe` now lives in :mod:`porecad.jobs`."""

from .jobs import run_recipe
from .jobs.tpms_job import demo_recipe, plan_tpms

__all__ = ["run_recipe", "plan_tpms", "demo_recipe"]
