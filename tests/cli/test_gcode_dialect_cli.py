"""Dialects on the command line: `gcode check --dialect`, `init --dialect` and the
study's `[program] dialect`."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from helpers import run_cli as _run

from piecs_bayes.errors import InputError
from piecs_bayes.io import load_study

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "finish.ngc"
FANUC = ROOT / "tests" / "data" / "gcode" / "dialects" / "demo_shaft_fanuc.nc"


def test_check_prints_the_dialect_and_why(capsys):
    rc, text = _run(capsys, ["gcode", "check", FANUC, "--nose-radius", "0.4"])
    assert rc == 0, text
    assert "dialect: fanuc (G98/G99 feed modes, G50, U/W words)" in text
    assert "line 5: G50 S3000: spindle speed clamp recorded" in text
    rc, text = _run(capsys, ["gcode", "check", DEMO, "--nose-radius", "0.4"])
    assert rc == 0 and "dialect: linuxcnc (G7/G8 diameter/radius mode" in text


def test_check_with_a_dialect_that_does_not_fit_refuses_naming_the_line(capsys):
    rc, text = _run(capsys, ["gcode", "check", FANUC, "--dialect", "linuxcnc"])
    assert rc == 2 and len(text.strip().splitlines()) == 1, text
    assert f"{FANUC}:3: G99" not in text  # LinuxCNC reads G99 (a return level) ...
    assert f"{FANUC}:5: G50 is not understood" in text  # ... but not G50
    argv = ["gcode", "check", FANUC, "--dialect", "fanuc", "--rs274", "--nose-radius", "0.4"]
    rc, text = _run(capsys, argv)
    assert rc == 2 and "this program is read as fanuc" in text


def test_init_reads_the_fanuc_demo_shaft_as_the_linuxcnc_one(capsys, tmp_path):
    rc, text = _run(capsys, ["init", FANUC, "--out", tmp_path / "f.toml"])
    assert rc == 0, text
    assert "read as fanuc (the part program's dialect, detected: G98/G99 feed modes" in text
    assert _run(capsys, ["init", DEMO, "--out", tmp_path / "l.toml"])[0] == 0
    fanuc, linuxcnc = load_study(tmp_path / "f.toml"), load_study(tmp_path / "l.toml")
    assert fanuc.program_settings.dialect == "fanuc"
    assert linuxcnc.program_settings.dialect == "linuxcnc"
    assert fanuc.profile.ids == linuxcnc.profile.ids
    for a, b in zip(fanuc.profile.features, linuxcnc.profile.features, strict=True):
        assert math.dist(a.p0, b.p0) < 1e-9 and math.dist(a.p1, b.p1) < 1e-9
    written = (tmp_path / "f.toml").read_text()
    assert 'dialect = "fanuc"' in written


def test_init_with_a_given_dialect_and_the_study_key(capsys, tmp_path):
    rc, text = _run(capsys, ["init", FANUC, "--out", tmp_path / "h.toml", "--dialect", "haas"])
    assert rc == 0, text
    assert "the part program's dialect, as given" in (tmp_path / "h.toml").read_text()
    assert load_study(tmp_path / "h.toml").program_settings.dialect == "haas"
    bad = (tmp_path / "h.toml").read_text().replace('dialect = "haas"', 'dialect = "siemens"')
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(InputError, match=r"program\.dialect.*'siemens'.*'okuma'"):
        load_study(tmp_path / "bad.toml")
    rc, text = _run(capsys, ["init", FANUC, "--out", tmp_path / "x.toml", "--dialect", "siemens"])
    assert rc == 2 and "invalid choice" in text


BAD = {
    "unterminated_sub": ("G18 G21 G8 F1\no100 sub\nG1 X1\nM2\n", 2, "has no o100 endsub"),
    "unknown_label": ("G18 G21 G8 F1\no200 call\nM2\n", 2, "no o200 sub in this program"),
    "division_by_zero": ("G18 G21 G8 F1\n#1 = 0\nG1 X[1 / #1]\nM2\n", 3, "division by zero"),
    "endless_loop": ("G18 G21 G8 F1\no1 while [1]\nG1 X1\no1 endwhile\nM2\n", None,
                     "1,000,000 blocks without ending (inside the loop of line 2)"),
    "nul_byte": ("G18 G21 G8 F1\nG1 X1\x00\nM2\n", 2, "NUL byte"),
    "crlf_refusal": ("G18 G21 G8 F1\r\nG1 X[1/0]\r\nM2\r\n", 2, "division by zero"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD))
def test_refusals_exit_2_with_one_line_naming_the_line(capsys, tmp_path, case):
    text, line, message = BAD[case]
    path = tmp_path / f"{case}.ngc"
    path.write_bytes(text.encode("utf-8", errors="surrogateescape"))
    out = tmp_path / "out.ngc"
    argv = ["gcode", "nose-comp", path, "-o", out, "--nose-radius", "0.4"]
    rc, said = _run(capsys, argv)
    assert rc == 2 and len(said.strip().splitlines()) == 1, said
    assert message in said and "Traceback" not in said and not out.exists()
    if line is not None:
        assert f"{path}:{line}:" in said


def test_ten_megabytes_of_comments_are_read(capsys, tmp_path):
    path = tmp_path / "comments.ngc"
    comment = "(" + "a very long comment " * 50 + ")\n"
    path.write_text("G18 G21 G8 F1\n" + comment * (10_000_000 // len(comment)) + "G1 X1\nM2\n")
    rc, said = _run(capsys, ["gcode", "check", path, "-q"])
    assert rc == 0 and said == "", said
