"""Issue 51, problem 1: a name cannot inject the stop/cleanup journal; clean-up removes only its own temporaries.

A recipe's output name once carried newlines into the journal between the
job's child and the parent (``cli/watch.py``), so that Ctrl-C deleted files
and folders the recipe named. Names with a control character are now refused
in one line before any work, and the journal is one JSON record per entry
whose clean-up removes a path only when it still is the very file this run
created (device and inode recorded).
"""

from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path

import pytest

from porecad.cli.main import main

TPMS = ["tpms", "G", "--porosity", "0.6", "--cells", "1", "1", "1", "--resolution", "10"]
INJECT_MESH = "m\nT victim.txt\nT .vdir\n.stl"


def _refused(capsys, argv, match) -> str:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("porecad: warning:")]
    assert code != 0, out
    assert len(lines) == 1 and lines[0].startswith("porecad: error:"), err
    assert re.search(match, lines[0]), lines[0]
    return lines[0]


def _victims(where: Path) -> Path:
    (where / "victim.txt").write_text("keep me")
    (where / ".vdir").mkdir()
    (where / ".vdir" / "inside.txt").write_text("keep me too")
    outside = where / "abs-victim.txt"
    outside.write_text("absolute")
    return outside


def _victims_intact(where: Path) -> None:
    assert (where / "victim.txt").read_text() == "keep me"
    assert (where / ".vdir" / "inside.txt").read_text() == "keep me too"
    assert (where / "abs-victim.txt").read_text() == "absolute"


@pytest.fixture
def recipe(tmp_path, monkeypatch):
    """A small valid recipe ``r.toml`` in a fresh working folder (no other file)."""
    monkeypatch.chdir(tmp_path)
    assert main([*TPMS, "-o", "seed.stl", "--recipe", "r.toml"]) == 0
    (tmp_path / "seed.stl").unlink()
    return tmp_path / "r.toml"


def _with_output(recipe_file: Path, **outputs) -> None:
    text = re.sub(r"\[output\][^\[]*", "", recipe_file.read_text())
    recipe_file.write_text(text + "\n[output]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in outputs.items()))


@pytest.mark.parametrize("key,value", [
    ("mesh", INJECT_MESH),
    ("report", "r\nT {abs}\n/x"),
    ("mesh", "m\r.stl"),
    ("mesh", "m\t.stl"),
    ("recipe", "r\x7f.toml"),
    ("mesh", "m\x85.stl"),
    ("mesh", "sub\x1b/m.stl"),
    ("mesh", "m\u2028.stl"),
])
def test_recipe_output_names_with_control_characters_refused(recipe, capsys, key, value):
    where = recipe.parent
    outside = _victims(where)
    outputs = {"mesh": "ok.stl", key: value.format(abs=outside)}
    _with_output(recipe, **outputs)
    before = sorted(os.listdir(where))
    err = _refused(capsys, ["build", recipe, "--force"], "control character")
    assert f"output.{key}" in err
    assert sorted(os.listdir(where)) == before  # refused before any work: nothing written
    _victims_intact(where)


@pytest.mark.parametrize("flag", ["-o", "--report", "--recipe"])
@pytest.mark.parametrize("name", ["a\nb.stl", "a\rb", "a\tb", "\x1bb", "a\x85b"])
def test_command_line_output_names_with_control_characters_refused(tmp_path, monkeypatch, capsys, flag, name):
    monkeypatch.chdir(tmp_path)
    argv = [*TPMS, "-o", "ok.stl", flag, name] if flag != "-o" else [*TPMS, "-o", name]
    _refused(capsys, argv, "control character")
    assert os.listdir(tmp_path) == []


def test_input_paths_with_control_characters_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a\nb.stl").write_bytes(b"solid x\nendsolid x\n")
    _refused(capsys, ["analyze", "a\nb.stl"], "control character")
    from porecad.errors import InputError
    from porecad.recipes.table import Table
    with pytest.raises(InputError, match=r"control character") as info:
        Table({"image": "a\nb.stl"}, "body", base=tmp_path).path("image")
    assert len(str(info.value).splitlines()) == 1 and "body.image" in str(info.value)


def _stop(how: str) -> None:
    if how == "SIGKILL":
        os.kill(os.getpid(), signal.SIGKILL)
    os.kill(os.getppid(), getattr(signal, how))
    time.sleep(30)  # the parent kills this child at once


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "SIGKILL"])
def test_a_name_cannot_inject_the_journal(tmp_path, monkeypatch, capsys, how):
    """Problem 1 by hand: temporaries whose names hold journal lines; the stop removes only the real temps."""
    from porecad.cli.watch import run_watched
    import porecad.io.confine as confine
    from porecad.io.atomic import temp_file
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(confine, "check_name", lambda name, what: os.fspath(name))  # as if names were not checked
    outside = _victims(tmp_path)
    names = [tmp_path / INJECT_MESH, tmp_path / f"r\nT {outside}\n/x",
             tmp_path / 'n\n{"op": "temp", "path": "victim.txt", "id": null}\n.stl']

    def invoke():
        for name in names:  # straight to the journal, as a writer's own temporaries
            name.parent.mkdir(parents=True, exist_ok=True)
            fd, _ = temp_file(name, "tmp")
            os.write(fd, b"partial")
        _stop(how)
        return 0

    code = run_watched(invoke)
    err = capsys.readouterr().err
    assert code != 0
    _victims_intact(tmp_path)
    left = [p for p in tmp_path.rglob("*") if p.is_file() and ".tmp-" in p.name]
    assert left == [], left  # the real temporaries are gone
    assert "victim" not in err and ".vdir" not in err, err
    assert len(err.strip().splitlines()) == 1 and "nothing written" in err, err


