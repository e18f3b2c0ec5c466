"""Checked reading of recipe tables: every value typed and bounded, every error naming its key.

A job's spec is built from its recipe with a :class:`Table` per recipe
table. Each getter checks type and range and raises
:class:`~porecad.errors.RecipeError` with the dotted key (``"tis.relative"``),
which the command line turns into the option that set it. :meth:`Table.done`
refuses keys nobody read, so a misspelt key is an error naming it instead of
being silently ignored.

The job specs read every key with :meth:`Table.get`, which takes its kind,
bounds and default from the key's declaration in
:mod:`porecad.recipes.keys` (the table's ``schema``); reading a key that
is not declared there is a programming error (a LookupError), and
:meth:`Table.done` refuses keys the schema does not declare.

Integer counts always carry an upper bound: recipes come from other people,
and ``resolution = 2**62`` must be refused before any work starts.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

from ..errors import InputError, RecipeError

_MISSING = object()


class Table:
    """A recipe table (a dict) read through checked getters.

    Parameters
    ----------
    data : dict or None
        The table (None or missing: empty).
    name : str
        Its dotted recipe path (``""`` for the top level), used in errors.
    base : path, optional
        Directory that relative input paths are resolved against (the
        recipe file's directory); default the current directory.

    Examples
    --------
    >>> t = Table({"resolution": 20, "method": "lattice"}, "mesh")
    >>> t.integer("resolution", 17, lo=3, hi=4096)
    20
    >>> t.choice("method", ("lattice", "grid"), "lattice")
    'lattice'
    >>> t.done()
    """

    def __init__(self, data, name: str = "", base=None, loc: tuple = (), found: list | None = None,
                 confine=None, schema: dict | None = None):
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise RecipeError(name or "recipe", f"must be a table, got {type(data).__name__}")
        self.data = data
        self.name = name
        self.base = Path(base) if base is not None else None
        self.loc = loc
        self.read: set[str] = set()
        self.found = [] if found is None else found  # (location, resolved path) of every path read
        # (folder, paths typed on the command line): outputs of a recipe file stay inside its folder
        self.confine = confine
        # the declared keys of this table (name -> porecad.recipes.schema.Key); None: undeclared, explicit getters
        self.schema = schema

    def paths(self) -> list[tuple[tuple, str]]:
        """``(location, resolved path)`` of every path read through this table and its sub-tables."""
        return list(self.found)

    def _child(self, data, k, name):
        return Table(data, name, self.base, self.loc + (k,), self.found, self.confine, self._sub(k))

    def _sub(self, k):
        """The declared keys of sub-table ``k`` (None when this table has no schema)."""
        return None if self.schema is None else self.declared(k).keys or {}

    def declared(self, k: str):
        """The :class:`~porecad.recipes.schema.Key` declaring ``k`` (a LookupError if this table's schema lacks it)."""
        key = None if self.schema is None else self.schema.get(k)
        if key is None and self.schema is not None:
            raise LookupError(f"recipe key {self.key(k)!r} is read but not declared in porecad.recipes.keys")
        return key

    def get(self, k: str, default=_MISSING, *, check=None, **bounds):
        """The value of ``k`` checked as its declaration says (kind, bounds, default).

        ``default`` overrides the declared default where it depends on other
        values (the declaration's help says how); ``bounds`` override
        declared fields likewise (a bound set by another value). ``check``:
        the job's own check function for a key of kind ``any`` (or a type
        whose names live elsewhere, like the TPMS types).
        """
        from .key import REQUIRED
        key = self.declared(k)
        if key is None:
            raise LookupError(f"{self.name or 'the recipe'} has no schema to read {k!r} by; use a checked getter")
        if bounds:
            key = dataclasses.replace(key, **bounds)
        d = key.default if default is _MISSING else default
        d = _MISSING if d is REQUIRED else list(d) if isinstance(d, list) else d
        kind = key.kind
        if check is not None:
            return self.checked(k, check, d)
        if kind == "int" and key.local_only and self.confine is not None:  # workers of a recipe file: the cores
            from ..scale.schedulers import recipe_workers
            return self.checked(k, lambda v: recipe_workers(check_int(v, key.lo, key.hi, self.key(k))), d)
        if kind == "int":
            return self.integer(k, d, lo=key.lo, hi=key.hi)
        if kind == "number":
            return self.number(k, d, lo=key.lo, hi=key.hi, positive=key.positive, nonneg=key.nonneg,
                               open_lo=key.open_lo, open_hi=key.open_hi, what=key.what)
        if kind == "bool":
            return self.flag(k, d)
        if kind == "string":
            return self.string(k, d, max_len=key.max_len or 4096)
        if kind == "choice":
            return self.choice(k, key.choices, d, fold_case=key.fold_case)
        if kind == "path":
            return self.path(k, d, must_exist=key.must_exist)
        if kind == "output":
            return self.output(k)
        if kind == "numbers":
            return self.numbers(k, d, length=key.length, min_len=key.min_len, max_len=key.max_len or 64,
                                lo=key.lo, hi=key.hi, positive=key.positive, nonneg=key.nonneg)
        if kind == "integers":
            return self.integers(k, d, length=key.length, lo=key.lo, hi=key.hi, max_len=key.max_len or 64,
                                 what=key.what)
        if kind == "table":
            return self.table(k, required=d is _MISSING)
        if kind == "tables":
            return self.tables(k, max_len=key.max_len or 256)
        return self.raw(k, None if d is _MISSING else d)

    # ---- helpers ---------------------------------------------------------
    def key(self, k: str) -> str:
        """The dotted path of key ``k`` of this table."""
        if k.isdigit():
            return f"{self.name}[{k}]"
        return f"{self.name}.{k}" if self.name else k

    def error(self, k: str, detail: str) -> RecipeError:
        """A :class:`RecipeError` for key ``k`` (``detail`` a whole sentence)."""
        return RecipeError(self.key(k), detail)

    def bad(self, k: str, phrase: str, what: str | None = None) -> RecipeError:
        """A :class:`RecipeError` for key ``k`` saying ``"<what, default the key in words> <phrase>"``."""
        return RecipeError(self.key(k), f"{what or words(self.key(k))} {phrase}")

    def one_of(self, k: str, waived: bool = False, alternative: str = "") -> str | None:
        """Which of ``k`` and the keys it excludes is given (the one rule for them all).

        Two given is an error; none is one where ``k`` is declared ``one_of``
        and not ``waived`` (a job's ``alternative`` to them, like a ``[grading]``).
        """
        key = self.declared(k)
        group = (k, *key.excludes)
        given = [x for x in group if self.has(x)]
        if len(given) > 1 or (not given and key.one_of and not waived):
            rule = "exactly one" if key.one_of else "at most one"
            raise self.error(given[1] if given else k,
                             f"give {rule} of {' or '.join(f'`{x}`' for x in group)}{alternative}")
        return given[0] if given else None

    def has(self, k: str) -> bool:
        """Whether ``k`` is given (and not None)."""
        return self.data.get(k) is not None

    def raw(self, k: str, default=None):
        """The value of ``k`` unchecked (marks it read)."""
        self.declared(k)
        self.read.add(k)
        v = self.data.get(k)
        return default if v is None else v

    def _get(self, k, default):
        self.declared(k)
        self.read.add(k)
        v = self.data.get(k)
        if v is None:
            if default is _MISSING:
                raise self.bad(k, "is required")
            return None if default is None else default, True
        return v, False

    def checked(self, k: str, fn, default=_MISSING):
        """``fn(value)`` with any :class:`InputError` it raises reported against ``k``."""
        v, missing = self._get(k, default)
        if missing and v is None:
            return None
        try:
            return fn(v)
        except RecipeError:
            raise
        except InputError as exc:
            # "`shape` must be positive" reported against the key: "arbf.shape: must be positive"
            raise self.error(k, str(exc).removeprefix(f"`{k}` ")) from None

    # ---- scalars ---------------------------------------------------------
    def number(self, k: str, default=_MISSING, *, lo: float | None = None, hi: float | None = None,
               positive: bool = False, nonneg: bool = False, open_lo: bool = False, open_hi: bool = False,
               what: str | None = None):
        """A finite float, optionally within ``[lo, hi]`` (or open ends), positive or non-negative."""
        v, missing = self._get(k, default)
        if missing and v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            try:
                v = float(v) if isinstance(v, str) else None
            except ValueError:
                v = None
            if v is None:
                raise self.bad(k, f"must be a number, got {_show(self.data.get(k))}", what)
        try:
            x = float(v)
        except OverflowError:
            raise self.bad(k, f"is too large, got {_show(v)}", what) from None
        if not math.isfinite(x):
            raise self.bad(k, f"must be finite, got {_show(v)}", what)
        if positive and x <= 0:
            raise self.bad(k, f"must be positive, got {x:g}", what)
        if nonneg and x < 0:
            raise self.bad(k, f"must be ≥ 0, got {x:g}", what)
        below = lo is not None and (x < lo or (open_lo and x == lo))
        above = hi is not None and (x > hi or (open_hi and x == hi))
        if (below or above) and lo is not None and hi is not None:
            raise self.bad(k, f"must lie in {'(' if open_lo else '['}{lo:g}, {hi:g}{')' if open_hi else ']'}, "
                              f"got {x:g}", what)
        if below:
            raise self.bad(k, f"must be {'>' if open_lo else '≥'} {lo:g}, got {x:g}", what)
        if above:
            raise self.bad(k, f"must be {'<' if open_hi else '≤'} {hi:g}, got {x:g}", what)
        return x

    def integer(self, k: str, default=_MISSING, *, lo: int, hi: int):
        """An integer within ``[lo, hi]`` (both bounds required: counts are always bounded)."""
        v, missing = self._get(k, default)
        if missing and v is None:
            return None
        return check_int(v, lo, hi, self.key(k))

    def flag(self, k: str, default: bool = False) -> bool:
        """A boolean."""
        v, missing = self._get(k, default)
        if not isinstance(v, bool):
            raise self.bad(k, f"must be true or false, got {_show(v)}")
        return v

    def string(self, k: str, default=_MISSING, *, max_len: int = 4096):
        """A string of at most ``max_len`` characters."""
        v, missing = self._get(k, default)
        if missing and v is None:
            return None
        if not isinstance(v, str):
            raise self.bad(k, f"must be a string, got {_show(v)}")
        if len(v) > max_len:
            raise self.bad(k, f"is longer than {max_len} characters")
        return v

    def choice(self, k: str, choices, default=_MISSING, *, fold_case: bool = False):
        """One of ``choices`` (strings)."""
        v = self.string(k, default)
        if v is None:
            return None
        w = v.lower() if fold_case else v
        opts = [c.lower() for c in choices] if fold_case else list(choices)
        if w not in opts:
            raise self.bad(k, f"must be one of {', '.join(choices)}, got {_show(v)}")
        return list(choices)[opts.index(w)]

    def path(self, k: str, default=_MISSING, *, must_exist: bool = True):
        """An input path, resolved against the recipe's directory; must exist unless told otherwise."""
        from ..io.confine import check_name
        v = self.string(k, default)
        if v is None:
            return None
        check_name(v, self.key(k))  # no control character, before the name is used or shown
        p = Path(os.path.expanduser(v))
        if not p.is_absolute() and self.base is not None:
            # relative to the recipe's directory; recipes of format 1 may hold paths relative to where they ran
            p = self.base / p if (self.base / p).exists() or not p.exists() else p
        if must_exist and not p.exists():
            raise self.error(k, f"{v}: no such file")
        self.found.append((self.loc + (k,), str(p)))
        return str(p)

    def output(self, k: str):
        """An output path (None when not given).

        A recipe read from a file (``confine`` set) writes only inside its
        folder: :func:`~porecad.io.confine.confined_output` refuses absolute
        paths, ``~``, ``..`` and symlinks that leave it, naming the key. A
        recipe built from a command line writes where its user said.
        """
        from ..io.confine import check_name, confined_output
        v = self.string(k, None)
        if v is None:
            return None
        check_name(v, self.key(k))
        if self.confine is None or v in self.confine[1]:
            return self.path(k, None, must_exist=False)
        p = str(confined_output(v, self.confine[0], self.key(k)))
        self.found.append((self.loc + (k,), p))
        return p

    # ---- vectors ---------------------------------------------------------
    def numbers(self, k: str, default=_MISSING, *, length: int | tuple[int, ...] | None = None,
                min_len: int = 1, max_len: int = 64, lo=None, hi=None, positive=False, nonneg=False):
        """A list of finite floats (``length``: the count, or allowed counts)."""
        v, missing = self._get(k, default)
        if missing and v is None:
            return None
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v]
        if not isinstance(v, (list, tuple)):
            raise self.bad(k, f"must be a list of numbers, got {_show(v)}")
        allowed = (length,) if isinstance(length, int) else length
        if allowed is not None and len(v) not in allowed:
            raise self.bad(k, f"takes {' or '.join(map(str, allowed))} numbers, got {len(v)}")
        if not min_len <= len(v) <= max_len:
            raise self.bad(k, f"takes {min_len} to {max_len} numbers, got {len(v)}")
        sub = Table({str(i): x for i, x in enumerate(v)}, self.key(k))
        return [sub.number(str(i), lo=lo, hi=hi, positive=positive, nonneg=nonneg) for i in range(len(v))]

    def integers(self, k: str, default=_MISSING, *, length: int | None = None, lo: int, hi: int,
                 max_len: int = 64, what: str | None = None):
        """A list of bounded integers."""
        v, missing = self._get(k, default)
        if missing and v is None:
            return None
        if isinstance(v, int) and not isinstance(v, bool):
            v = [v]
        if not isinstance(v, (list, tuple)):
            raise self.bad(k, f"must be a list of integers, got {_show(v)}")
        if length is not None and len(v) != length:
            raise self.bad(k, f"takes {length} integers, got {len(v)}", what)
        if len(v) > max_len:
            raise self.bad(k, f"takes at most {max_len} integers, got {len(v)}", what)
        return [check_int(x, lo, hi, self.key(k), what) for x in v]

    # ---- nesting ---------------------------------------------------------
    def table(self, k: str, required: bool = False) -> "Table":
        """The sub-table ``k`` (empty if absent)."""
        sub = self._sub(k)
        self.read.add(k)
        v = self.data.get(k)
        if v is None and required:
            raise self.bad(k, "is required (a table)")
        if v is None:  # absent: nothing to rewrite
            return Table(None, self.key(k), self.base, self.loc + (k,), [], self.confine, sub)
        return self._child(v, k, self.key(k))

    def tables(self, k: str, max_len: int = 256) -> list["Table"]:
        """A list of tables (an array of tables in TOML)."""
        sub = self._sub(k)
        self.read.add(k)
        v = self.data.get(k) or []
        if not isinstance(v, (list, tuple)):
            raise self.bad(k, f"must be a list of tables, got {_show(v)}")
        if len(v) > max_len:
            raise self.bad(k, f"takes at most {max_len} entries, got {len(v)}")
        return [Table(x, f"{self.key(k)}[{i}]", self.base, self.loc + (k, i), self.found, self.confine, sub)
                for i, x in enumerate(v)]

    def done(self, *ignore: str) -> None:
        """Refuse keys of this table that nobody read, or that its schema does not declare (misspelt, unknown)."""
        undeclared = set() if self.schema is None else set(self.data) - set(self.schema)
        unknown = sorted((set(self.data) - self.read - set(ignore)) | undeclared)
        if unknown:
            known = sorted(self.read | set(ignore))
            raise RecipeError(self.key(str(unknown[0])),
                              f"unknown key {str(unknown[0])!r}" + (f" (known here: {', '.join(known)})" if known else ""))


def check_int(v, lo: int, hi: int, key: str, what: str | None = None) -> int:
    """``v`` as an int within ``[lo, hi]``, else a :class:`RecipeError` naming ``key``."""
    name = what or words(key)
    if isinstance(v, float) and math.isfinite(v) and v.is_integer():
        v = int(v)
    elif isinstance(v, str):
        try:
            v = int(v.strip())
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, int):
        raise RecipeError(key, f"{name} must be an integer, got {_show(v)}")
    if v < lo:
        need = "a positive integer" if lo == 1 else "≥ 0" if lo == 0 else f"an integer ≥ {lo}"
        raise RecipeError(key, f"{name} must be {need}, got {_show(v)}")
    if v > hi:
        raise RecipeError(key, f"{name} must be at most {hi:,}, got {_show(v)}")
    return int(v)


def words(key: str) -> str:
    """A recipe key in words: ``"tpms.cell_size"`` → ``"cell size"``, ``"tdf.edits[0].where"`` → ``"where"``."""
    last = key.replace("]", "").split(".")[-1].split("[")[0]
    return last.replace("_", " ")


def _show(v) -> str:
    """A short, one-line rendering of a user value for an error message."""
    s = repr(v)
    s = " ".join(s.split())
    return s if len(s) <= 60 else s[:57] + "..."
