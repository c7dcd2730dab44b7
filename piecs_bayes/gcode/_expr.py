"""Expressions of part programs: `[...]`, parameters and functions, read and evaluated.

[`read_value`][] reads a value where a word's number would stand (``12.5``, ``#1``,
``#<name>``, ``[#1 + 2]``, ``-#3``, ``SIN[30]``) into a syntax tree; [`read_bare`][]
reads the right side of an assignment, which Fanuc writes without brackets. The tree is
made once per line; [`compile_value`][] turns it into a function of the parameters
under a dialect's [`Rules`][] (operator precedence: LinuxCNC's or Fanuc's), checked
against LinuxCNC's ``rs274``. Every failure is an [`ExpressionError`][] with the text
it concerns (division by zero, a square root of a negative number, an unknown function).

The operators, functions and their rules: docs/models/part_programs.md, "Expressions".
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

_NUMBER = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)")
_NAME = re.compile(r"[A-Za-z]+")
_OPS = ("**", "*", "/", "+", "-")
_WORD_OPS = ("MOD", "EQ", "NE", "GT", "GE", "LT", "LE", "AND", "OR", "XOR")
FUNCTIONS = {
    "ABS",
    "ACOS",
    "ASIN",
    "ATAN",
    "COS",
    "EXP",
    "FIX",
    "FUP",
    "ROUND",
    "LN",
    "SIN",
    "SQRT",
    "TAN",
    "EXISTS",
}
# LinuxCNC's EQ and NE compare within this (rs274ngc TOLERANCE_EQUAL); GT/GE/LT/LE do not
EQUAL_TOLERANCE = 0.0001


class ExpressionError(Exception):
    """An expression that cannot be read or evaluated; ``pos`` is the column (0-based)
    where reading stopped, None for evaluation errors."""

    def __init__(self, msg: str, pos: int | None = None):
        super().__init__(msg)
        self.pos = pos


@dataclass(frozen=True)
class Rules:
    """How a dialect evaluates: binary operator precedence (higher binds tighter; equal
    precedence is left-associative) and whether AND/OR/XOR are logical (LinuxCNC) or
    bitwise on whole numbers (Fanuc macro B)."""

    name: str
    precedence: tuple[tuple[str, int], ...]
    logical: bool = True

    def rank(self, op: str) -> int:
        return dict(self.precedence)[op]


LINUXCNC_RULES = Rules(
    "linuxcnc",
    (
        ("**", 6),
        ("*", 5),
        ("/", 5),
        ("MOD", 5),
        ("+", 4),
        ("-", 4),
        *((op, 3) for op in ("EQ", "NE", "GT", "GE", "LT", "LE")),
        ("AND", 2),
        ("OR", 2),
        ("XOR", 2),
    ),
)
# Fanuc macro B: AND with the multiplicative operators, OR/XOR with the additive ones,
# comparisons below them (Fanuc 0i-TF operator's manual, "Arithmetic and logic operation")
FANUC_RULES = Rules(
    "fanuc",
    (
        ("**", 6),
        ("*", 5),
        ("/", 5),
        ("MOD", 5),
        ("AND", 5),
        ("+", 4),
        ("-", 4),
        ("OR", 4),
        ("XOR", 4),
        *((op, 3) for op in ("EQ", "NE", "GT", "GE", "LT", "LE")),
    ),
    logical=False,
)


# -- syntax tree -------------------------------------------------------------------------


@dataclass(frozen=True)
class Num:
    value: float


@dataclass(frozen=True)
class Param:
    """``#12`` (ref 12), ``#<name>`` (ref "name", lower case, blanks removed), ``##1`` or
    ``#[expr]`` (ref a node: the number is computed)."""

    ref: object


@dataclass(frozen=True)
class Unary:
    op: str
    operand: object


@dataclass(frozen=True)
class Func:
    name: str
    args: tuple


