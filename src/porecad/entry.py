"""The ``porecad`` program's entry point (``porecad`` and ``python -m porecad``).

Ctrl-C or SIGTERM while the program is still loading (nothing can have been
written yet) ends it at once with the usual line, instead of a traceback
from the middle of an import: the handlers are set here, before the CLI
and numpy load (``porecad/__init__`` loads its names on first use), and
:func:`porecad.cli.main.main` replaces them once loaded.
"""

import os
import signal


def main():
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop_while_loading)
    from .cli.main import main as run
    return run()


def _stop_while_loading(signum, frame):
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    os.write(2, f"porecad: {word}; nothing written\n".encode())
    os._exit(130 if signum == signal.SIGINT else 143)
