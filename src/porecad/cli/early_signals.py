"""Ctrl-C or SIGTERM while the ``porecad`` program is still loading: end at once with the usual line.

Nothing can have been written yet, so the process just exits (130 / 143);
without this a signal during an import prints a traceback from its middle.
:func:`porecad.cli.main._invoke` hands SIGINT back to Python once loaded.
"""

import os
import signal


def install() -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, stop_while_loading)


def stop_while_loading(signum, frame):
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    os.write(2, f"porecad: {word}; nothing written\n".encode())
    os._exit(130 if signum == signal.SIGINT else 143)
