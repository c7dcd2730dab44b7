"""Part programs (any dialect): lossless lexing and writing.

[`lex_gcode`][] keeps a program as its lines ([`GcodeText`][] of [`SourceLine`][]), each
with its exact text, its line ending and the spans of its words ([`Word`][]), comments
([`Comment`][]), parameter assignments, LinuxCNC O-word and Fanuc macro statements:
writing an unchanged program gives back the same bytes. [`edit_line`][] changes words
of a block keeping their order, its comments and each word's number format
([`format_number`][]): only the changed words differ; [`read_text_lossless`][] reads a
file without losing a byte. What cannot be lexed (an unclosed comment, a letter
without a value) is an :class:`~piecs_bayes.errors.InputError` naming the file, the
line, the column and its text. What the words mean is
:func:`~piecs_bayes.gcode.read_gcode`'s.

What the lexer accepts: docs/models/part_programs.md, "Lexing".
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path

from ..errors import InputError
from ._expr import FUNCTIONS, ExpressionError, Param, read_bare, read_param_ref, read_value

_EOL = re.compile(r"\r\n|\n|\r")
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)")
# a line of plain words only (most lines): lexed by one expression
_NUM = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)"
_PLAIN_LINE = re.compile(rf"[ \t]*(?:[A-Za-z][ \t]*{_NUM}[ \t]*)*")
_PLAIN_WORD = re.compile(rf"([A-Za-z])[ \t]*({_NUM})")
# ... and of plain words and comments
_COMMENTED_LINE = re.compile(rf"(?:[ \t]*(?:[A-Za-z][ \t]*{_NUM}|\([^()]*\)))*[ \t]*(?:;.*)?")
_COMMENTED_TOKEN = re.compile(rf"([A-Za-z])[ \t]*({_NUM})|\(([^()]*)\)|;(.*)")
_CODES: dict[tuple[str, float], str] = {}


@dataclass(frozen=True)
class Word:
    """One word: ``letter`` (upper case) and its number exactly as written.

    ``start``/``end`` span the whole word in the line text (letter to last
    digit); ``num_start`` is where the number begins. A value computed when the
    block runs (``X#1``, ``Z[#2 + 1]``) keeps its text in ``text`` and its syntax
    tree in ``expr``; its ``value`` is NaN. ``,C`` / ``,R`` words have the letter
    ``",C"`` / ``",R"``; a ``:0100`` program number is an ``O`` word.
    """

    letter: str
    text: str
    value: float
    start: int
    end: int
    num_start: int
    expr: object | None = None

    @property
    def decimals(self) -> int:
        """Digits after the decimal point as written (0 when there is no point)."""
        if self.expr is not None:
            return 0
        return len(self.text.split(".", 1)[1]) if "." in self.text else 0

    @cached_property
    def code(self) -> str:
        """Normalised code for G and M words: ``"G1"``, ``"G41.1"``, ``"M30"``."""
        if self.expr is not None:
            return f"{self.letter}{self.text}"
        return code_of(self.letter, self.value)

    def __str__(self) -> str:
        return f"{self.letter}{self.text}"


def code_of(letter: str, value: float) -> str:
    """``G`` and ``1.0`` -> ``"G1"``; ``G``, ``41.1`` -> ``"G41.1"``."""
    code = _CODES.get((letter, value))
    if code is None:
        num = f"{value:.4f}".rstrip("0").rstrip(".")
        code = _CODES.setdefault((letter, value), f"{letter}{num}")
    return code


@dataclass(frozen=True)
class Assignment:
    """``#1 = 2.5``, ``#<name> = [#1 * 2]``: ``target`` (a parameter reference) and
    ``value`` (a syntax tree of ``_expr``), spanning ``start:end`` of the line."""

    target: Param
    value: object
    start: int
    end: int
    text: str


@dataclass(frozen=True)
class OWord:
    """A LinuxCNC O-word statement: ``label`` (``"100"`` or ``"<name>"``, lower case),
    ``keyword`` (``sub``, ``call``, ``if``, ...), ``args`` (syntax trees of its
    ``[...]`` values)."""

    label: str
    keyword: str
    args: tuple
    start: int
    end: int


@dataclass(frozen=True)
class MacroStatement:
    """A Fanuc macro B statement: ``kind`` is ``if_goto``, ``if_then``, ``goto``,
    ``while`` (``loop`` = its DO number), ``end`` (``loop``: END number) or an output
    statement (``popen``, ``pclos``, ``dprnt``, ``bprnt``)."""

    kind: str
    start: int
    cond: object | None = None
    target: object | None = None
    then: Assignment | None = None
    loop: int = 0


@dataclass(frozen=True)
class Comment:
    """A comment: ``kind`` is ``"paren"`` or ``"semicolon"``; ``text`` without delimiters."""

    kind: str
    text: str
    start: int
    end: int


@dataclass(frozen=True)
class SourceLine:
    """One source line: number (1-based), text without its ending, the ending itself.

    Besides words and comments a line may hold parameter ``assignments``, a LinuxCNC
    ``oword`` statement, a Fanuc ``macro`` statement, a leading block delete ``/``,
    an Okuma ``header`` (``$NAME.MIN%``) and a ``%`` (``percent``). ``error`` is why
    the line could not be lexed (only when lexed with ``strict=False``).
    """

    number: int
    text: str
    eol: str
    words: tuple[Word, ...] = ()
    comments: tuple[Comment, ...] = ()
    percent: bool = False
    block_delete: bool = False
    assignments: tuple[Assignment, ...] = ()
    oword: OWord | None = None
    macro: MacroStatement | None = None
    header: str | None = None
    error: str | None = None

    def find(self, letter: str) -> tuple[Word, ...]:
        letter = letter.upper()
        return tuple(w for w in self.words if w.letter == letter)

    def word(self, letter: str) -> Word | None:
        """The single word with this letter, or None (repeats are refused by the reader)."""
        found = self.find(letter)
        return found[0] if found else None

    @property
    def is_blank(self) -> bool:
        return not (
            self.words
            or self.comments
            or self.percent
            or self.assignments
            or self.oword
            or self.macro
            or self.header
            or self.error
        )

    computed: bool = field(init=False, repr=False, compare=False)
    """Some word's value is computed (a parameter or an expression)."""

    def __post_init__(self):
        object.__setattr__(self, "computed", any(w.expr is not None for w in self.words))


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


class _LexError(Exception):
    pass


_O_KEYWORDS = frozenset(
    "sub endsub call return if elseif else endif while endwhile do repeat endrepeat "
    "break continue".split()
)
_O_LABEL = re.compile(r"\s*(?:(\d+)|<([^>]*)>)")
_O_KEYWORD_AFTER = re.compile(r"\s*[Oo]\s*\d+\s*[A-Za-z]")
_KEYWORD = re.compile(r"(IF|WHILE|GOTO|END\s*(\d)|THEN|POPEN|PCLOS|DPRNT|BPRNT)(?![A-Z])", re.I)
_ALNUM = re.compile(r"[A-Za-z]+")


def _blank(text: str, i: int) -> int:
    n = len(text)
    while i < n and text[i] in " \t":
        i += 1
    return i


def _rest_is_comment(text: str, i: int) -> bool:
    """Only blanks and comments from ``i`` to the end."""
    i = _blank(text, i)
    while i < len(text):
        if text[i] == ";":
            return True
        if text[i] != "(":
            return False
        j = text.find(")", i + 1)
        if j < 0:
            return False
        i = _blank(text, j + 1)
    return True


class _LineLexer:
    """Lexes one line into words, comments and statements (see `lex_line`)."""

    def __init__(self, text: str):
        self.text = text
        self.words: list[Word] = []
        self.comments: list[Comment] = []
        self.assignments: list[Assignment] = []
        self.oword: OWord | None = None
        self.macro: MacroStatement | None = None
        self.block_delete = False
        self.percent = False

    def fail(self, msg: str, col: int):
        raise _LexError(f"{msg} (column {col + 1})")

    def value(self, i: int):
        try:
            return read_value(self.text, i)
        except ExpressionError as exc:
            self.fail(str(exc), exc.pos if exc.pos is not None else i)

    def group(self, i: int, what: str):
        i = _blank(self.text, i)
        if i >= len(self.text) or self.text[i] != "[":
            self.fail(f"{what} needs a condition in [...]", i)
        return self.value(i)

    def comment_at(self, i: int) -> int:
        text = self.text
        if text[i] == ";":
            self.comments.append(Comment("semicolon", text[i + 1 :], i, len(text)))
            return len(text)
        j = text.find(")", i + 1)
        if j < 0:
            self.fail("comment '(' is not closed on this line", i)
        if "(" in text[i + 1 : j]:
            self.fail("nested comments are not allowed", i)
        self.comments.append(Comment("paren", text[i + 1 : j], i, j + 1))
        return j + 1

    def finish(self, i: int, what: str) -> None:
        """Only comments may follow ``what``."""
        text = self.text
        while True:
            i = _blank(text, i)
            if i >= len(text):
                return
            if text[i] in "(;":
                i = self.comment_at(i)
                continue
            if text[i] == "%" and _rest_is_comment(text, i + 1):
                self.percent = True
                i += 1
                continue
            self.fail(f"{text[i:].strip()!r} after {what}", i)

    def run(self) -> None:
        text, n = self.text, len(self.text)
        i = _blank(text, 0)
        if i < n and text[i] == "/":
            self.block_delete = True
            i += 1
            if i < n and text[i] in "123456789" and i + 1 < n and not text[i + 1].isdigit():
                i += 1  # Fanuc's optional block skip /1 .. /9
        elif i < n and text[i] == ":":
            m = _NUMBER.match(text, i + 1)
            if m is None or m.group()[0] in "+-":
                self.fail("':' is not followed by a program number", i)
            self.words.append(Word("O", m.group(), float(m.group()), i, m.end(), i + 1))
            i = m.end()
        while i < n:
            ch = text[i]
            if ch in " \t\f\v":
                i += 1
            elif ch in "(;":
                i = self.comment_at(i)
            elif ch == "%":
                if not _rest_is_comment(text, i + 1):
                    self.fail("'%' must end its line", i)
                self.percent = True
                i += 1
            elif ch == "#":
                i = self.assignment(i)
            elif ch == ",":
                j = _blank(text, i + 1)
                if j >= n or text[j].upper() not in "CRA":
                    self.fail("',' must begin a ,C / ,R chamfer or corner word", i)
                i = self.word(i, "," + text[j].upper(), j + 1)
            elif ch.isascii() and ch.isalpha():
                i = self.letter(i)
            elif ch == "\x00":
                self.fail("a NUL byte (the file is binary or damaged)", i)
            else:
                what = {
                    "[": "an expression [...] must be a word's value",
                    "/": "block delete '/' must begin the line",
                    ")": "')' without '('",
                    "=": "'=' without a parameter (#1 = ...)",
                }.get(ch, f"unexpected character {ch!r}")
                self.fail(what, i)

    def letter(self, i: int) -> int:
        text = self.text
        ch = text[i].upper()
        j = _blank(text, i + 1)
        nxt = text[j : j + 1]
        if ch == "O" and self.is_o_statement(i):
            return self.o_statement(i)
        if nxt and (nxt in "#[.0123456789" or (nxt in "+-" and text[j + 1 : j + 2] != "")):
            if ch == "O" and nxt == "[":
                self.fail("an O word takes a number or <name>", i)
            return self.word(i, ch, j)
        if ch == "O":
            return self.o_statement(i)
        m = _KEYWORD.match(text, i)
        if m is not None:
            return self.statement(i, m)
        func = _ALNUM.match(text, j) if nxt.isalpha() else None
        if func is not None and func.group().upper() in FUNCTIONS:
            k = _blank(text, func.end())
            if text[k : k + 1] == "[":  # a function as the value: X SIN[30]
                return self.word(i, ch, j)
        self.fail(f"word {ch!r} has no number", i)
        return i  # pragma: no cover

    def word(self, i: int, letter: str, j: int) -> int:
        text = self.text
        m = _NUMBER.match(text, j)
        if m is not None:
            end = m.end()
            if end < len(text) and text[end] in "#[":
                self.fail(f"word {letter} has a value that is not understood", i)
            self.words.append(Word(letter, m.group(), float(m.group()), i, end, j))
            return end
        node, end = self.value(j)
        raw = text[j:end]
        self.words.append(Word(letter, raw, math.nan, i, end, j, node))
        return end

    def assignment(self, i: int) -> int:
        text = self.text
        try:
            target, j = read_param_ref(text, i)
        except ExpressionError as exc:
            self.fail(str(exc), exc.pos if exc.pos is not None else i)
        k = _blank(text, j)
        if k >= len(text) or text[k] != "=":
            self.fail(
                f"parameter {text[i:j].strip()} is not assigned (write #1 = value; "
                "a word takes it as X#1)",
                i,
            )
        try:
            node, end = read_bare(text, k + 1)
        except ExpressionError as exc:
            self.fail(str(exc), exc.pos if exc.pos is not None else k + 1)
        self.assignments.append(Assignment(target, node, i, end, text[i:end].strip()))
        return end

    def is_o_statement(self, i: int) -> bool:
        m = _O_LABEL.match(self.text, i + 1)
        if m is None:
            return False
        if m.group(2) is not None:
            return True
        kw = _ALNUM.match(self.text, _blank(self.text, m.end()))
        return kw is not None and kw.group().lower() in _O_KEYWORDS

    def o_statement(self, i: int) -> int:
        """``o100 sub``, ``O<name> call [1] [2]``, ``o101 if [..]`` (LinuxCNC)."""
        text = self.text
        m = _O_LABEL.match(text, i + 1)
        if m is None:
            self.fail("an O word takes a number or <name>", i)
        label = (
            m.group(1)
            if m.group(1) is not None
            else "<" + "".join(m.group(2).split()).lower() + ">"
        )
        if m.group(1) is not None:
            label = str(int(m.group(1)))
        k = _blank(text, m.end())
        kw = _ALNUM.match(text, k)
        if kw is None or kw.group().lower() not in _O_KEYWORDS:
            if m.group(1) is not None and kw is None:  # pragma: no cover (numbers are words)
                self.fail("an O number", i)
            got = repr(kw.group()) if kw else "nothing"
            self.fail(f"O{m.group(0).strip()} is followed by {got}, not sub/call/if/while/...", i)
        keyword = kw.group().lower()
        j = kw.end()
        args: list = []
        if keyword in ("if", "elseif", "while", "repeat"):
            node, j = self.group(j, f"o{label} {keyword}")
            args.append(node)
        elif keyword in ("call", "return", "endsub"):
            while True:
                j2 = _blank(text, j)
                if j2 < len(text) and text[j2] == "[":
                    node, j = self.value(j2)
                    args.append(node)
                else:
                    break
            if keyword != "call" and len(args) > 1:
                self.fail(f"o{label} {keyword} takes at most one value", j)
        self.oword = OWord(label, keyword, tuple(args), i, j)
        self.finish(j, f"o{label} {keyword}")
        return len(text)

    def statement(self, i: int, m) -> int:
        """Fanuc macro B: IF [..] GOTO n / IF [..] THEN #i = ..., WHILE [..] DOm, ENDm,
        GOTO n; POPEN, PCLOS, DPRNT[..], BPRNT[..] (output, recorded)."""
        text = self.text
        kw = m.group(1).upper().replace(" ", "")
        j = m.end()
        if kw == "IF":
            cond, j = self.group(j, "IF")
            k = _blank(text, j)
            nxt = _KEYWORD.match(text, k)
            if nxt is not None and nxt.group(1).upper() == "GOTO":
                target, j = self.value(nxt.end())
                self.macro = MacroStatement("if_goto", i, cond=cond, target=target)
            elif nxt is not None and nxt.group(1).upper() == "THEN":
                j = _blank(text, nxt.end())
                if j >= len(text) or text[j] != "#":
                    self.fail("IF [...] THEN takes an assignment (#1 = ...)", j)
                j = self.assignment(j)
                then = self.assignments.pop()
                self.macro = MacroStatement("if_then", i, cond=cond, then=then)
            else:
                self.fail("IF [...] must be followed by GOTO n or THEN #i = ...", k)
        elif kw == "GOTO":
            target, j = self.value(j)
            self.macro = MacroStatement("goto", i, target=target)
        elif kw == "WHILE":
            cond, j = self.group(j, "WHILE")
            k = _blank(text, j)
            do = re.compile(r"DO\s*(\d)", re.I).match(text, k)
            if do is None:
                self.fail("WHILE [...] must be followed by DO1 .. DO3", k)
            self.macro = MacroStatement("while", i, cond=cond, loop=int(do.group(1)))
            j = do.end()
        elif kw.startswith("END"):
            self.macro = MacroStatement("end", i, loop=int(m.group(2)))
        elif kw == "THEN":
            self.fail("THEN without IF [...]", i)
        elif kw in ("POPEN", "PCLOS"):
            self.macro = MacroStatement(kw.lower(), i)
        else:  # DPRNT / BPRNT [ ... ]: the bracket's text is output, not an expression
            k = _blank(text, j)
            end = text.rfind("]")
            if k >= len(text) or text[k] != "[" or end < k:
                self.fail(f"{kw} needs [...]", k)
            self.macro = MacroStatement(kw.lower(), i)
            j = end + 1
        self.finish(j, kw)
        return len(text)


_new = object.__new__


def _plain_word(m) -> Word:
    """``Word(...)`` of a plain word's match, built without the frozen ``__init__``
    (most of a long program's time is spent making its words)."""
    w = _new(Word)
    w.__dict__.update(
        letter=m[1].upper(),
        text=m[2],
        value=float(m[2]),
        start=m.start(),
        end=m.end(),
        num_start=m.start(2),
        expr=None,
    )
    return w


def _plain_line(number: int, text: str, eol: str, words: tuple) -> SourceLine:
    """``SourceLine(number, text, eol, words)``, as `_plain_word` builds a word."""
    line = _new(SourceLine)
    line.__dict__.update(_LINE_DEFAULTS, number=number, text=text, eol=eol, words=words)
    line.__dict__["computed"] = False  # plain words only
    return line


def lex_line(
    text: str, eol: str, number: int, name: str | None, *, strict: bool = True
) -> SourceLine:
    """One line lexed; with ``strict`` an error raises, else it is kept in ``.error``."""
    stripped = text.strip()
    if stripped == "%":
        return SourceLine(number, text, eol, percent=True)
    if stripped.startswith("$"):  # Okuma OSP header: $NAME.MIN% (or $NAME.MIN)
        return SourceLine(number, text, eol, percent=stripped.endswith("%"), header=stripped)
    if _PLAIN_LINE.fullmatch(text):
        words = tuple([_plain_word(m) for m in _PLAIN_WORD.finditer(text)])
        if not (words and words[0].letter == "O" and _O_KEYWORD_AFTER.match(text)):
            return _plain_line(number, text, eol, words)
    elif _COMMENTED_LINE.fullmatch(text) and not _O_KEYWORD_AFTER.match(text):
        words, comments = [], []
        for m in _COMMENTED_TOKEN.finditer(text):
            if m[1] is not None:
                words.append(_plain_word(m))
            elif m[3] is not None:
                comments.append(Comment("paren", m[3], m.start(), m.end()))
            else:
                comments.append(Comment("semicolon", m[4], m.start(), m.end()))
        return SourceLine(number, text, eol, tuple(words), tuple(comments))
    lx = _LineLexer(text)
    error = None
    try:
        lx.run()
    except _LexError as exc:
        if strict:
            raise _error(str(exc), name, number, text) from None
        error = str(exc)
    return SourceLine(
        number,
        text,
        eol,
        tuple(lx.words),
        tuple(lx.comments),
        lx.percent,
        block_delete=lx.block_delete,
        assignments=tuple(lx.assignments),
        oword=lx.oword,
        macro=lx.macro,
        error=error,
    )


_LINE_DEFAULTS = {
    f.name: f.default
    for f in fields(SourceLine)
    if f.name not in ("number", "text", "eol", "computed")
}


def lex_gcode(text: str, *, name: str | None = None, strict: bool = True) -> GcodeText:
    """Split ``text`` into lines (keeping ``\\n``, ``\\r\\n`` or ``\\r`` endings) and lex each.

    **Arguments:**

    - `text`: the program text (decoded with ``surrogateescape`` to stay lossless).
    - `name`: the file name used in error messages.
    - `strict`: raise on the first line that cannot be lexed; else each such line
      keeps its error (``SourceLine.error``) for the reader to report.

    **Returns:** a :class:`GcodeText`; ``GcodeText.text == text`` always.
    """
    lines: list[SourceLine] = []
    seen: dict[str, SourceLine] = {}  # a text lexed before gives the same line (CAM
    pos, number = 0, 0  # output repeats its rapids, M codes and cycle blocks)
    for m in _EOL.finditer(text):
        number += 1
        lines.append(_lex_cached(seen, text[pos : m.start()], m.group(), number, name, strict))
        pos = m.end()
    if pos < len(text):
        number += 1
        lines.append(_lex_cached(seen, text[pos:], "", number, name, strict))
    return GcodeText(tuple(lines), name)


def _lex_cached(seen, raw: str, eol: str, number: int, name, strict: bool) -> SourceLine:
    hit = seen.get(raw)
    if hit is None:
        line = lex_line(raw, eol, number, name, strict=strict)
        if line.error is None and len(raw) <= 256:
            seen[raw] = line
        return line
    line = _new(SourceLine)  # a copy, its number and ending its own (as `_plain_line`)
    line.__dict__.update(hit.__dict__)
    line.__dict__["number"] = number
    line.__dict__["eol"] = eol
    return line


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
