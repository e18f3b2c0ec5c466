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


def prepare(tmp: Path, femur: Path | None = None) -> Path:
    """A folder for a page's examples, with a femur at ../shared/data/femur.stl: ``femur`` (the real one),
    or a generated capsule of half a femur's size (60 mm long, 14 mm thick: room for a few 5 mm cells across)
    that keeps the examples quick."""
    data = tmp / "shared" / "data"
    data.mkdir(parents=True)
    if femur is None:
        import trimesh
        femur = tmp / STANDIN
        trimesh.creation.capsule(height=60.0, radius=7.0, count=[32, 32]).export(femur)
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
