"""Which tool cuts the finish pass: the T word in force on the finish-cut blocks.

:func:`tool_call` reads a T word into a [`ToolCall`][] (tool and wear offset number):
in a program without M6 (*turret style*: Fanuc, Haas, Okuma and other Fanuc-style
lathes) ``Tttoo`` is tool ``tt`` with wear offset ``oo`` (``T0202``, ``T202``: tool 2,
offset 2; ``T2``: tool 2, offset 2; six digits are Okuma's ``Tnnttoo``, nose-radius
number ``nn``, tool ``tt``, offset ``oo``; five or more than six refused); in a program with
M6 (*M6 style*: LinuxCNC) the number is the tool as written and the offset number is
the tool number. :func:`finish_cut_tools` gives the tools in force on the finish-cut
blocks ([`FinishCutTools`][]), with `why` when the blocks could not be mapped and the
compensated moves stood in.

What a T word means on each control: docs/models/part_programs.md, "Which tool".
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
    if len(digits) == 6:  # Okuma OSP (manual 5238-E, 6 1-4): nose-radius number, tool, offset
        return ToolCall((v // 100) % 100, v % 100, word.text, word.line, "turret")
    if len(digits) > 4:
        raise InputError(
            f"{word.text}: a T word of five or more than six digits is not understood "
            "(Tttoo: tool tt, wear offset oo; Okuma Tnnttoo: nose-radius number nn, tool tt, "
            "offset oo); name the tool in the study's [offsets] tool",
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
