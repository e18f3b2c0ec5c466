"""Issue 42: every documented example runs as written (tests/doc_examples.py collects and runs them)."""

import pytest

from doc_examples import ExampleFailed, Block, blocks, commands, pages, prepare, run_block, run_page

PAGES = [p for p in pages() if blocks(p)]


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_page_examples_run(page, tmp_path):
    counts = run_page(page, prepare(tmp_path))
    assert counts["collected"] == counts["run"] + counts["skipped"] + counts["files"]
    assert counts["run"] >= 1 or counts["skipped"] == counts["collected"]


def test_every_page_with_a_shell_or_python_block_is_collected():
    names = {p.name for p in PAGES}
    assert {"README.md", "tis.md", "tdf-format.md", "scale-out.md"} <= names
    readme = blocks(pages()[0])
    assert len(readme) >= 15
    assert all(b.skip is None or len(b.skip) >= 8 for p in PAGES for b in blocks(p))


def test_markers_and_command_lines(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n<!-- example: skip (needs the network) -->\n```bash\npip install x\n```\n"
                    "<!-- example: file a.csv -->\n```\n1,2\n```\n"
                    "<!-- example: expect print 0.5 0.01 -->\n```python\nprint(0.5)\n```\n"
                    "```toml\nx = 1\n```\n")
    got = blocks(page)
    assert [b.lang for b in got] == ["bash", "", "python"]
    assert got[0].skip == "needs the network" and got[1].file == "a.csv" and got[2].expect == [("print", 0.5, 0.01)]
    assert commands("porecad a \\\n   b  # note\npython -c 'print(1)' && porecad c\n") == [
        ["porecad", "a", "b"], ["python", "-c", "print(1)"], ["porecad", "c"]]
    run_block(got[1], tmp_path)
    assert (tmp_path / "a.csv").read_text() == "1,2\n"
    with pytest.raises(ExampleFailed, match="quotes print = 0.7"):
        run_block(Block("p", 1, "python", "print(0.5)\n", expect=[("print", 0.7, 0.01)]), tmp_path)
    with pytest.raises(ExampleFailed, match="mark the block"):
        run_block(Block("p", 1, "bash", "rm -rf x\n"), tmp_path)
    with pytest.raises(ExampleFailed, match="exited 2"):
        run_block(Block("p", 1, "bash", "porecad tpms NOPE -o x.stl\n"), tmp_path)