@dataclass(frozen=True)
class Group:
    """``[a op b op c]``: operands and operators in order; precedence is the dialect's."""

    items: tuple


def _skip(text: str, i: int) -> int:
    n = len(text)
    while i < n and text[i] in " \t":
        i += 1
    return i


def read_param_ref(text: str, i: int) -> tuple[Param, int]:
    """Read ``#...`` at ``i`` (which holds ``#``)."""
    j = _skip(text, i + 1)
    if j < len(text) and text[j] == "<":
        k = text.find(">", j + 1)
        if k < 0:
            raise ExpressionError("'#<' without '>'", j)
        name = "".join(text[j + 1 : k].split()).lower()
        if not name:
            raise ExpressionError("a parameter name is empty", j)
        return Param(name), k + 1
    if j < len(text) and text[j] in "#[":
        node, end = read_value(text, j)
        return Param(node), end
    m = _NUMBER.match(text, j)
    if m is None:
        raise ExpressionError("'#' is not followed by a parameter number, name or [...]", j)
    if "." in m.group():
        raise ExpressionError(f"parameter number #{m.group()} is not a whole number", j)
    return Param(int(m.group())), m.end()


def read_value(text: str, i: int) -> tuple[object, int]:
    """A value at ``i``: a number, a parameter, ``[...]``, a signed value or a function.

    **Returns:** the node and the index after it. Raises :class:`ExpressionError`.
    """
    i = _skip(text, i)
    if i >= len(text):
        raise ExpressionError("a value is missing", i)
    ch = text[i]
    if ch == "[":
        return _read_group(text, i)
    if ch == "#":
        return read_param_ref(text, i)
    if ch in "+-":
        m = _NUMBER.match(text, i + 1)
        if m is not None:
            v = float(m.group())
            return Num(-v if ch == "-" else v), m.end()
        node, end = read_value(text, i + 1)
        return (Unary(ch, node) if ch == "-" else node), end
    m = _NUMBER.match(text, i)
    if m is not None:
        return Num(float(m.group())), m.end()
    m = _NAME.match(text, i)
    if m is not None:
        name = m.group().upper()
        if name not in FUNCTIONS:
            raise ExpressionError(f"unknown function or word {m.group()!r}", i)
        j = _skip(text, m.end())
        if j >= len(text) or text[j] != "[":
            raise ExpressionError(f"function {name} needs [...]", j)
        if name == "EXISTS":
            k = _skip(text, j + 1)
            if k >= len(text) or text[k] != "#":
                raise ExpressionError("EXISTS needs a parameter: EXISTS[#<name>]", k)
            ref, k = read_param_ref(text, k)
            k = _skip(text, k)
            if k >= len(text) or text[k] != "]":
                raise ExpressionError("EXISTS[...] is not closed", k)
            return Func(name, (ref,)), k + 1
        if name == "ATAN":
            a, k = _read_group(text, j, allow_comma=True)
            if isinstance(a, tuple):  # Fanuc 30i ATAN[a, b]
                return Func(name, a), k
            k2 = _skip(text, k)
            if k2 >= len(text) or text[k2] != "/":
                raise ExpressionError("ATAN needs two values: ATAN[a]/[b]", k2)
            k3 = _skip(text, k2 + 1)
            if k3 >= len(text) or text[k3] != "[":
                raise ExpressionError("ATAN needs two values: ATAN[a]/[b]", k3)
            b, k = _read_group(text, k3)
            return Func(name, (a, b)), k
        arg, k = _read_group(text, j)
        return Func(name, (arg,)), k
    raise ExpressionError(f"unexpected {ch!r} where a value should be", i)


def _read_op(text: str, i: int) -> tuple[str | None, int]:
    i = _skip(text, i)
    for op in _OPS:
        if text.startswith(op, i):
            return op, i + len(op)
    m = _NAME.match(text, i)
    if m is not None and m.group().upper() in _WORD_OPS:
        return m.group().upper(), m.end()
    return None, i


