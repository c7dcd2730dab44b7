"""The probe reader's fast path reads exactly what the row reader reads.

`read_probe_csv` reads plain rows a column at a time (`io._fastcsv`) and hands
every row it does not vouch for to the row reader; `read_probe_csv_by_rows` is
the row reader alone. Both must give identical arrays (dtype, bits, -0.0) on the
shipped data and on files with every quirk the format allows, and the same
error (type, message, file, line, column, value) for every bad input.
"""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.io import read_probe_csv
from piecs_bayes.io._probe import read_probe_csv_by_rows

ROOT = Path(__file__).resolve().parents[2]
#: the shipped probe files (data/gauge holds a gauge study's readings, not probe points)
SHIPPED = sorted(p for p in (ROOT / "data").glob("*/*.csv") if p.parent.name != "gauge")
FIELDS = ("feature", "points", "lines", "part", "approach", "time", "temperature")


def _same_data(a, b) -> None:
    assert a.file == b.file and len(a) == len(b)
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        if x is None or y is None:
            assert x is None and y is None, f
            continue
        assert x.dtype == y.dtype and x.shape == y.shape, (f, x.dtype, y.dtype)
        if x.dtype.kind == "U":
            assert x.tolist() == y.tolist(), f
        else:
            assert x.tobytes() == y.tobytes(), f  # bit for bit: -0.0, last digits


def _outcome(reader, path, **kw):
    try:
        return reader(path, **kw)
    except Exception as exc:  # the row reader's own errors, whatever they are
        where = (exc.file, exc.line, exc.column, exc.feature, exc.value) if isinstance(
            exc, InputError
        ) else None  # fmt: skip
        return (type(exc), str(exc), where)


def _same(path, **kw):
    """Both readers on `path`: the same data or the same error; returns the outcome."""
    fast = _outcome(read_probe_csv, path, **kw)
    rows = _outcome(read_probe_csv_by_rows, path, **kw)
    if isinstance(rows, tuple):
        assert fast == rows
    else:
        assert not isinstance(fast, tuple), fast
        _same_data(fast, rows)
    return fast


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_files_read_the_same(path):
    out = _same(path)
    assert len(out) > 0
    _same(path, x_mode="radius", units="in", features=tuple(np.unique(out.feature)))


HEAD = "part,feature,x,z,approach_x,approach_z"

QUIRKS = {
    "blank and comment lines": "# c1\n\n{head}\n\n# c2\n  # indented comment\n \t \n{rows}",
    "CRLF": "{head}\r\n{rows}",
    "CR CR LF and no final newline": "{head}\r\r\n{rows}",
    "quoted cells": '{head}\n"p1","dia",26.0,"-5.5",-1,0\n{rows}\n"p,2",dia,"26.1",-6,-1,0\n',
    "spaces around cells": "{head}\n  p1 , dia ,  26.0 , -5 ,-1,0 \n{rows}\np2,dia,26, -7 ,-1 , 0\n",
    "tabs": "{head}\np1\t,dia,\t26.0,-5,-1,0\n{rows}",
    "scientific notation": "{head}\np1,dia,2.6e1,-5E0,-1e+0,0e-5\np1,dia,.26E2,-5.,-1.E0,+0\n{rows}",
    "signs and zeros": "{head}\np1,dia,+26,-0,-0.0,+1.0\np1,dia,0026.000,-.5,-1,-0e3\n{rows}",
    "underscores": "{head}\np1,dia,2_6.0,-5,-1,0\n{rows}",
    "many digits": "{head}\np1,dia,26.0000000000000000000001,-5.12345678901234567890,-1,0\n"
    "p1,dia,9007199254740993,-5,-1,0\np1,dia,1e-300,-5,-1,4.9e-324\n{rows}",
    "upper-case header": "PART,Feature, X ,Z,APPROACH_X,approach_z\n{rows}",
    "trailing cr in cells": "{head}\n{rows}\r\r",
    "form feed in a comment": "# page\x0c 2\n{head}\n{rows}",
}