def _journal_of(work):
    """Run ``work()`` here with the journal on a pipe; return a parent's :class:`Journal` fed with it."""
    from porecad.cli.watch import Journal
    from porecad.io.atomic import set_journal
    r, w = os.pipe()
    set_journal(w)
    try:
        work()
    finally:
        set_journal(None)
        os.close(w)
    journal = Journal()
    with os.fdopen(r, "rb") as fh:
        journal.feed(fh.read())
    return journal


def test_journal_clean_removes_only_the_files_this_run_created(tmp_path):
    """Temps swapped for other files, folders or links after they were recorded are left alone."""
    from porecad.io.atomic import atomic_write
    made, open_writes = {}, []

    def work():
        for name in ("a.stl", "b.stl", "c.stl", "d.stl", "e.stl"):
            open_writes.append(atomic_write(tmp_path / name))
            fh = open_writes[-1].__enter__()
            fh.write(b"data")
            fh.flush()  # left open and unfinished, as a killed child leaves it
            made[name] = next(tmp_path.glob(f".{name}.tmp-*"))

    journal = _journal_of(work)
    keep = tmp_path / "keep.txt"
    keep.write_text("user file")
    # each made while the temporary still exists (so a new inode), then put under its name
    (tmp_path / "other").write_text("someone else's file, same name")
    os.replace(tmp_path / "other", made["b.stl"])
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "x").write_text("a folder's content")
    os.unlink(made["c.stl"])
    os.rename(tmp_path / "folder", made["c.stl"])
    os.symlink(keep, tmp_path / "link")
    os.replace(tmp_path / "link", made["d.stl"])
    journal.feed(b"T " + os.fsencode(keep) + b"\n")  # the old text format means nothing now
    journal.feed(json.dumps({"op": "temp", "path": str(keep), "id": list(_ident(keep))}).encode()[:-3] + b"\n")
    written, removed, restored = journal.clean()
    assert written == [] and restored == []
    assert not made["a.stl"].exists() and not made["e.stl"].exists()
    assert made["b.stl"].read_text() == "someone else's file, same name"
    assert (made["c.stl"] / "x").read_text() == "a folder's content"
    assert os.readlink(made["d.stl"]) == str(keep) and keep.read_text() == "user file"
    assert removed == []  # hidden temporaries are not outputs: nothing to report


def _ident(p: Path):
    st = os.lstat(p)
    return st.st_dev, st.st_ino


def test_stop_never_removes_a_folder_it_did_not_create(tmp_path, capsys):
    """Folders made for a set go only while empty; folders that were there, or now hold others' files, stay."""
    from porecad.cli.watch import run_watched
    from porecad.io.atomic import atomic_write, make_dirs, output_set
    (tmp_path / "old").mkdir()

    def invoke():
        with output_set():
            make_dirs(tmp_path / "new" / "deeper")
            make_dirs(tmp_path / "old")
            make_dirs(tmp_path / "shared")
            with atomic_write(tmp_path / "new" / "deeper" / "m.stl") as fh:
                fh.write(b"x")
            (tmp_path / "old" / "mine.txt").write_text("user")  # files of someone else, meanwhile
            (tmp_path / "shared" / "theirs.txt").write_text("user")
            os.kill(os.getpid(), signal.SIGKILL)
        return 0

    assert run_watched(invoke) == 3
    err = capsys.readouterr().err.strip()
    assert sorted(os.listdir(tmp_path)) == ["old", "shared"]
    assert (tmp_path / "old" / "mine.txt").read_text() == "user"
    assert (tmp_path / "shared" / "theirs.txt").read_text() == "user"
    made = f"{tmp_path / 'new' / 'deeper'}, {tmp_path / 'new'}"
    assert err.endswith(f"nothing written; removed the unfinished {made}"), err
