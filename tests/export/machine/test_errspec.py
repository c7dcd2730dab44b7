"""Error specification files: native round trip, LinuxCNC comp tables and refusals."""

import json
import re

import numpy as np
import pytest

from piecs_bayes.compensate import CompensationTable, ErrorSpec
from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.export.machine import (
    errspec_texts,
    linuxcnc_comp_text,
    parse_linuxcnc_comp,
    read_errspec,
    read_linuxcnc_comp,
    validate_linuxcnc_comp,
    write_errspec,
    write_linuxcnc_comp,
)


def _x_table(n=5, **kw):
    pos = np.linspace(10.0, 30.0, n)
    c = -0.002 + 0.0001 * (pos - 10.0)  # a diameter error growing with the radius
    args = dict(
        name="x_radius",
        axis="x",
        position_axis="x",
        position=pos,
        correction=c,
        u_correction=np.full(n, 0.0004),
    )
    args.update(kw)
    return CompensationTable(**args)


def _spec():
    z = CompensationTable(
        name="z_vs_x",
        axis="z",
        position_axis="x",
        position=[12.5, 20.0 / 3.0],
        correction=[1e-3 / 3.0, -2.5e-4],
        u_correction=[2e-4, 3e-4],
        correction_reverse=[4e-4, -1e-4],
        u_correction_reverse=[2e-4, 3e-4],
        feature=["F3", "F, 4"],
        description="face position error vs radius",
    )
    return ErrorSpec(tables=(_x_table(), z), description="demo shaft", source={"study": "demo"})


# --------------------------------------------------------------------------- native


def test_native_round_trip_is_exact(tmp_path):
    spec = _spec()
    paths = write_errspec(spec, tmp_path / "demo.errspec.json")
    assert sorted(p.name for p in paths) == [
        "demo.errspec.json",
        "demo.x_radius.csv",
        "demo.z_vs_x.csv",
    ]
    back = read_errspec(tmp_path / "demo.errspec.json")
    assert back.description == "demo shaft" and back.source == {"study": "demo"}
    for a, b in zip(spec.tables, back.tables, strict=True):
        assert (a.name, a.axis, a.position_axis, a.frame) == (
            b.name,
            b.axis,
            b.position_axis,
            b.frame,
        )
        for attr in ("position", "correction", "u_correction"):
            np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr))  # bit-exact
        assert a.feature == b.feature
    z = back.table("z_vs_x")
    assert z.directional and z.feature == ("F, 4", "F3")  # sorted by position
    np.testing.assert_array_equal(z.position, [20.0 / 3.0, 12.5])
    np.testing.assert_array_equal(z.correction_reverse, [-1e-4, 4e-4])


def test_native_files_content():
    files = errspec_texts(_spec(), "part7")
    doc = json.loads(files["part7.errspec.json"])
    assert doc["format"] == "piecs-bayes-errspec" and doc["version"] == 1
    assert doc["units"] == "mm" and doc["x_positions"] == "radius"
    meta = doc["tables"][1]
    assert meta["file"] == "part7.z_vs_x.csv" and meta["rows"] == 2
    assert meta["columns"] == [
        "position",
        "correction",
        "u_correction",
        "correction_reverse",
        "u_correction_reverse",
        "feature",
    ]
    assert files["part7.z_vs_x.csv"].splitlines() == [
        ",".join(meta["columns"]),
        '6.666666666666667,-0.00025,0.0003,-0.0001,0.0003,"F, 4"',
        "12.5,0.0003333333333333333,0.0002,0.0004,0.0002,F3",
    ]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d, c: d.update(version=2), "format version 2 is not supported"),
        (lambda d, c: d.update(format="other"), "format is 'other'"),
        (lambda d, c: d.update(units="inch"), "units must be 'mm'"),
        (lambda d, c: d["tables"][0].update(rows=4), "5 rows, but"),
        (lambda d, c: d["tables"][0].update(axis="y"), "axis must be one of"),
        (lambda d, c: d["tables"][0].update(file="../x.csv"), "plain file name"),
        (lambda d, c: d["tables"][0].pop("rows"), "missing key 'rows' in tables\\[0\\]"),
    ],
)
def test_native_reader_refuses_bad_structure(tmp_path, edit, message):
    write_errspec(_spec(), tmp_path / "s.errspec.json")
    path = tmp_path / "s.errspec.json"
    doc = json.loads(path.read_text())
    edit(doc, None)
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=message):
        read_errspec(path)


