"""Collect and run the documented examples (issue 42): every fenced ``bash``/``sh``/``python`` block of
README.md and docs/*.md.

A block may be preceded by markers (HTML comments, on the lines just above its fence):

``<!-- example: skip (REASON) -->``
    not run; the reason is required (a download, a server that runs until stopped, a job of minutes).
``<!-- example: ci-form -->``
    the block is the reduced form of the long one above it, which the tests run instead (shown on the page).
``<!-- example: file NAME -->``
    the block (any language) is a file the later examples read: it is written to NAME.
``<!-- example: expect KEY VALUE TOL -->``
    a figure the text quotes: ``KEY`` (dotted) of the last JSON object the block prints (``print``: the
    last number a Python block prints) must be ``VALUE`` within ``TOL``.

Shell blocks are run line by line (``\\`` continues a line, ``#`` starts a comment, ``&&`` chains):
``porecad ARGS`` runs the command line in this process (:func:`porecad.cli.main`, as the CLI tests do;
``PORECAD_EXAMPLES_SUBPROCESS=1`` runs ``python -m porecad`` instead), ``python -c CODE`` runs CODE.
Anything else must be marked ``skip`` with its reason. Python blocks run in this process too.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LANGS = {"bash", "sh", "python"}
MARK = re.compile(r"<!--\s*example:\s*(skip|ci-form|file|expect)\b\s*(.*?)\s*-->")
FENCE = re.compile(r"^```(\S*)\s*$")


@dataclass
class Block:
    page: str
    line: int
    lang: str
    text: str
    skip: str | None = None
    ci_form: bool = False
    file: str | None = None
    expect: list = field(default_factory=list)

    @property
    def where(self):
        return f"{self.page}:{self.line}"


def pages() -> list[Path]:
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


def blocks(path: Path) -> list[Block]:
    """The collected blocks of one page, in order (file blocks of any language included)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    out, marks, i = [], [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            found = MARK.findall(lines[i])
            if found:
                marks += found
            elif lines[i].strip():
                marks = []
            i += 1
            continue
        j = i + 1
        while j < len(lines) and lines[j].rstrip() != "```":
            j += 1
        b = Block(path.name if path.parent == ROOT else f"docs/{path.name}", i + 1, m.group(1),
                  "\n".join(lines[i + 1:j]) + "\n")
        for kind, arg in marks:
            if kind == "skip":
                if not re.fullmatch(r"\(.{8,}\)", arg):
                    raise ValueError(f"{b.where}: a skip marker needs a reason in parentheses")
                b.skip = arg[1:-1]
            elif kind == "ci-form":
                b.ci_form = True
            elif kind == "file":
                b.file = arg
            else:
                key, value, tol = arg.split()
                b.expect.append((key, float(value), float(tol)))
        if b.lang in LANGS or b.file:
            out.append(b)
        marks, i = [], j + 1
    return out


# ------------------------------------------------------------------------------------------ running


def commands(text: str) -> list[list[str]]:
    """The shell lines of a block as argument lists (continuations joined, comments dropped, && split)."""
    text = text.replace("\\\n", " ")
    out = []
    for line in text.splitlines():
        argv = shlex.split(line, comments=True)
        while argv:
            cut = argv.index("&&") if "&&" in argv else len(argv)
            out.append(argv[:cut])
            argv = argv[cut + 1:]
    return out


class ExampleFailed(AssertionError):
    pass


def _porecad(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    if os.environ.get("PORECAD_EXAMPLES_SUBPROCESS") == "1":
        env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
        p = subprocess.run([sys.executable, "-m", "porecad", *argv], cwd=cwd, env=env,
                           capture_output=True, text=True)
        return p.returncode, p.stdout, p.stderr
    from porecad.cli.main import main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def _python(code: str, where: str) -> tuple[int, str, str]:
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, where, "exec"), {"__name__": "__main__"})  # noqa: S102 - our own documentation
    except Exception as e:  # the example failed: say where and how
        return 1, out.getvalue(), f"{type(e).__name__}: {e}"
    return 0, out.getvalue(), ""


