"""Typed errors.

Every error a user can cause derives from :class:`PorecadError`. The CLI maps
these to a one-line message and a non-zero exit code; anything else is a bug
and prints one line too (``internal error: <Type>: <message>``, exit status 70).
"""


class PorecadError(Exception):
    """Base class of all user-facing porecad errors."""

    exit_code = 2


class InputError(PorecadError, ValueError):
    """A parameter or input file is invalid (unknown type, bad value, garbage file)."""


class RecipeError(InputError):
    """A recipe value is invalid; ``key`` is its dotted recipe path (e.g. ``"tis.relative"``).

    The message reads ``"<key>: <detail>"``; the command line shows the
    option that set the key instead (``"--relative-threshold: <detail>"``).
    """

    def __init__(self, key: str, detail: str):
        self.key = str(key)
        self.detail = str(detail)
        super().__init__(f"{self.key}: {self.detail}")


class RangeError(InputError):
    """A threshold or porosity lies outside the valid range of a type and structure."""


class ResourceError(PorecadError):
    """A job would exceed the machine's memory or a size limit; refused up front."""

    exit_code = 3


class OutputError(PorecadError):
    """An output cannot be written (exists without ``--force``, unwritable directory)."""


class MeshError(PorecadError):
    """A mesh failed validation (not closed, not manifold, mis-oriented)."""

    exit_code = 4


class PromiseError(PorecadError):
    """A solid that is not the part asked for (a ``strict`` job's warning of the promise check, or a body's
    filling in separate parts of comparable size); nothing written."""

    exit_code = 6


def one_line(text: object) -> str:
    """``text`` on one line (runs of whitespace, newlines included, become one space)."""
    return " ".join(str(text).split())
