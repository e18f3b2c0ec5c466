"""The TDF scaffold file (porecad.io.tdf_file): exact round trip, layout, strict reader."""

import re
import struct
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from porecad.errors import InputError, OutputError
from porecad.io.tdf_file import TDFRecord, read_tdf, write_tdf
from porecad.splines.knots import clamped_uniform_knots

DOCS = Path(__file__).resolve().parents[2] / "docs" / "tdf-format.md"

# The file write_tdf produces for _base_record(); line numbers matter below.
BASE_LINES = [
    "porecad-tdf 1",                                   # 1
    "## porecad TDF scaffold file; specification: docs/tdf-format.md",  # 2
    "#metadata",                                       # 3
    "units = mm",                                      # 4
    "#TPMS type",                                      # 5
    "G",                                               # 6
    "#structure type",                                 # 7
    "pore",                                            # 8
    "#period coefficients (rho_u, rho_v, rho_w)",      # 9
    "2.0 3.0 4.0",                                     # 10
    "#degrees of TDF (p_u, p_v, p_w)",                 # 11
    "1 1 1",                                           # 12
    "#resolution of the control grid of TDF",          # 13
    "2 2 2",                                           # 14
    "#control points of TDF",                          # 15
    "0.1 0.2",                                         # 16
    "0.3 0.4",                                         # 17
    "0.5 0.6",                                         # 18
    "0.7 0.8",                                         # 19
    "#knot vector in u-direction of TDF",              # 20
    "0.0 0.0 1.0 1.0",                                 # 21
    "#knot vector in v-direction of TDF",              # 22
    "0.0 0.0 1.0 1.0",                                 # 23
    "#knot vector in w-direction of TDF",              # 24
    "0.0 0.0 1.0 1.0",                                 # 25
    "#degrees of TBSS (p_u, p_v, p_w)",                # 26
    "1 1 1",                                           # 27
    "#periodic flags of TBSS (u, v, w)",               # 28
    "0 0 0",                                           # 29
    "#resolution of the control grid of TBSS",         # 30
    "2 2 2",                                           # 31
    "#control points of TBSS",                         # 32
    "0.0 0.0 0.0",                                     # 33
    "0.0 0.0 1.0",                                     # 34
    "0.0 1.0 0.0",                                     # 35
    "0.0 1.0 1.0",                                     # 36
    "1.0 0.0 0.0",                                     # 37
    "1.0 0.0 1.0",                                     # 38
    "1.0 1.0 0.0",                                     # 39
    "1.0 1.0 1.0",                                     # 40
    "#knot vector in u-direction of TBSS",             # 41
    "0.0 0.0 1.0 1.0",                                 # 42
    "#knot vector in v-direction of TBSS",             # 43
    "0.0 0.0 1.0 1.0",                                 # 44
    "#knot vector in w-direction of TBSS",             # 45
    "0.0 0.0 1.0 1.0",                                 # 46
    "#end",                                            # 47
]


def _base_record():
    box = np.stack(np.meshgrid([0.0, 1.0], [0.0, 1.0], [0.0, 1.0], indexing="ij"), axis=-1)
    return TDFRecord(
        tpms_type="G", structure="pore", periods=(2, 3, 4),
        tdf_degrees=(1, 1, 1), tdf_knots=[[0, 0, 1, 1]] * 3,
        tdf_control=np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]).reshape(2, 2, 2),
        tbss_degrees=(1, 1, 1), tbss_knots=[[0, 0, 1, 1]] * 3, tbss_control=box,
        metadata={"units": "mm"},
    )


def _random_record(rng, tdf_shape, tbss_shape, tdf_deg=(3, 3, 3), tbss_deg=(3, 3, 3)):
    return TDFRecord(
        tpms_type="IWP", structure="sheet", periods=(8.0, 6.0, 8.0),
        tdf_degrees=tdf_deg,
        tdf_knots=[clamped_uniform_knots(n, p) for n, p in zip(tdf_shape, tdf_deg)],
        tdf_control=rng.normal(scale=0.01, size=tdf_shape),
        tbss_degrees=tbss_deg,
        tbss_knots=[clamped_uniform_knots(n, p) for n, p in zip(tbss_shape, tbss_deg)],
        tbss_control=rng.uniform(-200.0, 200.0, size=tuple(tbss_shape) + (3,)),
    )


