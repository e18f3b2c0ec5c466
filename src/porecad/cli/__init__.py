"""The ``porecad`` command line: a thin layer that builds a recipe and runs it through the job registry.

Commands only import the library (never the other way round); each command
module holds the options of one job and the function that turns them into a
recipe.
"""

__all__ = ["cli", "main"]


def main(argv=None):
    """The ``porecad`` program (:func:`porecad.cli.main.main`), its signal handlers set before it loads."""
    if argv is None:
        from .early_signals import install
        install()
    from .main import main as run
    return run(argv)


def __getattr__(name):
    if name == "cli":
        from .main import cli
        return cli
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
