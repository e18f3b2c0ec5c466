"""The ``porecad`` command line: a thin layer that builds a recipe and runs it through the job registry.

Commands only import the library (never the other way round); each command
module holds the options of one job and the function that turns them into a
recipe.
"""

from .main import cli, main

__all__ = ["cli", "main"]