def _assert_same(a: TDFRecord, b: TDFRecord):
    assert (a.version, a.tpms_type, a.structure) == (b.version, b.tpms_type, b.structure)
    assert a.periods == b.periods
    assert a.tdf_degrees == b.tdf_degrees and a.tbss_degrees == b.tbss_degrees
    assert a.tbss_periodic == b.tbss_periodic
    assert a.metadata == b.metadata
    for x, y in [(a.tdf_control, b.tdf_control), (a.tbss_control, b.tbss_control),
                 *zip(a.tdf_knots, b.tdf_knots), *zip(a.tbss_knots, b.tbss_knots)]:
        assert x.dtype == y.dtype == np.float64
        assert x.shape == y.shape
        assert np.array_equal(x, y)
        assert np.array_equal(np.signbit(x), np.signbit(y))  # -0.0 stays -0.0


def _text(lines):
    return "".join(line + "\n" for line in lines)


# ----------------------------------------------------------------- round trip


def test_writer_output_is_the_documented_layout(tmp_path):
    p = write_tdf(tmp_path / "base.tdf", _base_record())
    assert p.read_text(encoding="utf-8") == _text(BASE_LINES)
    _assert_same(read_tdf(p), _base_record())


def test_exact_round_trip_of_awkward_floats(tmp_path):
    awkward = [0.1, 1 / 3, 1e-300, -0.0, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308,
               -2.5e-17, 2 / 3, 1e16 + 2, 123456789.12345679, np.nextafter(1.0, 2.0)]
    tdf = np.array(awkward * 6)[:64].reshape(4, 4, 4)
    tdf[3, 3, 3] = -1 / 7
    rng = np.random.default_rng(7)
    tbss = rng.normal(size=(5, 4, 6, 3)) * 10.0 ** rng.integers(-12, 12, size=(5, 4, 6, 3))
    tbss[0, 0, 0] = [-0.0, 0.1, 1 / 3]
    third = 1 / 3
    rec = TDFRecord(
        tpms_type="D", structure="rod", periods=(10 / 3, 0.1, 7.000000000000001),
        tdf_degrees=(2, 1, 3),
        tdf_knots=[[0, 0, 0, third, 1, 1, 1], [0, 0, 0.1, 2 / 3, 1, 1], [-0.0, 0, 0, 0, 1, 1, 1, 1]],
        tdf_control=tdf,
        tbss_degrees=(2, 3, 1),
        tbss_knots=[[0, 0, 0, third, 2 / 3, 1, 1, 1], clamped_uniform_knots(4, 3), clamped_uniform_knots(6, 1)],
        tbss_control=tbss,
        tbss_periodic=(False, True, False),
        metadata={"units": "µm", "created-by": "porecad test", "comment": "a = b # not a header"},
    )
    back = read_tdf(write_tdf(tmp_path / "awkward.tdf", rec))
    _assert_same(back, rec)
    # and once more: writing what was read gives the very same bytes
    again = write_tdf(tmp_path / "again.tdf", back)
    assert again.read_bytes() == (tmp_path / "awkward.tdf").read_bytes()


