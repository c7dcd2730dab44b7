"""``piecs-bayes gcode nose-comp`` / ``gcode check``: outputs, exit codes, no overwrite."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from piecs_bayes.cli import _gcode as _cli_gcode
from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.gcode import nose_compensate, read_gcode, read_tool_table, rs274_path

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
PROGRAM = DATA / "01_od_dia_mm_t3_g42.ngc"
TABLE = DATA / "tools.tbl"


class _Console:
    def __init__(self):
        self.lines: list[str] = []

    def say(self, msg: str) -> None:
        self.lines.append(msg)

    step = say


def _run(argv):
    parser = argparse.ArgumentParser(prog="piecs-bayes")
    _cli_gcode.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    console = _Console()
    return args.func(args, console), console


def _main(argv):
    from piecs_bayes.cli import main

    return main(argv)


def test_nose_comp_writes_the_library_result(tmp_path):
    out = tmp_path / "out.ngc"
    argv = ["gcode", "nose-comp", str(PROGRAM), "-o", str(out)]
    rc, console = _run(argv + ["--tool-table", str(TABLE), "--tool-units", "in"])
    assert rc == 0 and out.exists()
    expected = nose_compensate(read_gcode(PROGRAM), tool_table=read_tool_table(TABLE, units="in"))
    assert out.read_text() == expected.text
    assert any("lines rewritten" in line for line in console.lines)
    rc, _ = _run(argv + ["--nose-radius", "0.4", "--corner", "extend"])
    assert rc == 0 and "G42 G1" not in out.read_text()


def test_nose_comp_errors(tmp_path):
    out = tmp_path / "out.ngc"
    with pytest.raises(InputError, match="tool table"):
        _run(["gcode", "nose-comp", str(PROGRAM), "-o", str(out)])
    with pytest.raises(AnalysisError, match="concave corner"):
        gouge = DATA / "gouge" / "g02_groove_too_narrow.ngc"
        _run(["gcode", "nose-comp", str(gouge), "-o", str(out), "--nose-radius", "0.4"])
    copy = tmp_path / "in.ngc"
    copy.write_bytes(PROGRAM.read_bytes())
    with pytest.raises(InputError, match="refusing to overwrite"):
        _run(["gcode", "nose-comp", str(copy), "-o", str(copy), "--nose-radius", "0.4"])
    assert copy.read_bytes() == PROGRAM.read_bytes()


def test_exit_codes_through_main(tmp_path, capsys):
    try:
        from piecs_bayes.cli import build_parser

        build_parser().parse_args(["gcode", "check", str(PROGRAM)])
    except SystemExit:
        pytest.skip("the gcode commands are not wired into piecs_bayes.cli")
    out = str(tmp_path / "o.ngc")
    assert _main(["gcode", "nose-comp", str(PROGRAM), "-o", out, "-q"]) == 2
    gouge = str(DATA / "gouge" / "g02_groove_too_narrow.ngc")
    assert _main(["gcode", "nose-comp", gouge, "-o", out, "--nose-radius", "0.4"]) == 1
    assert _main(["gcode", "nose-comp", str(PROGRAM), "-o", out, "--nose-radius", "0.4"]) == 0
    err = capsys.readouterr().err
    assert "g02_groove_too_narrow.ngc:10" in err


def test_check_prints_what_was_read():
    rc, console = _run(["gcode", "check", str(PROGRAM), "--nose-radius", "0.4"])
    assert rc == 0
    text = "\n".join(console.lines)
    assert "G42 nose on the right of travel" in text
    assert "feed  to (x=10.0000, z=-15.0000) mm radius [G42]" in text
    assert "compensated path: 15 moves" in text


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
def test_check_against_rs274():
    argv = ["gcode", "check", str(PROGRAM), "--tool-table", str(TABLE), "--tool-units", "in"]
    rc, console = _run(argv + ["--rs274"])
    assert rc == 0 and "rs274 agrees: 15 canonical moves" in console.lines[-1]


# an OD contour with G41 (the material side, issue 42), and left behind the part (untold)
OD_G41 = """G18 G21 G7 G90 G40
G0 X30 Z5
G41 G1 X16 Z1 F0.2
G1 X20 Z-1
G1 Z-15
G1 X26 Z-25
G1 Z-35
G1 X32
G40 G0 X40
G0 Z5
M30
"""
UNTOLD = OD_G41.replace("G41", "G42").replace("G40 G0 X40\nG0 Z5\n", "G40 G0 X40 Z-40\n")


def test_nose_comp_refuses_g41_on_the_material_side(tmp_path, capsys):
    program, out = tmp_path / "od_g41.ngc", tmp_path / "out.ngc"
    program.write_text(OD_G41)
    assert _main(["gcode", "nose-comp", str(program), "-o", str(out), "--nose-radius", "0.4"]) == 2
    err = capsys.readouterr().err
    assert f"error: {program}:3: G41 (line 3) puts the tool nose left of travel, below" in err
    assert "the exit move (line 9) passes above the contour at X40.0000 Z-35.0000" in err
    assert "use G42" in err and not out.exists()
    program.write_text(OD_G41.replace("G41", "G42"))
    assert _main(["gcode", "nose-comp", str(program), "-o", str(out), "--nose-radius", "0.4"]) == 0
    assert out.exists() and "G42" not in out.read_text()


def test_a_side_the_moves_do_not_tell(tmp_path, capsys):
    """`check` warns and says why; `nose-comp --kind auto` refuses naming --kind; said
    with --kind, it is resolved."""
    from piecs_bayes.gcode import MaterialSideWarning

    program, out = tmp_path / "untold.ngc", tmp_path / "out.ngc"
    program.write_text(UNTOLD)
    with pytest.warns(MaterialSideWarning) as caught:
        rc, console = _run(["gcode", "check", str(program), "--nose-radius", "0.4"])
    assert rc == 0 and len(caught) == 1
    warning = str(caught[0].message)
    assert warning.startswith(f"gcode nose-comp --kind auto refuses this run: {program}:3: G42")
    assert "no move in air passes beside it" in warning and "--kind external" in warning
    assert (
        "  material side: G42 (line 3), contour lines 4-8: no move in air passes beside it: "
        "the side is not told"
    ) in console.lines
    argv = ["gcode", "nose-comp", str(program), "-o", str(out), "--nose-radius", "0.4"]
    assert _main(argv) == 2
    err = capsys.readouterr().err
    assert f"{program}:3: G42 (line 3), contour lines 4-8: no move in air" in err
    assert "say where it is: --kind external" in err and not out.exists()
    assert _main([*argv, "--kind", "external"]) == 0 and out.exists()


def test_check_says_the_side_the_moves_tell():
    rc, console = _run(["gcode", "check", str(PROGRAM), "--nose-radius", "0.4"])
    assert rc == 0
    (line,) = [ln for ln in console.lines if "material side" in ln]
    assert line == (
        "  material side: G42 (line 6), contour lines 7-16: the exit move (line 17) passes "
        "above the contour at X49.5046 Z0.8716 (mm, X a diameter), across from line 7: an "
        "OD (material between the contour and the axis); G42 agrees"
    )