def _read_items(text: str, j: int, start: int, ends: str) -> tuple[object, int, str]:
    """Values and operators from ``j`` up to one of ``ends``; the node, the index after
    the terminator and the terminator."""
    items: list = []
    while True:
        node, j = read_value(text, j)
        items.append(node)
        k = _skip(text, j)
        if k < len(text) and text[k] in ends:
            return (items[0] if len(items) == 1 else Group(tuple(items))), k + 1, text[k]
        op, j2 = _read_op(text, j)
        if op is None:
            if k >= len(text):
                raise ExpressionError("'[' is not closed", start)
            raise ExpressionError(f"unexpected {text[k]!r} in an expression", k)
        items.append(op)
        j = j2


def _read_group(text: str, i: int, *, allow_comma: bool = False):
    """``[ ... ]`` at ``i``; with ``allow_comma``, ``[a, b]`` gives a tuple of two nodes."""
    node, k, end = _read_items(text, i + 1, i, "]," if allow_comma else "]")
    if end == ",":
        second, k, _ = _read_items(text, k, i, "]")
        return (node, second), k
    return node, k


def read_bare(text: str, i: int) -> tuple[object, int]:
    """An expression without brackets (``#1 = #2 + 3``): values and operators up to the
    first thing that is neither."""
    node, j = read_value(text, i)
    items = [node]
    while True:
        op, j2 = _read_op(text, j)
        if op is None:
            break
        # "-" directly before a word letter is not an operator here: stop
        node, j = read_value(text, j2)
        items += [op, node]
    return (items[0] if len(items) == 1 else Group(tuple(items))), j


# -- evaluation -------------------------------------------------------------------------


def _fix(v: float) -> float:
    return float(math.floor(v))


def _round(v: float) -> float:
    return float(math.floor(v + 0.5) if v >= 0 else -math.floor(-v + 0.5))


def _checked(name: str, fn: Callable[[float], float], ok: Callable[[float], bool], why: str):
    def f(v: float) -> float:
        if not ok(v):
            raise ExpressionError(f"{name}[{v:g}]: {why}")
        return fn(v)

    return f


_UNARY = {
    "ABS": abs,
    "ACOS": _checked(
        "ACOS", lambda v: math.degrees(math.acos(v)), lambda v: -1 <= v <= 1, "outside [-1, 1]"
    ),
    "ASIN": _checked(
        "ASIN", lambda v: math.degrees(math.asin(v)), lambda v: -1 <= v <= 1, "outside [-1, 1]"
    ),
    "COS": lambda v: math.cos(math.radians(v)),
    "SIN": lambda v: math.sin(math.radians(v)),
    "TAN": lambda v: math.tan(math.radians(v)),
    "EXP": math.exp,
    "FIX": _fix,
    "FUP": lambda v: float(math.ceil(v)),
    "ROUND": _round,
    "LN": _checked("LN", math.log, lambda v: v > 0, "the logarithm of a number <= 0"),
    "SQRT": _checked("SQRT", math.sqrt, lambda v: v >= 0, "the square root of a negative number"),
}


def _as_int(v: float, op: str) -> int:
    if v != int(v):
        raise ExpressionError(f"{op} on {v:g}: Fanuc's {op} takes whole numbers")
    return int(v)


