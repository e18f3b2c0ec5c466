"""Options shared by the commands, and the map from recipe keys to the options that set them.

A command declares an option that sets a recipe key with :func:`keyed`; when
the job refuses that key (:class:`~porecad.errors.RecipeError`), the error
names the option the user typed (``--relative-threshold: must lie in [0, 1]``)
instead of the recipe key. This is the one place where keys meet flags.
"""

from __future__ import annotations

import click

from ..errors import RecipeError
from ..io.mesh_formats import mesh_suffixes


class KeyedOption(click.Option):
    """A click option that sets the recipe key ``recipe_key`` (of ``job``: its declaration gives the rest).

    With ``job``, the option's default, help and shown range come from the
    key's declaration (:func:`porecad.recipes.schema.declared`), never from
    the command: a command may not restate a declared default (a TypeError
    when the command module loads), only pass ``default=None`` where the job
    picks the value itself when the option is not given.
    """

    def __init__(self, *args, recipe_key: str | tuple = (), job: str | None = None, **kwargs):
        from ..recipes.schema import declared, default_of
        keys = (recipe_key,) if isinstance(recipe_key, str) else tuple(recipe_key)
        self.declared = declared(job, keys[0]) if job and keys else None
        if self.declared is not None:
            default = default_of(job, keys[0])
            if kwargs.get("default") is not None and not kwargs.get("is_flag"):
                raise TypeError(f"{job} {keys[0]}: its default is declared in porecad.recipes.keys; "
                                f"the option may not restate it")
            if "default" not in kwargs and default is not None and not kwargs.get("is_flag"):
                if kwargs.get("multiple") and not isinstance(default, (list, tuple)):
                    default = [default]  # one value stands for all (a cell size for x, y and z)
                kwargs.update(default=list(default) if isinstance(default, tuple) else default, show_default=True)
            units = f" ({self.declared.units})" if self.declared.units and self.declared.units != "mm" else ""
            kwargs.setdefault("help", self.declared.help + units)
            if self.declared.choices and "type" not in kwargs and not kwargs.get("is_flag"):
                kwargs["type"] = click.Choice(self.declared.choices, case_sensitive=not self.declared.fold_case)
        super().__init__(*args, **kwargs)
        self.recipe_keys = keys

    def get_help_extra(self, ctx):
        """click's extras, with the declared range where the option's type shows none."""
        from ..recipes.schema import range_text
        extra = super().get_help_extra(ctx)
        if self.declared is not None and "range" not in extra and not self.declared.choices:
            text = range_text(self.declared)
            if text:
                extra["range"] = f"range: {text}"
        return extra