def run_block(b: Block, cwd: Path, femur_figures: bool = True) -> str:
    """Run one block in ``cwd``; return what it printed. Raises ExampleFailed."""
    if b.file:
        (cwd / b.file).write_text(b.text, encoding="utf-8")
        return ""
    printed = []
    if b.lang == "python":
        runs = [("python", b.text)]
    else:
        runs = []
        for argv in commands(b.text):
            if argv[0] == "porecad":
                runs.append(("porecad", argv[1:]))
            elif argv[0] in ("python", "python3") and len(argv) == 3 and argv[1] == "-c":
                runs.append(("python", argv[2]))
            else:
                raise ExampleFailed(f"{b.where}: cannot run {shlex.join(argv)!r} in the tests: "
                                    "mark the block <!-- example: skip (reason) -->")
    for kind, what in runs:
        try:
            if kind == "python":
                code, out, err = _python(what, b.where)
            else:
                code, out, err = _porecad(what, cwd)
        except SystemExit as e:
            code, out, err = e.code, "", ""
        shown = shlex.join(["porecad", *what]) if kind == "porecad" else what.strip().splitlines()[0]
        if code != 0:
            raise ExampleFailed(f"{b.where}: `{shown}` exited {code}: {err.strip()[-2000:]}")
        printed.append(out)
    if femur_figures or "shared/data/femur.stl" not in b.text:
        _check_expect(b, printed)
    return "".join(printed)


def _last_json(printed):
    for out in reversed(printed):
        s = out.strip()
        if s.startswith("{"):
            return json.loads(s)
    return None


def _check_expect(b: Block, printed):
    for key, value, tol in b.expect:
        if key == "print":
            nums = re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", "".join(printed))
            if not nums:
                raise ExampleFailed(f"{b.where}: expected a printed number near {value}")
            got = float(nums[-1])
        else:
            got = _last_json(printed)
            if got is None:
                raise ExampleFailed(f"{b.where}: expect {key}: the block printed no JSON report")
            for part in key.split("."):
                got = got[int(part)] if isinstance(got, list) else got[part]
            got = float(got)
        if abs(got - value) > tol:
            raise ExampleFailed(f"{b.where}: the text quotes {key} = {value} (±{tol}); the command gives {got}")


# ------------------------------------------------------------------ one test per example (issue 53)

SHARED = "../shared/"  # the prepared inputs (:func:`prepare`), not written by any example
_OUT_OPTIONS = re.compile(r"^(-o|--out(put)?|--recipe|--report|--save-[\w-]+|--zarr)$")
_SUFFIX = re.compile(r"\.[A-Za-z][A-Za-z0-9]*$")
_STRING = re.compile(r"""(?<![A-Za-z0-9_])(?:"([^"\n]*)"|'([^'\n]*)')""")


def _pathlike(tok: str) -> bool:
    return (bool(tok) and not tok.startswith("-") and not tok.startswith(SHARED) and not any(c.isspace() for c in tok)
            and (tok.endswith("/") or bool(_SUFFIX.search(tok))))


def _clean(toks) -> set[str]:
    return {t.rstrip("/") for t in toks if t.rstrip("/") not in ("", ".")}


def names(b: Block) -> tuple[set[str], set[str]]:
    """The files and folders a block mentions, and of those the ones it surely writes (relative to its folder,
    without a trailing ``/``): a file block writes its NAME; a shell line mentions its path-like arguments
    (``x.stl``, ``spine/``) and writes the values of its output options (``-o``, ``--recipe``, ``--report``,
    ``--save-tets`` ...); a Python block mentions its path-like string literals. ``../shared/...`` (the
    prepared femur) is nobody's output."""
    if b.file:
        return _clean([b.file]), _clean([b.file])
    mentioned, written = set(), set()
    if b.lang == "python":
        for m in _STRING.finditer(b.text):
            tok = m.group(1) if m.group(1) is not None else m.group(2)
            if _pathlike(tok):
                mentioned.add(tok)
    else:
        for argv in commands(b.text):
            for i, tok in enumerate(argv[1:], 1):
                out = bool(_OUT_OPTIONS.match(argv[i - 1])) and not tok.startswith((SHARED, "-"))
                if out:
                    written.add(tok)
                if out or _pathlike(tok):
                    mentioned.add(tok)
    return _clean(mentioned), _clean(written)


def _same(a: str, b: str) -> bool:
    """One name is the other, or a file inside it (``femur-report`` and ``femur-report/report.json``)."""
    return a == b or a.startswith(b + "/") or b.startswith(a + "/")


def prerequisites(page_blocks: list[Block]) -> dict[int, list[Block]]:
    """For each block that runs (by line), the earlier ones it needs, in page order, and what those need in
    turn: a block needs an earlier one that writes a file or folder it mentions. A block writes what its output
    options name (:func:`names`) and what it is the first on the page to mention (a Python block's
    ``save(..., "body.stl")``); so two blocks that only read the same file stay apart, and a block that
    overwrites a file is needed by the later readers too. Blocks without such a link run on their own."""
    run = [b for b in page_blocks if not b.skip]
    mentioned, writes, seen = {}, {}, set()
    for b in run:
        m, w = names(b)
        mentioned[b.line] = m
        writes[b.line] = w | {x for x in m if not any(_same(x, y) for y in seen)}
        seen |= m
    needs: dict[int, list[Block]] = {}
    for k, b in enumerate(run):
        direct = [a for a in run[:k] if any(_same(x, y) for x in mentioned[b.line] for y in writes[a.line])]
        closure = {a.line for a in direct}
        for a in direct:
            closure |= {c.line for c in needs[a.line]}
        needs[b.line] = [a for a in run[:k] if a.line in closure]
    return needs