def _binary(op: str, logical: bool) -> Callable[[float, float], float]:
    if op == "+":
        return lambda a, b: a + b
    if op == "-":
        return lambda a, b: a - b
    if op == "*":
        return lambda a, b: a * b
    if op == "/":

        def div(a: float, b: float) -> float:
            if b == 0.0:
                raise ExpressionError(f"division by zero ({a:g} / 0)")
            return a / b

        return div
    if op == "MOD":

        def mod(a: float, b: float) -> float:
            if b == 0.0:
                raise ExpressionError(f"division by zero ({a:g} MOD 0)")
            r = math.fmod(a, b)
            return r + abs(b) if r < 0 else r

        return mod
    if op == "**":

        def power(a: float, b: float) -> float:
            if a < 0 and b != int(b):
                raise ExpressionError(f"{a:g} ** {b:g}: a negative number to a fractional power")
            if a == 0 and b < 0:
                raise ExpressionError(f"0 ** {b:g}: division by zero")
            return a**b

        return power
    cmp = {
        "EQ": lambda a, b: abs(a - b) < EQUAL_TOLERANCE,
        "NE": lambda a, b: abs(a - b) >= EQUAL_TOLERANCE,
        "GT": lambda a, b: a > b,
        "GE": lambda a, b: a >= b,
        "LT": lambda a, b: a < b,
        "LE": lambda a, b: a <= b,
    }
    if op in cmp:
        c = cmp[op]
        return lambda a, b: 1.0 if c(a, b) else 0.0
    if logical:
        return {
            "AND": lambda a, b: 1.0 if (a != 0.0 and b != 0.0) else 0.0,
            "OR": lambda a, b: 1.0 if (a != 0.0 or b != 0.0) else 0.0,
            "XOR": lambda a, b: 1.0 if ((a != 0.0) != (b != 0.0)) else 0.0,
        }[op]
    bit = {"AND": int.__and__, "OR": int.__or__, "XOR": int.__xor__}[op]
    return lambda a, b: float(bit(_as_int(a, op), _as_int(b, op)))


#: ``params(ref) -> float`` reads a parameter; ``exists(ref) -> bool`` for EXISTS
Reader = Callable[[object], float]


def compile_value(node, rules: Rules, params: Reader, exists: Callable[[object], bool]):
    """A function of no arguments that evaluates ``node`` now, with ``params`` reading
    parameters (a reference is a number, a lower-case name, or a node to evaluate)."""
    if isinstance(node, Num):
        v = node.value
        return lambda: v
    if isinstance(node, Param):
        ref = node.ref
        if isinstance(ref, (int, str)):
            return lambda: params(ref)
        inner = compile_value(ref, rules, params, exists)

        def indirect() -> float:
            v = inner()
            if v != int(v):
                raise ExpressionError(f"parameter number {v:g} is not a whole number")
            return params(int(v))

        return indirect
    if isinstance(node, Unary):
        f = compile_value(node.operand, rules, params, exists)
        return lambda: -f()
    if isinstance(node, Func):
        if node.name == "EXISTS":
            ref = node.args[0].ref
            return lambda: 1.0 if exists(ref) else 0.0
        if node.name == "ATAN":
            a = compile_value(node.args[0], rules, params, exists)
            b = compile_value(node.args[1], rules, params, exists)
            return lambda: math.degrees(math.atan2(a(), b()))
        fn = _UNARY[node.name]
        arg = compile_value(node.args[0], rules, params, exists)
        return lambda: fn(arg())
    if isinstance(node, Group):
        return _compile_group(node.items, rules, params, exists)
    raise ExpressionError(f"cannot evaluate {node!r}")  # pragma: no cover


def _compile_group(items, rules, params, exists):
    ranks = dict(rules.precedence)
    for op in items[1::2]:
        if op not in ranks:
            raise ExpressionError(f"operator {op} is not part of {rules.name}'s expressions")
    operands = [compile_value(n, rules, params, exists) for n in items[0::2]]
    ops = list(items[1::2])
    # precedence climbing over the flat list (left-associative at equal rank)
    pos = 0

    def climb(min_rank: int):
        nonlocal pos
        left = operands[pos]
        while pos < len(ops) and ranks[ops[pos]] >= min_rank:
            op = ops[pos]
            pos += 1
            right = climb(ranks[op] + 1)
            left = _apply(_binary(op, rules.logical), left, right)
        return left

    return climb(0)


def _apply(fn, left, right):
    return lambda: fn(left(), right())
