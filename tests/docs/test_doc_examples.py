"""Issue 42: every documented example runs as written (tests/doc_examples.py collects and runs them).

Issue 53: one test item per example (a fenced block), so that pytest-xdist spreads the pages' examples over
its workers; an example that reads what earlier ones wrote gets those first (:func:`prerequisites`), built
once per worker by the module fixture ``inputs`` and copied into the example's own folder.
"""

import shutil

import pytest

from doc_examples import (ExampleFailed, Block, blocks, commands, names, pages, prepare, prerequisites, run_block,
                          run_blocks, standin, title)

BLOCKS = {p: blocks(p) for p in pages()}  # read once: the items, their prerequisites and the checks agree
PAGES = [p for p in pages() if BLOCKS[p]]
NEEDS = {p: prerequisites(BLOCKS[p]) for p in PAGES}
ITEMS = [(p, b) for p in PAGES for b in BLOCKS[p] if not b.skip and not b.file]
IDS = [title(b) for _, b in ITEMS]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """(the femur stand-in, build): ``build(page, blocks)`` runs those blocks once in a folder of their own
    and returns it (the shared inputs of the examples that need them)."""
    femur = standin(tmp_path_factory.mktemp("femur"))
    built = {}

    def build(page, need):
        key = (page.name, tuple(b.line for b in need))
        if key not in built:
            work = prepare(tmp_path_factory.mktemp("inputs"), femur)
            run_blocks(need, work)
            built[key] = work
        return built[key]

    return femur, build


@pytest.mark.parametrize("page,block", ITEMS, ids=IDS)
def test_example_runs(page, block, inputs, tmp_path):
    femur, build = inputs
    need = NEEDS[page][block.line]
    work = prepare(tmp_path, femur)
    if need:
        shutil.copytree(build(page, need), work, symlinks=True, dirs_exist_ok=True)
    run_blocks([block], work)  # raises ExampleFailed: a command exited non-zero, or a quoted figure is off
    written = names(block)[1]
    missing = [n for n in sorted(written) if not (work / n).exists() and not list(work.glob(n + ".*"))]
    assert not missing, f"{block.where} names outputs it did not write: {missing}"


def test_every_example_is_a_test_item():
    for p in PAGES:
        got = BLOCKS[p]
        run = [b for b in got if not b.skip and not b.file]
        assert len(got) == len(run) + sum(1 for b in got if b.skip) + sum(1 for b in got if b.file and not b.skip)
        assert run or all(b.skip for b in got), p.name
        assert [b.line for q, b in ITEMS if q == p] == [b.line for b in run]
    assert len(set(IDS)) == len(IDS)


def test_every_page_with_a_shell_or_python_block_is_collected():
    names = {p.name for p in PAGES}
    assert {"README.md", "tis.md", "tdf-format.md", "scale-out.md"} <= names
    readme = blocks(pages()[0])
    assert len(readme) >= 15
    assert all(b.skip is None or len(b.skip) >= 8 for p in PAGES for b in blocks(p))


def test_prerequisites_follow_the_files(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- example: file pts.csv -->\n```\n1,2\n```\n"
                    "```python\nimport porecad as pc\npc.save(pc.datasets.star_blob(), 'body.stl')\n```\n"
                    "```bash\nporecad infill body.stl G -o a.stl --report rep/\n```\n"
                    "```bash\nporecad infill body.stl P --porosity-points pts.csv -o b.stl\n```\n"
                    "```bash\nporecad analyze a.stl && python -c 'print(open(\"rep/report.json\").read())'\n```\n"
                    "```bash\nporecad tpms G -o c.stl  # on its own\n```\n"
                    "<!-- example: skip (writes a.stl again) -->\n```bash\nporecad tpms G -o a.stl\n```\n"
                    "```bash\nporecad analyze ../shared/data/femur.stl\n```\n")
    got = blocks(page)
    assert names(got[2]) == ({"body.stl", "a.stl", "rep"}, {"a.stl", "rep"})
    need = {line: [a.line for a in v] for line, v in prerequisites(got).items()}
    lines = [b.line for b in got]
    assert need == {lines[0]: [], lines[1]: [], lines[2]: [lines[1]], lines[3]: [lines[0], lines[1]],
                    lines[4]: [lines[1], lines[2]], lines[5]: [], lines[7]: []}
    assert title(got[2]) == f"docs/page.md:{lines[2]} porecad infill body.stl G -o a.stl -"
    assert title(got[1]) == f"docs/page.md:{lines[1]} pc.save(pc.datasets.star_blob(), bod"
    assert title(got[7]) == f"docs/page.md:{lines[7]} porecad analyze femur.stl"


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