def _rows(n=40, seed=0):
    rng = random.Random(seed)
    out = []
    for i in range(n):
        feat = ("dia", "face", "fillet_arc")[i // 7 % 3]
        out.append(
            f"part{i // 20:02d},{feat},{rng.uniform(10, 40):.5f},{rng.uniform(-90, 0):.5f}"
            + rng.choice([",-1.000000,0.000000", ",-0.000000,-1.000000", ",0.707107,-0.707107"])
        )
    return "\n".join(out)


def test_long_and_short_strings_to_the_end_of_the_file(tmp_path):
    p = tmp_path / "strings.csv"
    long = "p" * 250
    p.write_text(f"feature,x,z,part\nf,1,2,{long}\nf,1,2,{long}x\nf,1,2,{'q' * 300}\nf,1,2,q")
    out = _same(p)
    assert out.part.tolist() == [long, long + "x", "q" * 300, "q"]


@pytest.mark.parametrize("name", QUIRKS)
def test_quirks_read_the_same(tmp_path, name):
    p = tmp_path / "quirk.csv"
    p.write_bytes(QUIRKS[name].format(head=HEAD, rows=_rows()).encode())
    out = _same(p)
    assert not isinstance(out, tuple), out
    _same(p, features=("dia", "face", "fillet_arc"))


@pytest.mark.parametrize(
    "encoding, data",
    [
        ("utf-8", "\ufeff# Ø 24 mm\nfeature,x,z\ndia,24.0,-5\ndia,24.0,-6\n".encode()),
        ("utf-8", "feature,x,z\nØ24,24.0,-5\ndia,24.0,-6\ndia,24.0,-7\n".encode()),
        ("cp1252", "# Ø 24 mm, 25 °C\nfeature,x,z,temperature\ndia,24.0,-5,25\n".encode("cp1252")),
        ("latin-1", "feature,x,z\ndia,24.0,-5\ndia,24.0,-6\n".encode("latin-1")),
        ("utf-16", "feature,x,z\ndia,24.0,-5\ndia,24.0,-6\n".encode("utf-16")),
    ],
)
def test_encodings_read_the_same(tmp_path, encoding, data):
    p = tmp_path / "enc.csv"
    p.write_bytes(data)
    out = _same(p, encoding=encoding)
    assert not isinstance(out, tuple), out


def _number_cells(seed=3, n=3000):
    """Decimal strings of every shape, and random strings of number characters."""
    rng = random.Random(seed)
    cells = []
    for _ in range(n):
        digits = "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 24)))
        cut = rng.randint(0, len(digits))
        cell = rng.choice(["", "-", "+"]) + digits[:cut] + rng.choice([".", ""]) + digits[cut:]
        if rng.random() < 0.3:
            cell += rng.choice("eE") + rng.choice(["", "-", "+"]) + str(rng.randint(0, 400))
        cells.append(cell)
    for _ in range(n):
        cells.append("".join(rng.choice("0123456789.eE+- _") for _ in range(rng.randint(1, 10))))
    return cells


def _is_number(cell: str) -> bool:
    try:
        return np.isfinite(float(cell.strip()))
    except ValueError:
        return False


def test_numbers_are_python_floats_bit_for_bit(tmp_path):
    cells = [c for c in _number_cells() if _is_number(c)]
    cells += ["0.1", "0.3", "2.675", "1e22", "1e23", "9007199254740992", "9007199254740993",
              "123456789012345678", "4.35", "-0", "5e-324", "1.7976931348623157e308"]  # fmt: skip
    p = tmp_path / "numbers.csv"
    p.write_text("feature,x,z\n" + "".join(f"f,{c},{c}\n" for c in cells))
    out = _same(p, x_mode="radius")
    expect = np.array([float(c) for c in cells])
    assert out.points[:, 1].tobytes() == expect.tobytes()


def test_bad_number_cells_are_named_the_same(tmp_path):
    bad = [c for c in _number_cells(seed=5, n=400) if not _is_number(c)]
    bad = bad[:150] + ["nan", "inf", "-Infinity", "1e400", "", " ", "1,5", "0x10", "1__0"]
    for i, cell in enumerate(bad):
        p = tmp_path / f"bad{i}.csv"
        p.write_text(f"feature,x,z\nf,1.0,2.0\nf,3.0,{cell}\nf,4.0,5.0\n")
        out = _same(p)
        assert isinstance(out, tuple), cell


GOOD = "feature,x,z,approach_x,approach_z\ndia,26.0,-5,-1,0\ndia,26.0,-6,-1,0\n"

BAD_FILES = {
    "missing column": "feature,x\ndia,26\n",
    "column twice": "feature,x,z,x\ndia,26,1,2\n",
    "unknown column": "feature,x,z,colour\ndia,26,1,red\n",
    "empty file": "",
    "only comments": "# one\n\n  # two\n",
    "header only": "feature,x,z\n# no rows\n\n",
    "not a number": GOOD + "dia,26.0,abc,-1,0\n",
    "nan": GOOD + "dia,nan,-5,-1,0\n",
    "overflow": GOOD + "dia,1e999,-5,-1,0\n",
    "empty numeric cell": GOOD + "dia,26.0,,-1,0\n",
    "empty feature cell": GOOD + " ,26.0,-5,-1,0\n",
    "unknown feature": GOOD + "bore,26.0,-5,-1,0\n",
    "too many cells": GOOD + "dia,26.0,-5,-1,0,7\n",
    "too few cells": GOOD + "dia,26.0,-5\n",
    "quoted comma": GOOD + 'dia,"26,0",-5,-1,0\n',
    "zero approach": GOOD + "dia,26.0,-7,0,-0.0\n",
    "approach_x only": "feature,x,z,approach_x\ndia,26,-5,-1\n",
    "cr inside a row": GOOD + "dia,26.0,-7\r,-1,0\n",
    "earlier odd row wins": GOOD + " dia,26.0,x,-1,0\ndia,26.0,y,-1,0\n",
    "earlier plain row wins": GOOD + "dia,26.0,x,-1,0\n dia,26.0,y,-1,0\n",
    "zero approach after a bad cell": GOOD + "dia,26.0,-7,0,0\ndia,26.0,q,-1,0\n",
    "invalid utf-8": b"feature,x,z\ndia,26.0,-5\n\xd8,1,2\n",
}


@pytest.mark.parametrize("name", BAD_FILES)
def test_bad_files_are_named_the_same(tmp_path, name):
    p = tmp_path / "p.csv"
    data = BAD_FILES[name]
    p.write_bytes(data if isinstance(data, bytes) else data.encode())
    out = _same(p, features=("dia", "face"))
    assert isinstance(out, tuple), out


def _big(path: Path, n: int, *, bad_row: int | None = None, quirks: bool = False) -> int:
    """A probe file of `n` data rows after a comment and the header; returns the line of
    data row `bad_row` (1-based), whose z cell is made 'abc'."""
    i = np.arange(n)
    x = np.round(24.0 + 0.001 * (i % 997), 5)
    z = np.round(-300.0 - 0.01 * (i % 7919), 5)
    feats = np.array(["dia", "face", "fillet"])[i // 10 % 3]
    rows = [f"p{k // 70},{f},{a:.5f},{b:.5f},-1.0,0.0" for k, f, a, b in
            zip(i.tolist(), feats.tolist(), x.tolist(), z.tolist(), strict=True)]  # fmt: skip
    if quirks:
        for k in range(5, n, 1013):
            rows[k] = rows[k].replace(",", ", ", 1)
        for k in range(7, n, 2003):
            rows[k] = '"' + rows[k].replace(",", '",', 1)
        for k in range(11, n, 4001):
            rows[k] += "\n# a comment\n"
    lines = ["# big", HEAD, *rows]
    line = None
    if bad_row is not None:
        line = bad_row + 2
        cells = lines[line - 1].split(",")
        cells[3] = "abc"
        lines[line - 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return line


def test_large_file_with_quirks_reads_the_same(tmp_path):
    p = tmp_path / "big.csv"
    _big(p, 60_000, quirks=True)
    out = _same(p, features=("dia", "face", "fillet"))
    assert len(out) == 60_000


def test_bad_cell_deep_in_a_large_file_is_named_exactly(tmp_path):
    p = tmp_path / "big.csv"
    line = _big(p, 600_000, bad_row=500_123)
    assert line == 500_125
    with pytest.raises(InputError) as fast:
        read_probe_csv(p)
    assert str(fast.value) == f"{p}:500125, column 'z': not a number: 'abc'"
    assert (fast.value.line, fast.value.column, fast.value.value) == (500_125, "z", "abc")
    with pytest.raises(InputError) as rows:
        read_probe_csv_by_rows(p)
    assert str(rows.value) == str(fast.value)


def _old_duplicates(probe):
    """`drop_duplicates` as it was (one sort of every row as a record): the reference."""
    key = np.rec.fromarrays([probe.part, probe.feature, probe.points[:, 0], probe.points[:, 1]])
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    dup = np.ones(len(probe), dtype=bool)
    dup[first] = False
    if not dup.any():
        return dup, None
    i = int(np.flatnonzero(dup)[0])
    return dup, (i, int(first[inverse.reshape(-1)[i]]))


@pytest.mark.parametrize("seed", range(6))
def test_duplicates_are_the_ones_a_full_sort_finds(tmp_path, seed):
    import warnings

    from piecs_bayes.io import PlausibilityWarning
    from piecs_bayes.io._plausibility import drop_duplicates

    rng = random.Random(seed)
    vals = ["1.0", "2.0", "0.0", "-0.0", "3.5"]
    rows = [
        f"{rng.choice('ab')},{rng.choice(['dia', 'face'])},{rng.choice(vals)},{rng.choice(vals)}"
        for _ in range(rng.choice([5, 40, 400]))
    ]
    p = tmp_path / "dup.csv"
    p.write_text("part,feature,x,z\n" + "\n".join(rows) + "\n")
    probe = read_probe_csv(p)
    dup, pair = _old_duplicates(probe)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        kept = drop_duplicates(probe)
    assert kept.lines.tolist() == probe.lines[~dup].tolist()
    if pair is None:
        assert kept is probe and not caught
        return
    i, j = pair
    msg = str(caught[0].message)
    assert caught[0].category is PlausibilityWarning
    assert f"dropped {int(dup.sum())} repeated" in msg
    assert (
        f"line {probe.lines[i]} repeats line {probe.lines[j]}, feature '{probe.feature[i]}'" in msg
    )
    with pytest.raises(InputError, match=f"line {probe.lines[i]} repeats line {probe.lines[j]}"):
        drop_duplicates(probe, policy="error")