def test_index_order_k_fastest(tmp_path):
    # non-cubic, non-symmetric grids: a transposition or a wrong order cannot pass
    tdf = np.arange(2 * 3 * 4, dtype=np.float64).reshape(2, 3, 4)
    tbss = np.arange(3 * 2 * 4 * 3, dtype=np.float64).reshape(3, 2, 4, 3) / 8
    rec = TDFRecord(
        tpms_type="P", structure="pore", periods=(1, 2, 3),
        tdf_degrees=(1, 2, 3), tdf_knots=[clamped_uniform_knots(n, p) for n, p in [(2, 1), (3, 2), (4, 3)]],
        tdf_control=tdf,
        tbss_degrees=(2, 1, 3), tbss_knots=[clamped_uniform_knots(n, p) for n, p in [(3, 2), (2, 1), (4, 3)]],
        tbss_control=tbss,
    )
    p = write_tdf(tmp_path / "order.tdf", rec)
    lines = p.read_text(encoding="utf-8").splitlines()
    i = lines.index("#control points of TDF")
    assert lines[i + 1] == "0.0 1.0 2.0 3.0"           # tdf[0, 0, :]
    assert lines[i + 2] == "4.0 5.0 6.0 7.0"           # tdf[0, 1, :]
    assert lines[i + 4] == "12.0 13.0 14.0 15.0"       # tdf[1, 0, :]
    assert lines[i + 7].startswith("#knot vector in u")  # 2*3 lines, one per (i, j)
    i = lines.index("#control points of TBSS")
    assert lines[i + 1] == "0.0 0.125 0.25"                     # tbss[0, 0, 0]
    assert lines[i + 2] == " ".join(map(repr, tbss[0, 0, 1].tolist()))  # k fastest
    assert lines[i + 5] == " ".join(map(repr, tbss[0, 1, 0].tolist()))
    assert lines[i + 9] == " ".join(map(repr, tbss[1, 0, 0].tolist()))
    assert lines[i + 3 * 2 * 4 + 1].startswith("#knot vector in u")
    back = read_tdf(p)
    assert back.tdf_control.shape == (2, 3, 4) and back.tbss_control.shape == (3, 2, 4, 3)
    assert back.tdf_control[1, 2, 3] == 23.0 and back.tdf_control[0, 2, 1] == 9.0
    _assert_same(back, rec)


def test_line_breaks_inside_a_section_do_not_matter(tmp_path):
    # all 8 TDF values on one line, TBSS coordinates one per line (like the reference files)
    lines = BASE_LINES[:15] + ["0.1 0.2 0.3 0.4 0.5 0.6 0.7 0.8"] + BASE_LINES[19:32]
    lines += [tok for pt in BASE_LINES[32:40] for tok in pt.split()] + BASE_LINES[40:]
    p = tmp_path / "rewrapped.tdf"
    p.write_text(_text(lines))
    _assert_same(read_tdf(p), _base_record())


def test_tolerated_variants(tmp_path):
    # CRLF, BOM, blank lines, '##' comments, 001 appendix / reference header wording, plain ints
    lines = list(BASE_LINES)
    lines[12] = "#resolution of control grid of TDF"               # 001's appendix wording
    lines[8] = "#period coefficients (rho_u,rho_v,rho_w)"          # reference wording
    lines[4] = "#TPMS type, m=0: P-type; m=1: G-type"              # reference wording
    lines[9] = "2 3 4e0"
    lines.insert(17, "")
    lines.insert(17, "## a comment inside the data")
    p = tmp_path / "variants.tdf"
    p.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(lines).encode() + b"\r\n\r\n")
    _assert_same(read_tdf(p), _base_record())


def test_size_of_20_cubed_tdf_and_10_cubed_tbss(tmp_path):
    rec = _random_record(np.random.default_rng(1), (20, 20, 20), (10, 10, 10))
    p = write_tdf(tmp_path / "size.tdf", rec)
    size = p.stat().st_size
    assert 100_000 < size < 400_000, size  # ~0.23 MB of full-precision numbers; well under 1 MB
    _assert_same(read_tdf(p), rec)


def test_docs_example_is_a_valid_file(tmp_path):
    text = DOCS.read_text(encoding="utf-8")
    m = re.search(r"```\n(porecad-tdf 1\n.*?)```", text, re.S)
    assert m, "docs/tdf-format.md has no example file"
    p = tmp_path / "box.tdf"
    p.write_text(m.group(1))
    rec = read_tdf(p)
    assert rec.tdf_control.shape == (4, 4, 4) and rec.tbss_control.shape == (4, 4, 4, 3)
    assert rec.tdf_control[0, 1, 2] == 0.71
    assert list(rec.tbss_control[3, 0, 1]) == [12.0, 0.0, 2.0]
    assert rec.metadata["units"] == "mm"
    # it is exactly what the writer produces for that record
    assert write_tdf(tmp_path / "box2.tdf", rec).read_text(encoding="utf-8") == m.group(1)


# ----------------------------------------------------------------- writing