@pytest.mark.parametrize(
    "line3, message",
    [
        ("12.0,abc,0.0004", r"s.x_radius.csv:3, column 'correction': not a number: 'abc'"),
        ("12.0,0.001,-0.0004", r":3, column 'u_correction': standard uncertainty -0.0004"),
        ("12.0,nan,0.0004", r":3, column 'correction': 'nan' is not finite"),
        ("12.0,0.001", r":3: 2 cells, expected 3"),
    ],
)
def test_native_reader_names_bad_cells(tmp_path, line3, message):
    write_errspec(_spec(), tmp_path / "s.errspec.json")
    csv_path = tmp_path / "s.x_radius.csv"
    lines = csv_path.read_text().splitlines()
    lines[2] = line3
    csv_path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=message):
        read_errspec(tmp_path / "s.errspec.json")


def test_table_constructor_refuses_nan_and_bad_shapes():
    with pytest.raises(InputError, match=r"correction\[2\] is nan; expected a finite number"):
        _x_table(correction=[0.0, 0.0, float("nan"), 0.0, 0.0])
    with pytest.raises(InputError, match="u_correction has 4 values, position has 5"):
        _x_table(u_correction=[0.1] * 4)
    with pytest.raises(InputError, match="table name"):
        _x_table(name="x table")


# --------------------------------------------------------------------------- LinuxCNC


def test_linuxcnc_known_text_type0_and_type1():
    t = CompensationTable(
        "x", "x", "x", position=[20.0, 10.0], correction=[-0.001, 0.0025], u_correction=[0, 0]
    )
    assert linuxcnc_comp_text(t, comp_type=0) == (
        "10.000000 9.997500 9.997500\n20.000000 20.001000 20.001000\n"
    )
    assert linuxcnc_comp_text(t, comp_type=1, decimals=4) == (
        "10.0000 0.0025 0.0025\n20.0000 -0.0010 -0.0010\n"
    )
    inch = linuxcnc_comp_text(t, comp_type=1, machine_units="inch")
    assert inch.splitlines()[0] == "0.393701 0.000098 0.000098"


_LINE = re.compile(r"^-?\d+\.\d{6} -?\d+\.\d{6} -?\d+\.\d{6}$")


@pytest.mark.parametrize("comp_type", [0, 1])
def test_written_tables_pass_independent_format_checks(tmp_path, comp_type):
    """rs274-independent checks: three plain numbers per line, nothing else, nominal
    strictly ascending, at most 256 rows, and the trims LinuxCNC applies are ours."""
    rng = np.random.default_rng(1)
    pos = np.sort(rng.uniform(0.0, 200.0, 256))
    c = 0.003 * np.sin(pos / 30.0)
    c_rev = c + 0.0015
    t = CompensationTable("x", "x", "x", pos, c, np.full(256, 5e-4), c_rev, np.full(256, 5e-4))
    path = write_linuxcnc_comp(tmp_path / "x.comp", t, comp_type=comp_type)
    raw = path.read_bytes()
    assert raw.endswith(b"\n") and b"\r" not in raw and raw.isascii()
    lines = raw.decode().split("\n")[:-1]
    assert 1 <= len(lines) <= 256
    assert all(_LINE.match(line) for line in lines)
    cols = np.array([[float(v) for v in line.split()] for line in lines])
    assert np.all(np.diff(cols[:, 0]) > 0)
    fwd = cols[:, 0] - cols[:, 1] if comp_type == 0 else cols[:, 1]
    rev = cols[:, 0] - cols[:, 2] if comp_type == 0 else cols[:, 2]
    np.testing.assert_allclose(fwd, c, atol=1.01e-6)
    np.testing.assert_allclose(rev, c_rev, atol=1.01e-6)
    comp = read_linuxcnc_comp(path, comp_type=comp_type)
    assert comp.valid and len(comp) == 256
    # LinuxCNC interpolates linearly and holds the end values
    mid = (pos[:-1] + pos[1:]) / 2
    np.testing.assert_allclose(comp.trim(mid), np.interp(mid, pos, c), atol=2e-6)
    np.testing.assert_allclose(comp.trim([-5.0, 500.0]), [c[0], c[-1]], atol=1e-6)
    np.testing.assert_allclose(comp.trim(mid, reverse=True), np.interp(mid, pos, c_rev), atol=2e-6)


def test_rows_sharing_a_printed_nominal_are_merged():
    pos = np.repeat(np.linspace(0.0, 100.0, 200), 2)  # 400 rows, 200 positions
    pos[1::2] += 1e-8  # below the 1e-6 printing resolution
    c = np.tile([0.001, 0.003], 200)
    u = np.tile([0.001, 0.002], 200)
    text = linuxcnc_comp_text(CompensationTable("x", "x", "x", pos, c, u), comp_type=1)
    lines = text.splitlines()
    assert len(lines) == 200
    # inverse-variance weights 4:1 -> 0.0014
    assert lines[0] == "0.000000 0.001400 0.001400"


