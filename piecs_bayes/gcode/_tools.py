"""LinuxCNC tool tables (``*.tbl``): tool number, pocket, diameter, orientation.

One tool per line, words in any order, a ``;`` comment to the end of the
line::

    T1 P1 D0.8 Z+0.1 X+0.2 I95 J155 Q3 ; 0.4 mm nose, orientation 3

``T`` tool number and ``P`` pocket are whole numbers; ``D`` is the tool
**diameter** (twice the nose radius); ``Q`` the lathe tool orientation 0-9
(LinuxCNC's convention, see :mod:`piecs_bayes.gcode._nosecomp`); ``X Y Z A
B C U V W`` offsets and ``I J`` front / back angles are read and kept. Lengths
are in the machine's units, which the file does not say: pass ``units``
(LinuxCNC's standalone ``rs274`` reads them as inches).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError

_WORD = re.compile(r"\s*([A-Za-z])\s*([+-]?(?:\d+(?:\.\d*)?|\.\d+))")
_LENGTH_LETTERS = set("XYZUVWD")


@dataclass(frozen=True)
class ToolEntry:
    """One tool: ``diameter_mm`` (radius is half of it) and ``orientation`` 0-9."""

    tool: int
    pocket: int | None
    diameter_mm: float
    orientation: int
    offsets_mm: dict = field(default_factory=dict, compare=False)
    comment: str = ""
    line: int | None = None

    @property
    def radius_mm(self) -> float:
        return self.diameter_mm / 2.0


def parse_tool_table(text: str, *, units: str = "mm", name: str | None = None):
    """Parse tool-table text into ``{tool number: ToolEntry}``.

    **Arguments:**

    - `text`: the table.
    - `units`: ``"mm"`` or ``"in"``, the units of its lengths.
    - `name`: the file name used in error messages.
    """
    if units not in ("mm", "in"):
        raise InputError(f"tool table units must be 'mm' or 'in', got {units!r}", file=name)
    scale = 25.4 if units == "in" else 1.0
    tools: dict[int, ToolEntry] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        body, _, comment = raw.partition(";")
        if not body.strip():
            continue
        words: dict[str, float] = {}
        pos = 0
        while pos < len(body.rstrip()):
            m = _WORD.match(body, pos)
            if m is None:
                raise InputError(
                    f"cannot read the tool table entry here: {body[pos:].strip()!r}",
                    file=name,
                    line=number,
                )
            letter = m.group(1).upper()
            if letter in words and letter != "P":
                raise InputError(f"word {letter} appears twice", file=name, line=number)
            # a second P (the pocket, which nothing here uses) wins, as in LinuxCNC's
            # loader: its own lathe-comp test table writes "T7 P7 Z0.0 P0.0"
            words[letter] = float(m.group(2))
            pos = m.end()
        unknown = set(words) - set("TPDQIJXYZABCUVW")
        if unknown:
            raise InputError(
                f"unknown tool table word(s) {', '.join(sorted(unknown))}", file=name, line=number
            )
        if "T" not in words or words["T"] != int(words["T"]) or words["T"] < 0:
            raise InputError("each entry needs a whole tool number T", file=name, line=number)
        tool = int(words["T"])
        if tool in tools:
            raise InputError(f"tool T{tool} is listed twice", file=name, line=number)
        orientation = words.get("Q", 0.0)
        if orientation != int(orientation) or not 0 <= orientation <= 9:
            raise InputError(
                f"orientation Q must be a whole number 0-9, got {orientation:g}",
                file=name,
                line=number,
                value=orientation,
            )
        pocket = words.get("P")
        tools[tool] = ToolEntry(
            tool=tool,
            pocket=None if pocket is None else int(pocket),
            diameter_mm=words.get("D", 0.0) * scale,
            orientation=int(orientation),
            offsets_mm={
                k: v * scale if k in _LENGTH_LETTERS else v
                for k, v in words.items()
                if k in "XYZABCUVWIJ"
            },
            comment=comment.strip(),
            line=number,
        )
    return tools


def read_tool_table(path, *, units: str = "mm") -> dict[int, ToolEntry]:
    """Read a LinuxCNC tool table file (see :func:`parse_tool_table`)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the tool table: {exc}", file=str(path)) from None
    return parse_tool_table(text, units=units, name=str(path))