def test_refuses_overwrite_without_force(tmp_path):
    p = tmp_path / "scaffold.tdf"
    p.write_text("precious")
    with pytest.raises(OutputError, match="already exists"):
        write_tdf(p, _base_record())
    assert p.read_text(encoding="utf-8") == "precious"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["scaffold.tdf"]  # no temp file left
    write_tdf(p, _base_record(), force=True)
    _assert_same(read_tdf(p), _base_record())


@pytest.mark.parametrize("change, phrase", [
    (dict(structure="foam"), "structure must be"),
    (dict(periods=(1.0, 0.0, 1.0)), "> 0"),
    (dict(periods=(1.0, float("nan"), 1.0)), "> 0"),
    (dict(periods=(1.0, 2.0)), "expected 3 period coefficients"),
    (dict(tpms_type="two words"), "one non-empty token"),
    (dict(tpms_type=""), "one non-empty token"),
    (dict(tdf_degrees=(1, 0, 1)), "must be 1..7"),
    (dict(tdf_knots=[[0, 0, 1, 1], [0, 0.5, 1, 1], [0, 0, 1, 1]]), "not clamped"),
    (dict(tbss_knots=[[0, 0, 1, 1], [0, 0, 1], [0, 0, 1, 1]]), "expected 4 knots"),
    (dict(tdf_control=np.full((2, 2, 2), np.inf)), "finite"),
    (dict(tbss_control=np.zeros((2, 2, 2))), "shape"),
    (dict(metadata={"comment": "two\nlines"}), "one line"),
    (dict(metadata={"bad key": "x"}), "metadata key"),
    (dict(version=2), "unsupported TDF version"),
])
def test_invalid_records_are_refused(tmp_path, change, phrase):
    base = _base_record()
    fields = {k: getattr(base, k) for k in (
        "tpms_type", "structure", "periods", "tdf_degrees", "tdf_knots", "tdf_control",
        "tbss_degrees", "tbss_knots", "tbss_control", "tbss_periodic", "metadata", "version")}
    fields.update(change)
    with pytest.raises(InputError, match=re.escape(phrase)):
        TDFRecord(**fields)


def test_writer_revalidates_a_mutated_record(tmp_path):
    rec = _base_record()
    rec.structure = "foam"
    with pytest.raises(InputError, match="structure"):
        write_tdf(tmp_path / "x.tdf", rec)
    assert not (tmp_path / "x.tdf").exists()
    rec.structure = "rod"
    rec.tdf_control = rec.tdf_control.tolist()  # reassigned as nested lists: normalised on writing
    back = read_tdf(write_tdf(tmp_path / "x.tdf", rec))
    assert back.structure == "rod" and np.array_equal(back.tdf_control, _base_record().tdf_control)


# ----------------------------------------------------------------- strict reader


def _mutate(replace=None, delete=(), insert=None, cut=None, raw_tail=None):
    """BASE_LINES edited by 1-based line number (applied: replace, insert before, delete, cut)."""
    lines = list(BASE_LINES)
    for n, text in (replace or {}).items():
        lines[n - 1] = text
    for n, text in sorted((insert or {}).items(), reverse=True):
        lines.insert(n - 1, text)
    for n in sorted(delete, reverse=True):
        del lines[n - 1]
    if cut is not None:
        lines = lines[:cut]
    out = _text(lines)
    if raw_tail is not None:
        out = out[: -1] if raw_tail == "" else out + raw_tail
    return out


