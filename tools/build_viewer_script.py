"""Build ``src/porecad/vendor/three.classic.js``: three.js as one classic script defining ``window.THREE``.

Run ``python tools/build_viewer_script.py`` after updating the three.js sources in ``tools/three-src``
(three.js from the npm registry, MIT; see its README.txt); ``tests/docs/test_layout_docs.py`` checks that
the vendored file is this script's output.

Why a classic script: the scaffold report must open offline from a file by double click, and
browsers refuse ES modules from ``file://`` pages. Each module's body goes in its own function scope,
its ``import {…} from`` line becomes a destructuring of the modules before it, its ``export {…}``
list the object it returns. The report inlines the file; the studio loads it before its page script.
Both read it from ``porecad/vendor`` — neither reads the other's folders.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ROOT / "tools" / "three-src"
TARGET = ROOT / "src" / "porecad" / "vendor" / "three.classic.js"
#: module files in dependency order, with the names they are known by in import lines
MODULES = (("three.core.js", "./three.core.js"), ("three.module.js", "./three.module.js"),
           ("OrbitControls.js", None))

_IMPORT = re.compile(r"^import\s*\{([^}]*)\}\s*from\s*'([^']+)';\s*$", re.M)
_EXPORT = re.compile(r"^export\s*\{([^}]*)\}(\s*from\s*'([^']+)')?;\s*$", re.M)


def _names(listing: str):
    """``[(local, exported)]`` of an import/export list (``a as b`` → ``(a, b)``)."""
    out = []
    for item in listing.split(","):
        item = item.strip()
        if item:
            a, _, b = item.partition(" as ")
            out.append((a.strip(), (b or a).strip()))
    return out


def classic_script(sources: Path = SOURCES) -> str:
    """three.js (core, renderer, OrbitControls) joined into one classic script defining ``window.THREE``."""
    parts = ["// three.js (MIT, see tools/three-src/LICENSE) joined by tools/build_viewer_script.py: do not edit",
             "(function(){\"use strict\";const __m={};"]
    for name, known_as in MODULES:
        src = (sources / name).read_text(encoding="utf-8")
        head = []
        for m in _IMPORT.finditer(src):
            head.append("const {" + ",".join(f"{b}:{a}" for a, b in _names(m.group(1)))
                        + f"}}=__m[{json.dumps(m.group(2))}];")
        exports = []
        for m in _EXPORT.finditer(src):
            if m.group(3):  # a re-export of another module's names
                exports += [f"{b}:__m[{json.dumps(m.group(3))}].{a}" for a, b in _names(m.group(1))]
            else:
                exports += [f"{b}:{a}" for a, b in _names(m.group(1))]
        body = _EXPORT.sub("", _IMPORT.sub("", src))
        if re.search(r"^(import|export)\s", body, re.M):
            raise RuntimeError(f"{name}: an import or export the classic-script join does not handle")
        key = json.dumps(known_as or name)
        parts.append(f"__m[{key}]=(function(){{\"use strict\";{''.join(head)}\n{body}\n"
                     f"return {{{','.join(exports)}}};}})();")
    parts.append("window.THREE=Object.assign({},__m[\"./three.core.js\"],__m[\"./three.module.js\"],"
                 "__m[\"OrbitControls.js\"]);})();\n")
    return "\n".join(parts)


if __name__ == "__main__":
    TARGET.write_text(classic_script(), encoding="utf-8")
    print(f"wrote {TARGET.relative_to(ROOT)} ({TARGET.stat().st_size:,} bytes)", file=sys.stderr)
