"""Part programs (RS274 / ISO 6983, lathe dialect): lossless lexing and writing.

[`lex_gcode`][] keeps a program as its lines ([`GcodeText`][] of [`SourceLine`][]), each
with its exact text, its line ending and the spans of its words ([`Word`][]) and
comments ([`Comment`][]): writing an unchanged program gives back the same bytes.
[`edit_line`][] changes words of a block keeping their order, its comments and each
word's number format ([`format_number`][]): only the changed words differ;
[`read_text_lossless`][] reads a file without losing a byte. A line holds words (a
letter and a number), comments (`( ... )`, `;` to the end) or only `%`; anything else
(parameters `#`, expressions, block delete `/`, an unclosed comment) is an
:class:`~piecs_bayes.errors.InputError` naming the file, the line and its text. Which
words mean what is :func:`~piecs_bayes.gcode.read_gcode`'s (module ``_modal``).

What the lexer accepts: docs/models/part_programs.md, "Lexing".
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import InputError

_EOL = re.compile(r"\r\n|\n|\r")
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)")


@dataclass(frozen=True)
class Word:
    """One word: ``letter`` (upper case) and its number exactly as written.

    ``start``/``end`` span the whole word in the line text (letter to last
    digit); ``num_start`` is where the number begins.
    """

    letter: str
    text: str
    value: float
    start: int
    end: int
    num_start: int

    @property
    def decimals(self) -> int:
        """Digits after the decimal point as written (0 when there is no point)."""
        return len(self.text.split(".", 1)[1]) if "." in self.text else 0

    @property
    def code(self) -> str:
        """Normalised code for G and M words: ``"G1"``, ``"G41.1"``, ``"M30"``."""
        v = float(self.text)
        num = f"{v:.4f}".rstrip("0").rstrip(".")
        return f"{self.letter}{num}"

    def __str__(self) -> str:
        return f"{self.letter}{self.text}"


@dataclass(frozen=True)
class Comment:
    """A comment: ``kind`` is ``"paren"`` or ``"semicolon"``; ``text`` without delimiters."""

    kind: str
    text: str
    start: int
    end: int


@dataclass(frozen=True)
class SourceLine:
    """One source line: number (1-based), text without its ending, the ending itself."""

    number: int
    text: str
    eol: str
    words: tuple[Word, ...] = ()
    comments: tuple[Comment, ...] = ()
    percent: bool = False

    def find(self, letter: str) -> tuple[Word, ...]:
        letter = letter.upper()
        return tuple(w for w in self.words if w.letter == letter)

    def word(self, letter: str) -> Word | None:
        """The single word with this letter, or None (repeats are refused by the reader)."""
        found = self.find(letter)
        return found[0] if found else None

    @property
    def is_blank(self) -> bool:
        return not self.words and not self.comments and not self.percent


@dataclass(frozen=True)
class GcodeText:
    """The lines of a program file; ``str(program)`` / :attr:`text` is the exact text."""

    lines: tuple[SourceLine, ...]
    name: str | None = None

    @property
    def text(self) -> str:
        return "".join(line.text + line.eol for line in self.lines)

    def __str__(self) -> str:
        return self.text

    def to_bytes(self) -> bytes:
        """The program's bytes (UTF-8; undecodable input bytes come back unchanged)."""
        return self.text.encode("utf-8", errors="surrogateescape")

    def line(self, number: int) -> SourceLine:
        if not 1 <= number <= len(self.lines):
            raise InputError(
                f"line {number} does not exist (the program has {len(self.lines)} lines)",
                file=self.name,
            )
        return self.lines[number - 1]

    def with_line_texts(self, texts: Mapping[int, str]) -> GcodeText:
        """A new program with the given lines' texts replaced (endings kept), re-lexed."""
        lines = list(self.lines)
        for number, text in texts.items():
            old = self.line(number)
            lines[number - 1] = lex_line(text, old.eol, number, self.name)
        return replace(self, lines=tuple(lines))


def _error(msg: str, name: str | None, number: int, text: str) -> InputError:
    return InputError(f"{msg}: {text.strip()!r}", file=name or "<program>", line=number)


def lex_line(text: str, eol: str, number: int, name: str | None) -> SourceLine:
    words: list[Word] = []
    comments: list[Comment] = []
    stripped = text.strip()
    if stripped == "%":
        return SourceLine(number, text, eol, percent=True)
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch in " \t\f\v":
            i += 1
        elif ch == "(":
            j = text.find(")", i + 1)
            if j < 0:
                raise _error("comment '(' is not closed on this line", name, number, text)
            if "(" in text[i + 1 : j]:
                raise _error("nested comments are not allowed", name, number, text)
            comments.append(Comment("paren", text[i + 1 : j], i, j + 1))
            i = j + 1
        elif ch == ";":
            comments.append(Comment("semicolon", text[i + 1 :], i, n))
            i = n
        elif ch.isascii() and ch.isalpha():
            j = i + 1
            while j < n and text[j] in " \t":
                j += 1
            m = _NUMBER.match(text, j)
            if m is None:
                nxt = text[j : j + 1]
                what = {
                    "#": "parameters (#) are not supported",
                    "[": "expressions ([...]) are not supported",
                }.get(nxt, "has no number")
                raise _error(f"word {ch.upper()!r} at column {i + 1} {what}", name, number, text)
            words.append(Word(ch.upper(), m.group(), float(m.group()), i, m.end(), j))
            i = m.end()
        else:
            what = {
                "#": "parameters (#) are not supported",
                "[": "expressions ([...]) are not supported",
                "/": "block delete (/) is not supported",
                "%": "'%' must be alone on its line",
                ")": "')' without '('",
            }.get(ch, f"unexpected character {ch!r}")
            raise _error(f"{what} (column {i + 1})", name, number, text)
    return SourceLine(number, text, eol, tuple(words), tuple(comments))