class FiniteRange(click.ParamType):
    """A finite float within ``[lo, hi]`` (``open_lo``: ``lo`` itself excluded); nan and inf are refused.

    For the options that set no recipe key (``phantom``, ``seg``); options
    that set recipe keys are checked by the job's spec.
    """

    name = "float"

    def __init__(self, lo: float, hi: float, open_lo: bool = False):
        self.lo, self.hi, self.open_lo = float(lo), float(hi), open_lo

    def convert(self, value, param, ctx):
        import math
        try:
            x = float(value)
        except (TypeError, ValueError, OverflowError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(x):
            self.fail(f"must be a finite number, got {value}", param, ctx)
        if x < self.lo or x > self.hi or (self.open_lo and x == self.lo):
            self.fail(f"must lie in {'(' if self.open_lo else '['}{self.lo:g}, {self.hi:g}], got {x:g}", param, ctx)
        return x


def keyed(key, *param_decls, **attrs):
    """``click.option(*param_decls, **attrs)`` that also records that it sets recipe ``key`` (or keys)."""
    return click.option(*param_decls, cls=KeyedOption, recipe_key=key, **attrs)


def keyed_in(job: str):
    """:func:`keyed` for the options of ``job``'s command: their defaults, help and ranges are the declared ones."""
    def option(key, *param_decls, **attrs):
        return keyed(key, *param_decls, job=job, **attrs)
    return option


def flag_for(command: click.Command, key: str, given: dict | None = None) -> str | None:
    """The option of ``command`` that sets recipe ``key`` or a table holding it (its longest name), or None.

    Where several options may set the key (``--threshold`` and ``--porosity``
    both give ``grading.expr``), the one given (a value in ``given``, the
    command's parameters) is named.
    """
    import re
    parts = re.split(r"(?=[.\[])", key)
    for n in range(len(parts), 0, -1):
        k = "".join(parts[:n])
        found = [p for p in command.params if isinstance(p, KeyedOption) and k in p.recipe_keys]
        if found:
            used = [p for p in found if given and given.get(p.name) is not None]
            return max((used or found)[0].opts, key=len)
    # a bare parameter name (a library function's): the option of that name, or that sets a key ending in it
    found = [p for p in command.params if isinstance(p, click.Option) and (p.name == key or any(
        k.rsplit(".", 1)[-1] == key for k in getattr(p, "recipe_keys", ())))]
    return max(found[0].opts, key=len) if found else None


def with_flags(text: str, command: click.Command, given: dict | None = None) -> str:
    """``text`` with each parameter a library message names in backquotes (`resolution`) as ``command``'s option.

    Library errors name parameters and recipe keys, never flags (issue 38);
    on the command line they read as the options that set them. A name the
    command has no option for keeps its quotes.
    """
    import re

    def setting(m):  # a recipe setting the library suggests: (units = "m") -> (--units m)
        flag = flag_for(command, m.group(1), given)
        return f"({flag} {m.group(2)})" if flag else m.group(0)

    text = re.sub(r'\((\w+) = "(\w+)"\)', setting, text)
    return re.sub(r"`([A-Za-z_][\w.\[\]]*)`", lambda m: flag_for(command, m.group(1), given) or m.group(0), text)


def apply(fn, options):
    """Apply a list of option decorators to ``fn`` (in the listed order, top first)."""
    for opt in reversed(options):
        fn = opt(fn)
    return fn


def _promise_key(key):
    """A callback that keeps a given ``--strict`` / ``--islands`` for :func:`with_promise`."""
    def store(ctx, param, value):
        if value is not None and value is not False:
            ctx.meta.setdefault("porecad.promise", {})[key] = value
    return store


def with_promise(recipe: dict) -> dict:
    """The recipe with the running command's ``--strict`` / ``--islands`` as its ``strict`` / ``islands`` keys."""
    ctx = click.get_current_context(silent=True)
    given = ctx.meta.get("porecad.promise") if ctx is not None else None
    return {**recipe, **given} if given else recipe


def _keep_settings(ctx, param, value):
    """A callback that keeps the ``--set`` values for :func:`with_settings`."""
    if value:
        ctx.meta["porecad.set"] = tuple(value)


#: ``--set KEY=VALUE``: any key of the job's recipe, checked by its declaration (``porecad schema JOB``)
set_option = click.option("--set", "settings", metavar="KEY=VALUE", multiple=True, expose_value=False,
                          callback=_keep_settings,
                          help="Set any key of the job's recipe, e.g. --set mesh.smooth=3 (applied last; the keys, "
                               "their types and ranges: `porecad schema JOB`).")


def _literal(text: str):
    """A ``--set`` value: a TOML value (``3``, ``0.5``, ``true``, ``[1, 2]``, ``"x"``), else the text itself."""
    import tomllib
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except (tomllib.TOMLDecodeError, KeyError):
        return text


def with_settings(recipe: dict) -> dict:
    """The recipe with the running command's ``--set KEY=VALUE`` values, each checked by its key's declaration.

    A key the job's schema does not declare, or a value its declaration
    refuses, is a :class:`RecipeError` naming ``--set KEY``.
    """
    ctx = click.get_current_context(silent=True)
    given = ctx.meta.get("porecad.set") if ctx is not None else None
    if not given:
        return recipe
    import copy

    from ..recipes.table import Table
    from ..recipes.schema import job_keys
    recipe = copy.deepcopy(recipe)
    job = recipe.get("job")
    for item in given:
        dotted, sep, text = item.partition("=")
        dotted = dotted.strip()
        *tables, k = dotted.split(".")
        keys = job_keys(job)
        for t in tables:
            keys = keys[t].keys if keys is not None and t in keys and keys[t].kind == "table" else None
        if not sep or keys is None or k not in keys or keys[k].kind in ("table", "tables"):
            raise RecipeError("--set", f"takes KEY=VALUE with a key of job {job}'s recipe (`porecad schema {job}`), "
                                       f"got {item[:80]!r}")
        value = _literal(text.strip())
        try:
            Table({k: value}, ".".join(tables), schema=keys).get(k)
        except RecipeError as exc:
            raise RecipeError(f"--set {dotted}", exc.detail) from None
        node = recipe
        for t in tables:
            node = node.setdefault(t, {})
        node[k] = value
    return recipe


def output_options(extra=()):
    """``-o/--out``, ``--report``, ``--recipe``, ``--force``, ``--json``, ``--strict``, ``--islands``, ``--set``
    (every build command; the last three reach the recipe through :func:`with_promise` and :func:`with_settings`)."""
    def deco(fn):
        opts = [
            keyed("output.mesh", "-o", "--out", type=click.Path(dir_okay=False),
                  help=f"Output mesh ({mesh_suffixes('write', ' ')})."),
            *extra,
            keyed("output.report", "--report", type=click.Path(),
                  help="Report: a .json file, or a directory (report.json, report.html, plots: full analysis)."),
            keyed("output.recipe", "--recipe", "recipe_out", type=click.Path(dir_okay=False),
                  help="Also write the recipe (TOML) that regenerates these outputs with `porecad build`."),
            click.option("--force", is_flag=True, help="Overwrite existing outputs."),
            click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object."),
            strict_option,
            islands_option,
            set_option,
            max_memory_option,
        ]
        return apply(fn, opts)
    return deco


#: ``--strict``: any warning of the promise check (or the job) refuses the job; nothing is written
strict_option = keyed("strict", "--strict", is_flag=True, default=None, expose_value=False,
                      callback=_promise_key("strict"),
                      help="Refuse (write nothing) when the solid is not the part asked for: any warning "
                           "(islands, porosity-off, coverage-low, extent-short, ...).")
#: ``--islands drop|keep``: loose pieces of the solid besides the largest
islands_option = keyed("islands", "--islands", type=click.Choice(["drop", "keep"]), expose_value=False,
                       callback=_promise_key("islands"),
                       help="Pieces of the solid not attached to the largest one: drop them (the default) or "
                            "keep them (with the islands warning).")


def _keep_memory_limit(ctx, param, value):
    """A callback that keeps ``--max-memory`` (bytes) for :func:`memory_limit`."""
    if value is None:
        return None
    from ..errors import InputError
    from ..resources import parse_size
    try:
        ctx.meta["porecad.memory_limit"] = parse_size(value)
    except InputError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None
    return ctx.meta["porecad.memory_limit"]


#: ``--max-memory SIZE``: the memory a job may use (its up-front estimate is refused past it)
max_memory_option = click.option(
    "--max-memory", "memory_limit", metavar="SIZE", expose_value=False, callback=_keep_memory_limit,
    help="Memory the job may use, e.g. 4GB (default: 80 % of the available memory); a job estimated "
         "larger is refused before any work.")


def memory_limit() -> int | None:
    """The running command's ``--max-memory`` in bytes, or None."""
    ctx = click.get_current_context(silent=True)
    return ctx.meta.get("porecad.memory_limit") if ctx is not None else None


def threads_option(fn):
    """``--threads N``."""
    return click.option("--threads", type=click.IntRange(1, 1024), help="Worker threads (default: all cores).")(fn)


def check_intersections_option(fn):
    """``--check-intersections``."""
    return click.option("--check-intersections", is_flag=True, default=None,
                        help="Also test the solid for self-intersections before writing.")(fn)


def scale_options(fn):
    """The scale-out options of the lattice commands (``docs/scale-out.md``)."""
    return apply(fn, [
        keyed("scale.scheduler", "--scheduler",
              help="Where chunks run: threads (default), local:N (N worker processes) or "
                   "tcp://HOST:PORT (an existing dask cluster: dask exchanges pickles with it, so name only "
                   "one you trust; a recipe file cannot); dask needs porecad[dask]."),
        keyed("scale.stream", "--stream/--no-stream", default=None,
              help=f"Stream the mesh to the {mesh_suffixes('stream', '/')} file chunk by chunk (memory bounded by the "
                   "chunks, not the mesh); default: when the mesh would not fit in memory."),
        keyed("scale.zarr", "--zarr", "zarr_path", type=click.Path(),
              help="Also store the sampled field (float32, chunked by slab) in this zarr directory."),
        keyed("scale.retries", "--retries", type=int, help="Attempts after a chunk fails (default 2)."),
        keyed("scale.chunk_mb", "--chunk-mb", type=float, help="Samples per chunk in MiB (default 16)."),
        keyed("scale.max_output", "--max-output", metavar="SIZE",
              help="Refuse before any work a mesh estimated larger than SIZE (e.g. 2GB); an output over "
                   "1 GB or 10 M triangles is announced with its estimated size and time."),
    ])


def with_scale(recipe: dict, scheduler=None, stream=None, zarr_path=None, retries=None, chunk_mb=None,
               max_output=None) -> dict:
    """The recipe with the given scale-out options merged into its ``[scale]`` table."""
    given = given_only({"scheduler": scheduler, "stream": stream, "zarr": zarr_path, "retries": retries,
                        "chunk_mb": chunk_mb, "max_output": max_output})
    if given:
        recipe = dict(recipe)
        recipe["scale"] = {**dict(recipe.get("scale") or {}), **given}
    return recipe


def given_only(table: dict) -> dict:
    """The entries of a table whose value was given (not None)."""
    return {k: v for k, v in table.items() if v is not None}


def outputs(out=None, report=None, recipe_out=None, **extra) -> dict:
    """The ``[output]`` table of the given paths."""
    return given_only({"mesh": out, "report": report, "recipe": recipe_out, **extra})
