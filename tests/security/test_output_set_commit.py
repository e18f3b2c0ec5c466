"""Issue 51, problem 7 and acceptance 3: an output set is all or nothing, whatever stops it.

``-o m.stl --report m.json --recipe m.toml --force`` over earlier files: a
failed rename, Ctrl-C, SIGTERM or the kill of the job's child at any moment
leaves every earlier file byte-identical (or all three new ones), no other
file, and a message that says what really happened.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from porecad.cli.main import main

NAMES = ("m.json", "m.stl", "m.toml")
JOB = ["tpms", "G", "--porosity", "0.6", "--cells", "1", "1", "1", "--resolution", "10",
       "-o", "m.stl", "--report", "m.json", "--recipe", "m.toml", "--force"]


@pytest.fixture
def earlier(tmp_path, monkeypatch):
    """A working folder holding earlier m.stl, m.json and m.toml; returns their bytes."""
    monkeypatch.chdir(tmp_path)
    old = {name: f"earlier {name}\n".encode() for name in NAMES}
    for name, data in old.items():
        (tmp_path / name).write_bytes(data)
    return old


def _contents(where: Path) -> dict:
    return {p.name: (p.read_bytes() if p.is_file() else "folder") for p in sorted(where.iterdir())}


@pytest.mark.parametrize("links", [True, False])
def test_failed_rename_restores_every_earlier_output(tmp_path, earlier, monkeypatch, capsys, links):
    """Problem 7: m.json turned into a folder mid-job; the earlier m.stl and m.toml stay as they were.

    Also where the file system has no hard links (the earlier files are then moved aside).
    """
    real = os.replace
    if not links:
        def no_link(*args, **kwargs):
            raise PermissionError(1, "Operation not permitted")
        monkeypatch.setattr(os, "link", no_link)

    def replace(src, dst, *args, **kwargs):
        if Path(dst).name == "m.json" and ".tmp-" in Path(src).name:
            if Path(dst).is_file():
                os.unlink(dst)
            os.mkdir(dst)  # someone else's folder appears where the report goes
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    code = main(JOB)
    err = capsys.readouterr().err
    assert code != 0
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("porecad: warning:")]
    assert len(lines) == 1 and lines[0].startswith("porecad: error:"), err
    after = _contents(tmp_path)
    assert after == {"m.json": "folder", "m.stl": earlier["m.stl"], "m.toml": earlier["m.toml"]}, after


def test_successful_commit_leaves_no_backup(tmp_path, earlier):
    assert main(JOB) == 0
    after = _contents(tmp_path)
    assert sorted(after) == list(NAMES)
    assert all(after[n] != earlier[n] for n in NAMES)


def _records() -> int:
    """How many journal records one whole run writes (each is a moment to stop it at)."""
    import porecad.io.atomic as atomic
    r, w = os.pipe()
    atomic.set_journal(w)
    try:
        assert main(JOB) == 0
    finally:
        atomic.set_journal(None)
        os.close(w)
    with os.fdopen(r, "rb") as fh:
        return fh.read().count(b"\n")


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "SIGKILL"])
def test_stop_at_every_moment_keeps_earlier_files(tmp_path, earlier, monkeypatch, capsys, how):
    """Acceptance 3: the stop before and after each journal record (every step of the commit included)."""
    import porecad.io.atomic as atomic
    from porecad.cli.watch import run_watched
    total = _records()
    new = _contents(tmp_path)
    capsys.readouterr()
    assert total >= 14 and all(new[n] != earlier[n] for n in NAMES)
    outcomes = set()
    parent = os.getpid()
    real_note = atomic._note
    for k in range(2 * total + 1):  # moment 2i: before record i is written, 2i + 1: right after it
        for name, data in earlier.items():
            (tmp_path / name).write_bytes(data)
        seen = [0]

        def stop_here():
            seen[0] += 1
            if os.getpid() != parent and seen[0] > k:
                if how == "SIGKILL":
                    os.kill(os.getpid(), signal.SIGKILL)
                os.kill(os.getppid(), getattr(signal, how))
                time.sleep(30)  # the parent kills this child at once

        def note(*args, **kwargs):
            stop_here()
            real_note(*args, **kwargs)
            stop_here()

        monkeypatch.setattr(atomic, "_note", note)
        code = run_watched(lambda: main(JOB))
        err = "\n".join(ln for ln in capsys.readouterr().err.strip().splitlines() if "warning:" not in ln)
        after = _contents(tmp_path)
        assert sorted(after) == list(NAMES), (k, after, err)  # no temporary, no backup left
        if after == earlier:
            restored = err.partition("restored the earlier ")[2]
            assert code != 0 and ("nothing written" in err), (k, err)
            assert restored == "" or set(restored.split(", ")) <= {str(tmp_path / n) for n in NAMES}, (k, err)
            outcomes.add("restored" if restored else "untouched")
        else:
            outcomes.add("written")
            assert all(after[n] != earlier[n] for n in NAMES), (k, after)  # all three new, never a mix
            assert after["m.stl"] == new["m.stl"] and after["m.toml"] == new["m.toml"], k
            assert code == 0 or err.count(str(tmp_path)) == 3 and "wrote " in err, (k, err)
        if code != 0:
            assert len(err.splitlines()) == 1, (k, err)
            word = {"SIGINT": "interrupted", "SIGTERM": "terminated", "SIGKILL": "killed by signal 9"}[how]
            assert word in err, (k, err)
    assert outcomes == {"untouched", "restored", "written"}  # stops before, during and after the commit


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="finds the job's child through /proc (Linux)")
def test_the_program_stopped_or_its_child_killed_keeps_earlier_files(tmp_path, earlier):
    """Acceptance 3 on the real program: SIGINT, SIGTERM, or SIGKILL of the job's child, at random moments."""
    import random
    import subprocess
    import sys
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2] / "src"))
    run = [sys.executable, "-m", "porecad", *JOB[:-1], "--force"]
    t0 = time.perf_counter()
    subprocess.run(run, cwd=tmp_path, env=env, capture_output=True, timeout=300, check=True)
    span = time.perf_counter() - t0
    new = _contents(tmp_path)
    rng = random.Random(51)
    for i, how in enumerate(["SIGINT", "SIGTERM", "SIGKILL"]):
        for name, data in earlier.items():
            (tmp_path / name).write_bytes(data)
        proc = subprocess.Popen(run, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        time.sleep(rng.uniform(0.3, span))
        if how == "SIGKILL":
            for child in _children(proc.pid):
                os.kill(child, signal.SIGKILL)
        else:
            proc.send_signal(getattr(signal, how))
        _, err = proc.communicate(timeout=60)
        after = _contents(tmp_path)
        assert sorted(after) == list(NAMES), (i, how, after, err)
        assert after == earlier or after["m.stl"] == new["m.stl"] and after["m.toml"] == new["m.toml"] \
            and after["m.json"] != earlier["m.json"], (i, how, after)
        last = err.decode().strip().splitlines()[-1] if err.strip() else ""
        if after == earlier and proc.returncode not in (0, -2, -15):
            assert "nothing written" in last or "restored the earlier" in last, (i, how, last)
        if after != earlier and proc.returncode != 0:
            assert "wrote " in last and last.count(str(tmp_path)) == 3, (i, how, last)
