"""The ``porecad`` command line: a thin layer that builds a recipe and runs it through the job registry.

Commands only import the library (never the other way round); each command
module holds the options of one job and the function that turns them into a
recipe.
"""

import os
import signal

__all__ = ["cli", "main"]


def main(argv=None):
    """The ``porecad`` program (see :func:`porecad.cli.main.main`).

    Ctrl-C or SIGTERM while the program is still loading (nothing can have
    been written yet) ends it at once with the usual line instead of a
    traceback from the middle of an import.
    """
    if argv is None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _stop_while_loading)
    from .main import main as run
    return run(argv)


def _stop_while_loading(signum, frame):
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    os.write(2, f"porecad: {word}; nothing written\n".encode())
    os._exit(130 if signum == signal.SIGINT else 143)


def __getattr__(name):
    if name == "cli":
        from .main import cli
        return cli
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