def title(b: Block) -> str:
    """A readable test id: the page, the line and the example's first words (``README.md:74 porecad tpms G
    --structure sheet``; a Python block's first line after its imports)."""
    if b.lang == "python":
        lines = [ln for ln in b.text.splitlines()
                 if ln.strip() and not ln.startswith(("import ", "from ", "#"))] or b.text.splitlines()
        words = lines[0].split()
    else:
        words = (commands(b.text) or [["?"]])[0]
    text = " ".join(words).replace(SHARED + "data/", "").replace('"', "").replace("'", "")
    return f"{b.page}:{b.line} {text[:36].rstrip()}"


def run_blocks(run: list[Block], work: Path) -> list[str]:
    """Run blocks in order in ``work`` (this process's working folder meanwhile); return what each printed.
    The femur figures are checked only on the real femur, as in :func:`run_page`."""
    real = (work.parent / "shared" / "data" / "femur.stl").resolve().name != STANDIN
    here = os.getcwd()
    os.chdir(work)
    try:
        return [run_block(b, work, femur_figures=real) for b in run]
    finally:
        os.chdir(here)


def run_page(path: Path, work: Path, log=None, start: int = 0) -> dict:
    """Run a page's blocks in order in ``work``; return the counts (collected, run, skipped).

    The figures quoted for the femur are checked only where ``../shared/data/femur.stl`` is the real one
    (``PORECAD_EXAMPLES_FEMUR=real``); the tests use a generated stand-in (:func:`prepare`).
    """
    real = (work.parent / "shared" / "data" / "femur.stl").resolve().name != STANDIN
    import time
    counts = {"collected": 0, "run": 0, "skipped": 0, "files": 0}
    here = os.getcwd()
    os.chdir(work)
    try:
        for b in blocks(path):
            counts["collected"] += 1
            if b.skip or (b.line < start and not b.file):
                counts["skipped"] += 1
                continue
            t0, c0 = time.perf_counter(), time.process_time()
            run_block(b, work, femur_figures=real)
            counts["files" if b.file else "run"] += 1
            if log:  # CPU seconds too: the wall time of a loaded machine says little
                log(f"{b.where}: {time.perf_counter() - t0:.1f} s, CPU {time.process_time() - c0:.1f} s")
    finally:
        os.chdir(here)
    return counts


STANDIN = "femur-standin.stl"


def standin(folder: Path) -> Path:
    """The generated femur stand-in of :func:`prepare`, written in ``folder`` (the tests make it once a session)."""
    import trimesh
    femur = folder / STANDIN
    trimesh.creation.capsule(height=60.0, radius=7.0, count=[32, 32]).export(femur)
    return femur


def prepare(tmp: Path, femur: Path | None = None) -> Path:
    """A folder for a page's examples, with a femur at ../shared/data/femur.stl: ``femur`` (the real one),
    or a generated capsule of half a femur's size (60 mm long, 14 mm thick: room for a few 5 mm cells across)
    that keeps the examples quick."""
    data = tmp / "shared" / "data"
    data.mkdir(parents=True)
    if femur is None:
        femur = standin(tmp)
    (data / "femur.stl").symlink_to(femur)
    work = tmp / "work"
    work.mkdir()
    return work


if __name__ == "__main__":  # python tests/doc_examples.py [PAGE ...]: run pages, print each block's time
    import tempfile
    from porecad.datasets import femur_path
    if len(sys.argv) == 5 and sys.argv[2] == "--from":  # PAGE --from LINE WORKDIR: resume in a kept folder
        print(run_page(ROOT / sys.argv[1], Path(sys.argv[4]), log=print, start=int(sys.argv[3])))
        sys.exit()
    real = os.environ.get("PORECAD_EXAMPLES_FEMUR") == "real"
    for name in sys.argv[1:] or [str(p.relative_to(ROOT)) for p in pages()]:
        with tempfile.TemporaryDirectory() as tmp:
            work = prepare(Path(tmp), femur_path() if real else None)
            print(name, run_page(ROOT / name, work, log=print), flush=True)
