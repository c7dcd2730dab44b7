r"""Fanuc's ``DPRNT`` statement: its format, read from a program, and the line it prints.

``DPRNT[X#5061[44]*Z#5062[44]]`` prints, on one line: the text ``X``, the value of
``#5061`` with 4 integer digits and 4 decimals, a blank for ``*``, the text ``Z``, the
value of ``#5062``. :func:`parse_dprnt` reads the format ([`DprntFormat`][], whose
``render`` prints a line); :func:`dprnt_value` prints one value with ``[ab]`` (parameter
PRT = 0): a field of ``a + 1`` characters holding the integer digits right-aligned
without leading zeros (one ``0`` for an integer part of zero) with ``-`` directly
before them when negative, then ``.`` and exactly ``b`` decimals (Python's
``f"{v:.{b}f}"``; a value that rounds to zero has no sign). So ``[44]`` prints ``12.5``
as ``"   12.5000"``. A value with more than ``a`` integer digits is refused (the
control would print a wrong number). Lines end with ``"\n"``; the control codes that
``POPEN`` / ``PCLOS`` send are not written.

The gauging programs and their files: docs/models/gauging.md.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..errors import InputError

#: the variables a DPRNT of a gauging program may print: the skip positions
SKIP_VARIABLES = {5061: "X", 5062: "Z"}
_ITEM = re.compile(r"#(\d+)\[(\d)(\d)\]")


@dataclass(frozen=True)
class DprntFormat:
    """One ``DPRNT[...]``: ``items`` in order, each ``("text", s)`` (``*`` already a
    blank) or ``("var", number, digits, decimals)``; its source ``line`` and text."""

    line: int
    text: str
    items: tuple[tuple, ...]

    def render(self, values: dict[int, float]) -> str:
        """The printed line (without its ending) for the variables' `values`
        (program units; #5061 as the control's X mode says)."""
        out = []
        for item in self.items:
            if item[0] == "text":
                out.append(item[1])
            else:
                _, var, a, b = item
                out.append(dprnt_value(values[var], a, b, what=f"#{var}[{a}{b}]"))
        return "".join(out)


def dprnt_value(value: float, digits: int, decimals: int, *, what: str = "value") -> str:
    """`value` as DPRNT prints it with ``[digits decimals]`` (module docstring)."""
    text = f"{abs(value):.{decimals}f}"
    whole = text.split(".")[0]
    if len(whole) > digits:
        raise InputError(
            f"DPRNT {what}: {value:g} has more than {digits} integer digits; the control "
            "would print it wrong (widen the format)",
            value=value,
        )
    negative = value < 0 and text.strip("0.") != ""
    sign = "-" if negative else ""
    field = (sign + whole).rjust(digits + 1)
    return field + ("." + text.split(".")[1] if decimals > 0 else ".")


def parse_dprnt(body: str, *, line: int, text: str, name: str | None) -> DprntFormat:
    """The format of ``DPRNT[body]`` (``body`` between the outer brackets)."""
    items: list[tuple] = []
    i = 0
    while i < len(body):
        ch = body[i]
        if ch == "#":
            m = _ITEM.match(body, i)
            if m is None:
                raise InputError(
                    f"DPRNT: a variable needs its format, e.g. #5061[44]: {text.strip()!r}",
                    file=name or "<program>",
                    line=line,
                )
            var = int(m.group(1))
            if var not in SKIP_VARIABLES:
                raise InputError(
                    f"DPRNT of #{var}: only the skip positions #5061 (X) and #5062 (Z) are "
                    f"simulated: {text.strip()!r}",
                    file=name or "<program>",
                    line=line,
                )
            items.append(("var", var, int(m.group(2)), int(m.group(3))))
            i = m.end()
        elif ch == "*":
            items.append(("text", " "))
            i += 1
        elif ch in " \t":  # blanks in a block are ignored; `*` prints one
            i += 1
        elif ch.isascii() and (ch.isalnum() or ch in ".,:=/-+"):
            items.append(("text", ch.upper() if ch.isalpha() else ch))
            i += 1
        else:
            raise InputError(
                f"DPRNT: character {ch!r} cannot be printed: {text.strip()!r}",
                file=name or "<program>",
                line=line,
            )
    return DprntFormat(line, text, tuple(items))
