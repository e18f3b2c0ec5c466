"""One recipe key's declaration (:class:`Key`) and the :data:`REQUIRED` default (see :mod:`porecad.recipes.schema`)."""

from __future__ import annotations

import dataclasses
from typing import Any

KINDS = ("int", "number", "bool", "string", "choice", "path", "output", "numbers", "integers", "table",
         "tables", "any")


class _Required:
    """The default of a key that must be given."""

    def __repr__(self):
        return "REQUIRED"


#: the default of a required key
REQUIRED = _Required()


@dataclasses.dataclass(frozen=True)
class Key:
    """One recipe key, declared.

    ``kind`` is one of :data:`KINDS`; ``default`` its value when absent
    (:data:`REQUIRED`: it must be given; None: optional, no value). Numbers
    take ``lo``/``hi`` (with ``open_lo``/``open_hi``), ``positive`` or
    ``nonneg``; lists ``length`` (a count or allowed counts), ``min_len``
    and ``max_len``; strings ``max_len``; choices ``choices`` (``fold_case``:
    any letter case). ``keys`` is the sub-table of a ``table`` (or the item
    of ``tables``; for ``numbers`` the table it may be instead). ``json`` is
    the JSON type of a key of kind ``any`` (checked by the job's own
    function). ``what`` names the value in errors (default: the key in
    words); ``excludes`` the keys of the same table it may not be given with;
    ``one_of``: exactly one of this key and those it ``excludes`` must be
    given (:meth:`porecad.recipes.table.Table.one_of`; a job may waive it,
    as the tpms jobs do for a ``[grading]``); ``scalar``: one value stands
    for all of a list; ``when``: the condition
    under which a :data:`REQUIRED` key is required (empty: always).
    ``local_only``: the key names something of the machine that runs the
    job (a path, a scheduler, worker processes, a store; every ``path`` and
    ``output`` key is): the studio neither shows nor accepts it, and a worker
    count read from a recipe file is at most the machine's cores
    (``docs/security.md``).
    """

    kind: str
    default: Any = None
    help: str = ""
    units: str = ""
    lo: float | None = None
    hi: float | None = None
    open_lo: bool = False
    open_hi: bool = False
    positive: bool = False
    nonneg: bool = False
    choices: tuple = ()
    fold_case: bool = False
    length: int | tuple | None = None
    min_len: int = 1
    max_len: int | None = None
    must_exist: bool = True
    what: str | None = None
    excludes: tuple = ()
    one_of: bool = False
    keys: dict | None = None
    json: str | None = None
    scalar: bool = False
    when: str = ""
    local_only: bool = False

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown key kind {self.kind!r}")
        if self.kind in ("path", "output"):
            object.__setattr__(self, "local_only", True)