MALFORMED = [
    # id, file text, line, phrase
    ("empty", "", 1, "empty file"),
    ("blank-first-line", "\n\n\n", 1, "not a porecad TDF file"),
    ("wrong-magic", _mutate(replace={1: "porecad-tdx 1"}), 1, "not a porecad TDF file"),
    ("no-magic", _mutate(delete=[1]), 1, "not a porecad TDF file"),
    ("wrong-version", _mutate(replace={1: "porecad-tdf 2"}), 1, "unsupported TDF version '2'"),
    ("version-not-int", _mutate(replace={1: "porecad-tdf 1.0"}), 1, "unsupported TDF version"),
    ("ascii-stl", "solid cube\n  facet normal 0 0 1\n", 1, "not a porecad TDF file"),
    # truncated at several points
    ("cut-after-periods", _mutate(cut=10), 10, "unexpected end of file: missing section '#degrees of TDF"),
    ("cut-in-tdf-control", _mutate(cut=17), 17, "unexpected end of file: expected 8 control values"),
    ("cut-mid-line-knots", _mutate(cut=21, replace={21: "0.0 0.0 1.0"}), 21,
     "unexpected end of file: expected 4 knots"),
    ("cut-in-tbss-points", _mutate(cut=36), 36, "expected 24 control point coordinates"),
    ("cut-before-last-knots", _mutate(cut=44), 44, "missing section '#knot vector in w-direction of TBSS'"),
    ("cut-before-end", _mutate(cut=46), 46, "missing section '#end'"),
    ("cut-no-final-newline", _mutate(cut=40, raw_tail="", replace={40: "1.0 1.0"}), 40, "got 23"),
    # wrong counts
    ("two-periods", _mutate(replace={10: "2.0 3.0"}), 10, "expected 3 period coefficients, got 2"),
    ("four-periods", _mutate(replace={10: "2.0 3.0 4.0 5.0"}), 10, "too many values"),
    ("missing-tdf-row", _mutate(delete=[19]), 18, "expected 8 control values, got 6"),
    ("extra-tdf-row", _mutate(insert={20: "0.9 1.0"}), 20, "too many values"),
    ("resolution-larger-than-data", _mutate(replace={14: "3 2 2"}), 19, "expected 12 control values, got 8"),
    ("extra-knot", _mutate(replace={25: "0.0 0.0 0.5 1.0 1.0"}), 25, "too many values"),
    ("missing-knot", _mutate(replace={44: "0.0 0.0 1.0"}), 44, "expected 4 knots"),
    ("two-degrees", _mutate(replace={27: "1 1"}), 27, "expected 3 degrees"),
    # bad tokens
    ("non-numeric", _mutate(replace={17: "0.3 abc"}), 17, "'abc' is not a number"),
    ("underscore-number", _mutate(replace={38: "1.0 0.0 1_0"}), 38, "'1_0' is not a number"),
    ("hex-float", _mutate(replace={16: "0x1p-3 0.2"}), 16, "'0x1p-3' is not a number"),
    ("nan", _mutate(replace={18: "nan 0.6"}), 18, "'nan' is not a finite number"),
    ("inf", _mutate(replace={34: "0.0 -Infinity 1.0"}), 34, "not a finite number"),
    ("inf-period", _mutate(replace={10: "2.0 inf 4.0"}), 10, "not a finite number"),
    ("float-resolution", _mutate(replace={14: "2.0 2 2"}), 14, "'2.0' is not an integer"),
    # absurd or inconsistent sizes
    ("absurd-count", _mutate(replace={14: "100000 100000 100000"}), 14, "more than the limit of 4096 per axis"),
    ("absurd-total", _mutate(replace={31: "4000 4000 4"}), 31, "more than the limit of 50000000"),
    ("negative-count", _mutate(replace={31: "2 -2 2"}), 31, "size in v must be positive, got -2"),
    ("zero-count", _mutate(replace={14: "2 2 0"}), 14, "size in w must be positive, got 0"),
    ("grid-below-degree", _mutate(replace={12: "3 1 1"}), 14, "a degree-3 B-spline needs at least 4"),
    ("degree-0", _mutate(replace={12: "0 1 1"}), 12, "must be 1..7, got 0"),
    ("degree-8", _mutate(replace={27: "1 8 1"}), 27, "must be 1..7, got 8"),
    # knots
    ("decreasing-knots", _mutate(replace={21: "0.0 0.5 0.4 1.0"}), 21, "TDF knot vector u: knots decrease"),
    ("non-clamped-knots", _mutate(replace={23: "0.0 0.1 0.9 1.0"}), 23, "TDF knot vector v: not clamped"),
    ("empty-domain", _mutate(replace={46: "1.0 1.0 1.0 1.0"}), 46, "TBSS knot vector w: empty parameter domain"),
    # sections
    ("unknown-header", _mutate(replace={20: "#knot vector in q-direction of TDF"}), 20, "unknown section header"),
    ("swapped-sections", _mutate(replace={22: BASE_LINES[23], 24: BASE_LINES[21]}), 22, "out of order"),
    ("missing-structure", _mutate(delete=[7, 8]), 7, "out of order: expected '#structure type'"),
    ("repeated-section", _mutate(insert={11: "#period coefficients", 12: "1 1 1"}), 11, "out of order"),
    ("data-before-header", _mutate(replace={3: "1 2 3"}, delete=[4]), 3, "expected section header '#TPMS type'"),
    ("after-end", _mutate(insert={48: "0.5"}), 48, "unexpected content after '#end'"),
    # field values
    ("structure-code", _mutate(replace={8: "1"}), 8, "structure must be 'pore', 'rod' or 'sheet'"),
    ("zero-period", _mutate(replace={10: "2.0 0 4.0"}), 10, "period coefficients must be > 0"),
    ("negative-period", _mutate(replace={10: "-2.0 3.0 4.0"}), 10, "period coefficients must be > 0"),
    ("tpms-two-words", _mutate(replace={6: "G P"}), 6, "expected one word"),
    ("tpms-missing", _mutate(delete=[6]), 6, "expected the TPMS type name"),
    ("periodic-flag-2", _mutate(replace={29: "0 2 0"}), 29, "periodic flags must be 0 or 1"),
    ("metadata-syntax", _mutate(replace={4: "units: mm"}), 4, "expected 'key = value'"),
    ("metadata-twice", _mutate(insert={5: "units = cm"}), 5, "metadata key 'units' given twice"),
]