def lex_gcode(text: str, *, name: str | None = None) -> GcodeText:
    """Split ``text`` into lines (keeping ``\\n``, ``\\r\\n`` or ``\\r`` endings) and lex each.

    **Arguments:**

    - `text`: the program text (decoded with ``surrogateescape`` to stay lossless).
    - `name`: the file name used in error messages.

    **Returns:** a :class:`GcodeText`; ``GcodeText.text == text`` always.
    """
    lines: list[SourceLine] = []
    pos, number = 0, 0
    for m in _EOL.finditer(text):
        number += 1
        lines.append(lex_line(text[pos : m.start()], m.group(), number, name))
        pos = m.end()
    if pos < len(text):
        number += 1
        lines.append(lex_line(text[pos:], "", number, name))
    return GcodeText(tuple(lines), name)


def read_text_lossless(path) -> str:
    """Read a file as text without touching line endings or undecodable bytes."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read the program: {exc.strerror}", file=str(path)) from None
    return data.decode("utf-8", errors="surrogateescape")


def format_number(value: float, like: Word | None = None, *, decimals: int | None = None) -> str:
    """Format ``value`` in the number format of ``like`` (or with ``decimals``).

    The format keeps an explicit ``+`` sign, a leading zero or its absence
    (``.5`` vs ``0.5``) and the number of decimal places. A word written
    without a decimal point (``X20``) is given ``decimals`` places when its
    new value is not a whole number at that precision.
    """
    if like is not None:
        places = like.decimals
        has_point = "." in like.text
        if not has_point and decimals is not None and round(value) != round(value, decimals):
            places, has_point = decimals, True
    else:
        places = 4 if decimals is None else decimals
        has_point = True
    text = f"{value:.{places}f}"
    if text.lstrip("-").strip("0.") == "":
        text = text.lstrip("-")  # no "-0.000"
    if has_point and "." not in text:
        text += "."
    if like is not None:
        bare = like.text.lstrip("+-")
        if bare.startswith(".") and text.lstrip("-").startswith("0."):
            text = text.replace("0.", ".", 1)
        if like.text.startswith("+") and not text.startswith("-"):
            text = "+" + text
    return text


def edit_line(
    line: SourceLine,
    *,
    values: Mapping[int, str] | None = None,
    remove: frozenset[int] | set[int] = frozenset(),
    insert: Mapping[int, list[str]] | None = None,
) -> str:
    """New text for ``line`` with word-level edits; everything else byte-identical.

    **Arguments:**

    - `values`: word index -> new number text (the letter and its spacing kept).
    - `remove`: word indices to delete (with the blanks that followed them).
    - `insert`: word index -> word texts (``"Z-12.000"``) inserted after that
      word (index ``-1``: at the start of the line, after leading blanks).
      Words are separated by a blank when the line separates its words so.

    **Returns:** the new line text (without line ending).
    """
    values = values or {}
    insert = dict(insert or {})
    text = line.text
    sep = " " if _uses_blanks(line) else ""
    blanks = " \t"
    lead = text[: len(text) - len(text.lstrip(blanks))]
    out: list[str] = []
    pos = len(lead)
    for k, w in enumerate(line.words):
        gap = text[pos : w.start]
        pos = w.end
        if k in remove:
            if gap.strip(blanks):  # the gap holds a comment: keep it
                out.append(gap)
            continue
        if not gap.strip(blanks) and out and out[-1][-1:] in (" ", "\t"):
            gap = ""
        out.append(gap)
        out.append(
            text[w.start : w.num_start] + values[k] if k in values else text[w.start : w.end]
        )
        if insert.get(k):
            out.append(sep + sep.join(insert[k]))
    tail = text[pos:]
    if not tail.strip(blanks) and out and out[-1][-1:] in (" ", "\t"):
        tail = ""
    out.append(tail)
    rest = "".join(out).lstrip(blanks)
    if insert.get(-1):
        head = sep.join(insert[-1])
        rest = head + (sep if rest and sep and not rest.startswith(";") else "") + rest
    if not text[len(lead) :].endswith((" ", "\t")):
        rest = rest.rstrip(blanks)
    return lead + rest


def _uses_blanks(line: SourceLine) -> bool:
    words = line.words
    if len(words) < 2:
        return True
    return any(words[k].end < words[k + 1].start for k in range(len(words) - 1))
