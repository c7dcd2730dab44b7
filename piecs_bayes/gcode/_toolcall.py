"""Which tool cuts the finish pass: the T word in force on the finish-cut blocks.

**What a T word means** (read by :func:`tool_call`):

- *Turret style*, a program without any M6 (Fanuc, Haas, Okuma and other Fanuc-style
  lathe controls): the T word indexes the turret and applies the offsets at once.
  ``Tttoo`` is tool (station) ``tt`` with wear offset ``oo``: ``T0202`` and ``T202``
  are tool 2, wear offset 2; ``T0211`` is tool 2, wear offset 11; ``T0200`` cancels
  the offsets (offset 0). A T word of one or two digits (``T2``) is tool 2 with its own
  offset 2. More than four digits is refused (controls with six-digit T codes differ).
- *M6 style*, a program with M6 (LinuxCNC): the T word selects the tool that the next
  M6 loads, and its number is the tool number as written (``T2 M6`` and ``T0002 M6``
  are tool 2; ``T202 M6`` is tool 202). LinuxCNC keeps one tool-table entry per tool,
  which ``G10 L1 P<tool>`` sets: the offset number is the tool number.

LinuxCNC reads ``T0202`` as tool 202 unless a Fanuc-style T remap is configured; its
``lathe-fanucy`` sample configuration reads the pairs the other way round (``T0201``:
tool 1 with the wear entry 10002 of its tool table), so only ``Tnnnn`` with equal pairs
(``T0202``) means the same there. A turret-style program is read here the Fanuc way
(Fanuc: G10 ``P`` 1-64 addresses wear offsets, 10000 + n geometry offsets).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import AnalysisError, InputError
from ..geometry import Profile


@dataclass(frozen=True)
class ToolCall:
    """A tool as a program calls it: ``tool`` number, wear ``offset`` number, the T
    ``word`` as written, its ``line``, the ``style`` (``"turret"`` or ``"M6"``) and the
    finish-cut ``blocks`` (lines) cut with it."""

    tool: int
    offset: int
    word: str
    line: int
    style: str
    blocks: tuple[int, ...] = ()

    def __repr__(self) -> str:
        return f"ToolCall({self.word} line {self.line}: tool {self.tool}, offset {self.offset})"


@dataclass(frozen=True)
class FinishCutTools:
    """The tools that cut a program's finish-cut blocks.

    ``calls``: one [`ToolCall`][] per distinct (tool, offset), in program order;
    ``untooled``: finish-cut lines cut before any T word; ``mapped``: whether the
    finish-cut blocks are those mapped to the profile's features (else the
    compensated moves, or every feed move: ``why`` says why the mapping failed).
    """

    calls: tuple[ToolCall, ...]
    untooled: tuple[int, ...]
    mapped: bool
    why: str = ""


def tool_call(word, *, file: str | None = None) -> ToolCall:
    """The tool and wear offset a [`ToolWord`][piecs_bayes.gcode.ToolWord] calls
    (rules in the module docstring); `file` names the program in errors."""
    digits = word.text[1:].split(".")[0].lstrip("+")
    v = int(word.value)
    if word.by == "M6":
        return ToolCall(v, v, word.text, word.line, "M6")
    if len(digits) > 4:
        raise InputError(
            f"{word.text}: a T word of more than four digits is not understood (Tttoo: "
            "tool tt, wear offset oo); name the tool in the study's [offsets] tool",
            file=file,
            line=word.line,
            value=word.text,
        )
    if len(digits) <= 2:
        return ToolCall(v, v, word.text, word.line, "turret")
    return ToolCall(v // 100, v % 100, word.text, word.line, "turret")


def finish_cut_tools(
    program, profile: Profile, *, tol_mm: float = 0.01, mapping=None
) -> FinishCutTools:
    """The tools in force on the finish-cut blocks of `program`.

    The finish-cut blocks are those [`map_blocks_to_profile`][] pairs with the
    profile's features (same `tol_mm` and `mapping`); when they cannot be mapped
    (`AnalysisError`), the compensated moves (or, without compensation, every feed
    move) stand in, and `why` says so. A bad explicit `mapping` raises `InputError`.

    **Returns:** a [`FinishCutTools`][].
    """
    from ._adjust import candidates, map_blocks_to_profile, read_program

    program = read_program(program)
    why = ""
    try:
        lines = sorted(
            map_blocks_to_profile(program, profile, tol_mm=tol_mm, mapping=mapping).lines
        )
    except AnalysisError as exc:
        why = str(exc)
        lines = sorted({m.line for m in candidates(program)})
    by_key: dict[tuple[int, int], list] = {}
    untooled = []
    for ln in lines:
        word = program.state(ln).tool
        if word is None:
            untooled.append(ln)
            continue
        call = tool_call(word, file=program.name)
        by_key.setdefault((call.tool, call.offset), [call, []])[1].append(ln)
    calls = tuple(
        ToolCall(c.tool, c.offset, c.word, c.line, c.style, tuple(blocks))
        for c, blocks in by_key.values()
    )
    return FinishCutTools(calls, tuple(untooled), not why, why)