@pytest.mark.parametrize(
    "table, message",
    [
        (
            CompensationTable("zx", "z", "x", [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]),
            "corrects z as a function of x.*joint's own position",
        ),
        (
            CompensationTable("p", "x", "x", [0.0, 1.0], [0.0, 0.0], [0.0, 0.0], frame="part"),
            "positions are in part coordinates",
        ),
        (
            CompensationTable(
                "big", "x", "x", np.linspace(0, 300, 300), np.zeros(300), np.zeros(300)
            ),
            "300 rows after merging.*at most 256",
        ),
        (
            CompensationTable("steep", "x", "x", [0.0, 0.001, 1.0], [0.0, -0.002, 0.0], [0] * 3),
            "line 2: forward trim slope -2.*run backwards",
        ),
    ],
    ids=["cross-axis", "part-frame", "too-many-rows", "non-monotone"],
)
def test_linuxcnc_writer_refuses_what_it_cannot_express(table, message):
    with pytest.raises(AnalysisError, match=f"LinuxCNC compensation table for '{table.name}' "):
        linuxcnc_comp_text(table)
    with pytest.raises(AnalysisError, match=message):
        linuxcnc_comp_text(table)


def test_writer_refuses_to_overwrite_an_input(tmp_path):
    src = tmp_path / "probe.csv"
    src.write_text("feature,x,z\n")
    with pytest.raises(InputError, match="refusing to overwrite an input"):
        write_linuxcnc_comp(src, _x_table(), protect=[src])


# --------------------------------------------------------------------------- LinuxCNC reader


@pytest.mark.parametrize(
    "text, loaded, message",
    [
        ("# X axis\n0 0 0\n1 1 1\n", 0, "line 1: '# X axis' is not three numbers; LinuxCNC stops"),
        ("0.0 0.0 0.0\n\n2.0 2.0 2.0\n", 1, "line 2: '' is not three numbers.*ignores 1"),
        ("0.0 0.0 0.0 ; first\n1.0 1.0 1.0\n", 2, "line 1: text after the third number"),
        ("0.0 0.0 0.0\n0x1p1 2.0 2.0\n", 2, "line 2: .*not three plain decimal numbers"),
        ("0.0 0.0 0.0\n2.0 2.0 2.0\n1.0 1.0 1.0\n", 2, "line 3: nominal 1.0 is not above the"),
        ("0.0 0.0 0.0\n1.0 inf 1.0\n", 2, "line 2: non-finite value"),
        ("0.0 0.0\n", 0, "line 1: '0.0 0.0' is not three numbers"),
        ("", 0, "no entry would be loaded"),
    ],
    ids=["header", "blank", "trailing", "hex", "descending", "inf", "two", "empty"],
)
def test_parser_follows_linuxcnc_rules(text, loaded, message):
    comp = parse_linuxcnc_comp(text)
    assert len(comp) == loaded
    assert not comp.valid
    assert any(re.search(message, p) for p in comp.problems), comp.problems
    with pytest.raises(InputError):
        validate_linuxcnc_comp(text)


def test_parser_counts_like_sscanf():
    # sscanf("%lf %lf %lf") reads '1.0-2.0' as two numbers and ignores what follows
    comp = parse_linuxcnc_comp("0.0 0.0 0.0\n1.0 1.0-2.0 junk\n", comp_type=1)
    assert len(comp) == 2
    np.testing.assert_array_equal(comp.columns[1], [1.0, 1.0, -2.0])


def test_parser_drops_entries_beyond_256():
    text = "".join(f"{i}.0 {i}.0 {i}.0\n" for i in range(300))
    comp = parse_linuxcnc_comp(text)
    assert len(comp) == 256
    assert comp.problems[0].startswith("line 257: entry 257 exceeds the 256-entry limit")
    with pytest.raises(InputError, match=r"^x.comp:257: entry 257 exceeds .* \(\+43 more\)"):
        validate_linuxcnc_comp(text, file="x.comp")


def test_type0_and_type1_trims():
    t0 = parse_linuxcnc_comp("0.0 0.01 -0.01\n1.0 1.02 0.98\n", comp_type=0)
    np.testing.assert_allclose(t0.forward_trim, [-0.01, -0.02])  # nominal - forward
    np.testing.assert_allclose(t0.reverse_trim, [0.01, 0.02])
    t1 = parse_linuxcnc_comp("0.0 0.01 -0.01\n1.0 0.02 -0.02\n", comp_type=1)
    np.testing.assert_allclose(t1.forward_trim, [0.01, 0.02])  # the trims themselves
    with pytest.raises(InputError, match="COMP_FILE_TYPE must be 0 or 1"):
        parse_linuxcnc_comp("", comp_type=2)
