"""Expressions: LinuxCNC's operators, precedence and functions, Fanuc macro B's, errors.

Each value is computed by hand from the rules LinuxCNC documents (G-code overview,
"Binary operators": ``**`` before ``* / MOD`` before ``+ -`` before the comparisons
before ``AND OR XOR``, left to right at equal precedence; a sign belongs to the value
after it; EQ/NE within 0.0001) and checked against ``rs274`` where it is installed.
"""

from __future__ import annotations

import math

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import parse_gcode, rs274_path, run_rs274
from piecs_bayes.gcode._expr import (
    FANUC_RULES,
    LINUXCNC_RULES,
    ExpressionError,
    compile_value,
    read_value,
)


def _eval(text: str, rules=LINUXCNC_RULES, params=None) -> float:
    params = dict(params or {})
    node, end = read_value(text, 0)
    assert end == len(text), f"read {text[:end]!r} of {text!r}"

    def get(ref):
        if ref not in params:
            raise ExpressionError(f"#{ref} is not set")
        return params[ref]

    return compile_value(node, rules, get, lambda ref: ref in params)()


LINUXCNC = [
    ("[1 + 2 * 3]", 7.0),
    ("[2 ** 3 ** 2]", 64.0),  # left to right: (2 ** 3) ** 2
    ("[-2 ** 2]", 4.0),  # the sign belongs to the 2
    ("[10 / 4 * 2]", 5.0),
    ("[1 + 2 * 3 - 4 / 2]", 5.0),
    ("[3 - 1 - 1]", 1.0),
    ("[7 MOD 3]", 1.0),
    ("[-7 MOD 3]", 2.0),  # the remainder takes the divisor's sign
    ("[7.5 MOD 2]", 1.5),
    ("[-7.5 MOD -2]", 0.5),
    ("[1 + 2 LT 4]", 1.0),  # 3 < 4: comparisons after + and -
    ("[2 * 3 GT 5 + 1]", 0.0),  # 6 > 6
    ("[1 EQ 1.00001]", 1.0),  # EQ within 0.0001
    ("[1 NE 1.00001]", 0.0),
    ("[1 GE 1.00001]", 0.0),  # GE/GT/LE/LT exact
    ("[1 LT 1.00001]", 1.0),
    ("[2 AND 0 OR 1]", 1.0),  # (2 AND 0) OR 1
    ("[1 XOR 1 + 1]", 0.0),  # 1 XOR 2: both true
    ("[3 GT 2 AND 1 LT 0]", 0.0),  # AND after the comparisons
    ("[0 OR 0.5]", 1.0),
    ("[2 * -3]", -6.0),
    ("[2--1]", 3.0),
    ("[-[3]]", -3.0),
    ("[1+-+2]", -1.0),
    ("ATAN[1]/[1]", 45.0),
    ("ATAN[1]/[-1]", 135.0),
    ("SIN[30]", 0.5),
    ("COS[60]", 0.5),
    ("TAN[45]", 1.0),
    ("ACOS[0]", 90.0),
    ("ASIN[1]", 90.0),
    ("[SQRT[9] + ABS[-2]]", 5.0),
    ("[EXP[0] + LN[1]]", 1.0),
    ("FIX[-1.5]", -2.0),
    ("FUP[1.2]", 2.0),
    ("ROUND[2.5]", 3.0),
    ("ROUND[-2.5]", -3.0),  # halves away from zero
    ("ROUND[0.4]", 0.0),
    ("[#1 * #2]", 12.0),
    ("[#<a> + #<_b>]", 3.5),
    ("##3", 3.0),  # #3 holds 1: the value of #1
    ("#[1 + 2]", 1.0),
    ("[EXISTS[#<a>] + EXISTS[#<zz>]]", 1.0),
]
PARAMS = {1: 3.0, 2: 4.0, 3: 1.0, "a": 1.5, "_b": 2.0}


@pytest.mark.parametrize("text, value", LINUXCNC)
def test_linuxcnc_expressions(text, value):
    assert _eval(text, params=PARAMS) == pytest.approx(value, abs=1e-12)


FANUC = [
    ("[1 + 2 * 3]", 7.0),
    ("[6 AND 3]", 2.0),  # bitwise on whole numbers
    ("[4 OR 1]", 5.0),
    ("[6 XOR 3]", 5.0),
    ("[1 + 6 AND 3]", 3.0),  # AND ranks with *: 1 + (6 AND 3)
    ("[2 * 3 OR 1]", 7.0),  # OR ranks with +: (2 * 3) OR 1
    ("[[#1 GT 2] AND [#2 LT 5]]", 1.0),
    ("[#1 GT 2 OR 8]", 0.0),  # 3 > (2 OR 8) = 3 > 10
]


@pytest.mark.parametrize("text, value", FANUC)
def test_fanuc_macro_b_expressions(text, value):
    assert _eval(text, FANUC_RULES, PARAMS) == pytest.approx(value, abs=1e-12)


@pytest.mark.parametrize(
    "text, message",
    [
        ("[1 / 0]", "division by zero"),
        ("[1 MOD 0]", "division by zero"),
        ("SQRT[-1]", "square root of a negative number"),
        ("LN[0]", "logarithm"),
        ("ACOS[2]", "outside [-1, 1]"),
        ("[-8 ** 0.5]", "fractional power"),
        ("#9", "not set"),
    ],
)
def test_evaluation_errors_say_why(text, message):
    with pytest.raises(ExpressionError, match=message.replace("[", r"\[")):
        _eval(text, params=PARAMS)


def test_bitwise_fanuc_operators_want_whole_numbers():
    with pytest.raises(ExpressionError, match="whole numbers"):
        _eval("[1.5 AND 1]", FANUC_RULES)


@pytest.mark.parametrize(
    "text, message",
    [
        ("[1 + ]", "unexpected"),
        ("[1 2]", "unexpected"),
        ("FOO[1]", "unknown function"),
        ("[1 + 2", "not closed"),
        ("ATAN[1]", "two values"),
        ("#<a", "without '>'"),
        ("#1.5", "not a whole number"),
    ],
)
def test_syntax_errors_say_where(text, message):
    with pytest.raises(ExpressionError, match=message) as exc:
        read_value(text, 0)
    assert exc.value.pos is not None


def test_an_expression_error_in_a_program_names_the_file_line_and_word():
    text = "G18 G21 G8 F100\n#1 = 0\nG1 X[2 / #1] Z0\nM2\n"
    with pytest.raises(InputError) as exc:
        parse_gcode(text, name="div.ngc")
    assert exc.value.line == 3 and exc.value.file == "div.ngc"
    assert "word X[2 / #1]: division by zero" in str(exc.value)


@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
def test_rs274_computes_the_same_values():
    cases = [t for t, _ in LINUXCNC if "#" not in t]
    lines = [f"G1 X{t if t.startswith('[') else '[' + t + ']'} Z0" for t in cases]
    text = "G18 G21 G8 F100\n" + "\n".join(lines) + "\nM2\n"
    ref = run_rs274(text)
    assert ref.error is None, ref.error
    got = [m.end[0] for m in ref.moves]
    want = [v for t, v in LINUXCNC if "#" not in t]
    assert got == pytest.approx(want, abs=1e-4)
    assert [m.end[0] for m in parse_gcode(text).moves] == pytest.approx(want, abs=1e-12)
    assert math.isfinite(sum(got))
