"""The gauge-study file and its jobs (`jobs.read_gauge_study`, `gauge_type1_study`,
`gauge_rr_study`): the shipped example read and computed, units, and every refusal
naming the file and what is missing (docs/formats.md, "Gauge study")."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from msa_data import AIAG  # tests/msa is on the path

from piecs_bayes.errors import InputError
from piecs_bayes.jobs import gauge_rr_study, gauge_type1_study, read_gauge_study
from piecs_bayes.msa import MsaSettings, gauge_rr, type1_study

EXAMPLE = Path(__file__).resolve().parents[2] / "data" / "gauge" / "gauge.toml"

HEAD = """[gauge]
name = "probe on ring"
tolerance = 0.02
resolution = 0.0001
"""
TYPE1 = """[type1]
readings = "ring.csv"
reference = 40.0
expanded_uncertainty = 0.0004
coverage_factor = 2
"""
GRR = """[grr]
readings = "grr.csv"
appraiser = "setup"
"""


def _ring(n=30, seed=0):
    x = np.random.default_rng(seed).normal(40.0002, 0.0003, n)
    return "reading\n" + "".join(f"{float(v)!r}\n" for v in x), x


def _grr_csv(y, drop=None, extra=None):
    rows = ["part,appraiser,trial,value"]
    p, o, r = y.shape
    for j in range(o):
        for k in range(r):
            for i in range(p):
                if drop != (i, j, k):
                    rows.append(f"P{i + 1},{'ABC'[j]},{k + 1},{float(y[i, j, k])!r}")
    rows += extra or []
    return "\n".join(rows) + "\n"


def _study(tmp_path, toml, ring=None, grr=None) -> Path:
    (tmp_path / "gauge.toml").write_text(toml, encoding="utf-8")
    if ring is not None:
        (tmp_path / "ring.csv").write_text(ring, encoding="utf-8")
    if grr is not None:
        (tmp_path / "grr.csv").write_text(grr, encoding="utf-8")
    return tmp_path / "gauge.toml"


def test_the_shipped_example():
    s = read_gauge_study(EXAMPLE)
    assert s.name == "T9 probe on bore 40 H7" and s.tolerance == 0.025
    assert s.type1.readings.shape == (50,) and s.grr.readings.shape == (10, 3, 3)
    assert s.grr.appraiser_is == "setup" and s.grr.appraisers == ("A", "B", "C")
    assert s.process["temperature"] == pytest.approx(0.0004 / math.sqrt(3))
    t = gauge_type1_study(EXAMPLE)
    assert t.type1.capable and t.budget.u_mp is None and t.budget.q_ms_ok
    g = gauge_rr_study(EXAMPLE)
    assert g.grr.verdict == "acceptable" and g.budget.q_mp_ok and g.type1 is not None
    assert g.capable and repr(g).startswith("GaugeStudy('T9 probe on bore 40 H7', grr)")


def test_a_file_is_the_api(tmp_path):
    ring, x = _ring()
    y = AIAG * 1e-3 + 40.0
    path = _study(tmp_path, HEAD + TYPE1 + GRR, ring, _grr_csv(y))
    t = gauge_type1_study(path)
    direct = type1_study(x, reference=t.type1.reference, tolerance=0.02, resolution=1e-4)
    assert t.type1.cgk == pytest.approx(direct.cgk, rel=1e-12)
    g = gauge_rr_study(path, settings=MsaSettings(grr_basis="study"))
    ref = gauge_rr(y, tolerance=0.02, settings=MsaSettings(grr_basis="study"))
    assert g.grr.pct_grr_study == pytest.approx(ref.pct_grr_study, rel=1e-9)  # sum order
    assert g.grr.parts == tuple(f"P{i}" for i in range(1, 11))


def test_inches_are_read_as_mm(tmp_path):
    ring, _ = _ring()
    toml = HEAD.replace("0.02", "1.0").replace("0.0001", "0.001") + 'units = "in"\n' + TYPE1
    mm = read_gauge_study(_study(tmp_path, toml, ring))
    assert mm.tolerance == 25.4 and mm.resolution == pytest.approx(0.0254)
    assert mm.type1.reference.value == pytest.approx(40.0 * 25.4)


def test_inline_readings_and_spreads(tmp_path):
    x = ", ".join(f"{v:.5f}" for v in np.linspace(39.9995, 40.0005, 25))
    toml = (HEAD + TYPE1.replace('"ring.csv"', f"[{x}]") + "[uncertainty]\n"
            "system = { linearity = { U = 0.0002, k = 2 } }\n")  # fmt: skip
    s = read_gauge_study(_study(tmp_path, toml))
    assert len(s.type1.readings) == 25 and s.system == {"linearity": pytest.approx(0.0001)}


@pytest.mark.parametrize(
    "toml, ring, message",
    [
        (HEAD + TYPE1, _ring(24)[0], "ring.csv: a type-1 study needs at least 25 readings of the reference, got 24"),
        (HEAD + TYPE1.replace("expanded_uncertainty = 0.0004\n", ""), _ring()[0],
         "gauge.toml: \\[type1\\] expanded_uncertainty is missing: the reference's certified U and k"),
        (HEAD + TYPE1.replace("coverage_factor = 2\n", ""), _ring()[0], "\\[type1\\] coverage_factor is missing"),
        (HEAD + TYPE1, "reading\n" + "40.0001\n" * 30, "ring.csv: all 30 readings are equal"),
        (HEAD + TYPE1, "reading\n40.0\nabc\n", "ring.csv:3, column 'reading': not a number: 'abc'"),
        (HEAD + TYPE1, "value\n40.0\n", "ring.csv:1, column 'value': unknown column"),
        (HEAD + TYPE1 + "[grr]\nreadings = 'grr.csv'\n", _ring()[0], "grr.csv: \\[grr\\] readings file not found"),
        (HEAD.replace("tolerance = 0.02\n", "") + TYPE1, _ring()[0], "\\[gauge\\] tolerance is missing"),
        (HEAD + "colour = 'red'\n" + TYPE1, _ring()[0], "\\[gauge\\] unknown key 'colour'"),
        (HEAD, None, "neither a \\[type1\\] nor a \\[grr\\] study"),
        (HEAD + TYPE1 + "[settings]\nk_share = 2.0\n", _ring()[0], "\\[settings\\] msa setting 'k_share'"),
        (HEAD + TYPE1 + "[uncertainty]\nsystem = { heat = 'hot' }\n", _ring()[0],
         "\\[uncertainty\\] system.heat: expected a standard uncertainty"),
        (HEAD + TYPE1 + "[gauge2]\n", _ring()[0], "unknown section \\[gauge2\\]"),
    ],
    ids=["few", "no-U", "no-k", "zero-variance", "not-a-number", "column", "no-file",
         "no-tolerance", "unknown-key", "no-study", "settings", "source", "section"],
)  # fmt: skip
def test_bad_type1_input_names_the_file(tmp_path, toml, ring, message):
    path = _study(tmp_path, toml, ring)
    with pytest.raises(InputError, match=message):
        gauge_type1_study(path)


@pytest.mark.parametrize(
    "csv, message",
    [
        (_grr_csv(AIAG, drop=(6, 2, 1)),
         "grr.csv: part 'P7', setup 'C': 2 trials, the other cells have 3 \\(unbalanced design"),
        (_grr_csv(AIAG[:, :2, :], extra=[f"P{i},C,1,0.1" for i in range(1, 10)]),
         "grr.csv: part 'P10' has no reading by setup 'C': a crossed gauge R&R needs every part"),
        (_grr_csv(AIAG, extra=["P1,A,2,0.5"]), "grr.csv:92: part 'P1', setup 'A', trial 2 read twice \\(also line"),
        (_grr_csv(np.repeat(AIAG[:, :, :1], 3, axis=2)), "grr.csv: every part reads the same in all 3 trials of each setup"),
        (_grr_csv(AIAG[:, :, :1]), "grr.csv: a gauge R&R needs at least 2 trials, got 1"),
        ("part,appraiser,value\n", "grr.csv: a header but no readings"),
        ("part,setup,value\nP1,A,1\n", "grr.csv:1, column 'setup': unknown column"),
    ],
    ids=["unequal-trials", "missing-cell", "twice", "zero-variance", "one-trial", "empty", "column"],
)  # fmt: skip
def test_bad_grr_input_names_the_file(tmp_path, csv, message):
    path = _study(tmp_path, HEAD + GRR, grr=csv)
    with pytest.raises(InputError, match=message):
        gauge_rr_study(path)


def test_a_study_the_file_lacks_is_refused(tmp_path):
    path = _study(tmp_path, HEAD + GRR, grr=_grr_csv(AIAG))
    with pytest.raises(InputError, match="gauge.toml: the file has no \\[type1\\] study"):
        gauge_type1_study(path)
    g = gauge_rr_study(path)
    assert g.budget is None and "no VDA 5 budget" in g.notes[0]


def test_hostile_bytes_and_values_name_the_file(tmp_path):
    ring, _ = _ring()
    path = _study(tmp_path, HEAD + TYPE1, ring)
    (tmp_path / "ring.csv").write_bytes(b"reading\n40.0\xff\n")
    with pytest.raises(InputError, match="ring.csv: \\[type1\\] readings file is not UTF-8 text"):
        gauge_type1_study(path)
    path.write_bytes("\ufeff".encode() + (HEAD + TYPE1).replace("0.02", "nan").encode())
    with pytest.raises(
        InputError, match="gauge.toml: \\[gauge\\] tolerance: expected a number, got nan"
    ):
        read_gauge_study(path)
    path.write_text(HEAD + "[type1\n", encoding="utf-8")
    with pytest.raises(InputError, match="gauge.toml: not valid TOML"):
        read_gauge_study(path)