@pytest.mark.parametrize("text, line, phrase", [c[1:] for c in MALFORMED], ids=[c[0] for c in MALFORMED])
def test_malformed_files(tmp_path, text, line, phrase):
    p = tmp_path / "scaffold.tdf"
    p.write_text(text)
    with pytest.raises(InputError) as info:
        read_tdf(p)
    msg = str(info.value)
    assert msg.startswith(f"{p}:{line}: "), msg
    assert phrase in msg, msg
    assert "\n" not in msg


def test_absurd_count_fails_fast_without_allocating(tmp_path):
    p = tmp_path / "scaffold.tdf"
    p.write_text(_mutate(replace={14: "100000 100000 100000"}))
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(InputError, match=r"scaffold\.tdf:14: .*limit of 4096"):
            read_tdf(p)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 1.0
    assert peak < 2_000_000, peak


def _binary_stl() -> bytes:
    tri = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return b"binary STL written by some CAD tool".ljust(80, b" ") + struct.pack("<I", 200) + tri * 200


@pytest.mark.parametrize("data", [
    np.random.default_rng(3).bytes(4096),
    b"\xff\xfe\x00\x01garbage\n",
    _binary_stl(),
    b"porecad-tdf 1\n#TPMS type\nG\x00\x00\n",
    b"1" * (2 << 20),  # 2 MiB without a newline
    bytes(range(256)) * 8,
], ids=["random-bytes", "invalid-utf8", "binary-stl", "nul-byte", "huge-line", "all-bytes"])
def test_binary_garbage_gives_one_line_error(tmp_path, data):
    p = tmp_path / "scaffold.tdf"
    p.write_bytes(data)
    with pytest.raises(InputError) as info:
        read_tdf(p)
    msg = str(info.value)
    assert re.match(re.escape(str(p)) + r":\d+: ", msg), msg
    assert re.search(r"not a (porecad )?TDF (text )?file|line longer than", msg), msg
    assert "\n" not in msg and len(msg) < 300 + len(str(p))


def test_invalid_utf8_deep_in_a_file_names_its_line(tmp_path):
    # the reader decodes line by line, so a bad byte far down is reported where it is
    rec = _random_record(np.random.default_rng(5), (20, 20, 20), (6, 6, 6))
    p = write_tdf(tmp_path / "scaffold.tdf", rec)
    lines = p.read_bytes().split(b"\n")
    lines[300] = lines[300][:10] + b"\xff" + lines[300][10:]
    p.write_bytes(b"\n".join(lines))
    with pytest.raises(InputError, match=re.escape(f"{p}:301: not a TDF text file (invalid UTF-8")):
        read_tdf(p)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_tdf(tmp_path / "nope.tdf")
    with pytest.raises(InputError, match="is a directory"):
        read_tdf(tmp_path)
