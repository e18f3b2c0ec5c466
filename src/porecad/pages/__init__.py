"""HTML pages from Jinja2 templates: the scaffold report, the mechanics-and-flow page, the IVD index.

One environment with autoescape on (every value from a report, a file name or an error is escaped
unless a template marks it safe), one stylesheet (``templates/style.css``) that every page embeds, and
filters for the numbers a page shows (``num``: significant digits, a dash for a missing value).
Pages are self-contained: nothing is fetched when they are opened.

>>> from porecad.pages import render
>>> page = render("ivd.html", title="t", report={"subject": "<b>", "segmenter": "classical", "methods": [],
...                                             "discs": []}, rows=[], metrics=None)
>>> "&lt;b&gt;" in page and "<b>" not in page
True
"""

from __future__ import annotations

import functools

__all__ = ["render", "num"]


def num(x, digits: int = 4) -> str:
    """``x`` to ``digits`` significant digits; an en dash for ``None``; below 1e-9 in size, 0 (rounding
    noise such as ``1e-12`` is not shown as a value); large values with thousands separators, not
    in exponent form."""
    if x is None:
        return "–"
    x = float(x)
    if abs(x) < 1e-9:
        return "0"
    if 10 ** digits <= abs(x) < 1e12:      # 55,770 rather than 5.577e+04
        return f"{float(f'{x:.{digits}g}'):,.0f}"
    return f"{x:.{digits}g}"


@functools.lru_cache(maxsize=1)
def _environment():
    import jinja2
    env = jinja2.Environment(loader=jinja2.PackageLoader("porecad.pages", "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    env.filters["num"] = num
    return env


def render(template: str, **context) -> str:
    """The page ``template`` (a file of ``porecad/pages/templates``) filled with ``context``."""
    return _environment().get_template(template).render(**context)
