"""The comment block that makes an adjusted program traceable, and the diff's labels.

The block is written in the program's own comment syntax: ``( ... )`` (RS274, and
whenever the program has parenthesised comments or none at all), ``;`` when the
program only uses ``;`` comments. It goes after a leading ``%`` line and the O-number
line, if present, so that a controller still finds the tape start and the program
number where it expects them; every other line stays byte-identical.

A comment's text is made safe for the controller: no ``(`` or ``)`` inside a
parenthesised comment (they become ``[`` ``]``), no ``%`` (the end-of-record
character on ISO tapes), ASCII only (anything else becomes ``?``), and no text that
LinuxCNC would take for an active comment (``MSG,``, ``DEBUG,``, ``PRINT,``, ``LOG...``,
``PROBEOPEN``, ``PROBECLOSE``, ``AXIS,``: such a text gets ``- `` in front).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import PurePath

from ..errors import AnalysisError
from ._lexer import GcodeText, lex_gcode

_ACTIVE = ("MSG,", "DEBUG,", "PRINT,", "LOG", "PROBEOPEN", "PROBECLOSE", "AXIS,")


def comment_style(source: GcodeText) -> str:
    """``"paren"`` or ``"semicolon"``: the comment syntax the program uses."""
    kinds = {c.kind for line in source.lines for c in line.comments}
    return "semicolon" if kinds == {"semicolon"} else "paren"


def comment_text(text: str, style: str = "paren") -> str:
    """`text` made safe as the inside of a comment in `style` (module docstring)."""
    out = "".join(ch if " " <= ch <= "~" else "?" for ch in str(text)).replace("%", "?")
    if style == "paren":
        out = out.replace("(", "[").replace(")", "]")
    if out.lstrip().upper().startswith(_ACTIVE):
        out = "- " + out
    return out


def _insert_at(source: GcodeText) -> int:
    """How many leading lines stay first: a ``%`` line, then an O-number line."""
    k = 0
    lines = source.lines
    if k < len(lines) and lines[k].percent:
        k += 1
    if k < len(lines) and lines[k].words and lines[k].words[0].letter == "O":
        k += 1
    if k > 0 and not lines[k - 1].eol:  # nothing follows the last line: block first
        k = 0
    return k


def with_comment_block(source: GcodeText, texts: Sequence[str]) -> tuple[GcodeText, int]:
    """`source` with one comment line per text inserted after its ``%`` / O-number
    lines (see the module docstring).

    **Returns:** the new text (re-lexed, same name) and the number of lines inserted.
    """
    if not texts:
        return source, 0
    style = comment_style(source)
    k = _insert_at(source)
    eols = [line.eol for line in source.lines if line.eol]
    eol = source.lines[k - 1].eol if k > 0 else (eols[0] if eols else "\n")
    if style == "paren":
        block = [f"({comment_text(t, style)})" for t in texts]
    else:
        block = [f"; {comment_text(t, style)}" for t in texts]
    head = "".join(line.text + line.eol for line in source.lines[:k])
    tail = "".join(line.text + line.eol for line in source.lines[k:])
    return lex_gcode(head + "".join(b + eol for b in block) + tail, name=source.name), len(block)


def header_checked(program, texts: Sequence[str]) -> tuple[str, int]:
    """`program`'s text with the comment block, re-read to check that it moves exactly
    as `program` does (lines shifted by the block); returns the text and the block's
    number of lines."""
    from ._read import parse_gcode

    source, n = with_comment_block(program.source, [str(t) for t in texts])
    if n:
        again = parse_gcode(source.text, name=program.name, options=program.options)

        def back(m):
            comp = None if m.comp is None else replace(m.comp, line=m.comp.line - n)
            return replace(m, line=m.line - n, comp=comp)

        if [back(m) for m in again.moves] != list(program.moves):
            raise AnalysisError(f"{program.name}: the comment block changed the program's motion")
    return source.text, n


def diff_labels(input_name: str | None, output_name: str | None = None) -> tuple[str, str]:
    """``("a/<input>", "b/<output>")`` for a unified diff of an adjusted program.

    The output defaults to ``<input stem>_adjusted<suffix>``, the name the adjusted
    program is written under (beside the diff). A path's leading ``/`` is dropped
    after ``a/`` and ``b/``.
    """
    name = input_name or "program.ngc"
    if output_name is None:
        p = PurePath(name)
        output_name = f"{p.stem}_adjusted{p.suffix}"

    def label(prefix: str, path: str) -> str:
        return prefix + PurePath(path).as_posix().lstrip("/")

    return label("a/", name), label("b/", str(output_name))
