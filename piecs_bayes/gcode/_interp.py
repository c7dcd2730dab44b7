"""Running a part program's control flow: subroutines, loops, branches and parameters.

[`Interpreter`][] walks a lexed program as the control does: LinuxCNC O-word
subroutines (``sub``/``endsub``/``call``/``return`` with arguments and return values),
``if``/``elseif``/``else``/``endif``, ``while``/``endwhile``, ``do``/``while``,
``repeat``/``endrepeat``, ``break``/``continue``; Fanuc macro B (``IF [..] GOTO n``,
``IF [..] THEN``, ``WHILE [..] DOm``/``ENDm``, ``GOTO n``), subprograms (``M98 P``/``M99``,
Haas ``M97``) and macro calls (``G65 P``). Each executed line's words are evaluated
(parameters and ``[...]`` expressions, the line's assignments taking effect after it is
read, as LinuxCNC does) and handed to the :class:`ModalMachine` as a ``Block``. A
program that runs more than ``step_limit`` blocks stops with an error naming the loop;
anything not understood is an :class:`~piecs_bayes.errors.InputError` naming the
line, the word and why.

The constructs and their rules: docs/models/part_programs.md, "Control flow".
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import InputError
from ._cycle_run import finish_cycles, run_cycle
from ._dialect import DialectTable
from ._expr import ExpressionError, Param, compile_value
from ._lexer import GcodeText, SourceLine, code_of
from ._modal import Block, BlockWord, ModalMachine
from ._options import ReadOptions
from ._params import ParameterError, Parameters

_MAX_CALL_DEPTH = 50
_FLOW = ("if_goto", "if_then", "goto", "while", "end")
# G65 argument letters -> local parameters (Fanuc macro B, argument specification I)
_G65_ARGS = {
    "A": 1, "B": 2, "C": 3, "I": 4, "J": 5, "K": 6, "D": 7, "E": 8, "F": 9, "H": 11,
    "M": 13, "Q": 17, "R": 18, "S": 19, "T": 20, "U": 21, "V": 22, "W": 23, "X": 24,
    "Y": 25, "Z": 26,
}  # fmt: skip


@dataclass
class _Frame:
    """A call in progress: where to come back, how many passes are left (M98 L)."""

    kind: str  # "sub" (LinuxCNC), "m98", "m97", "g65"
    back: int
    label: str
    start: int = 0
    passes: int = 1
    modes: object | None = None
    repeats: dict[int, int] = field(default_factory=dict)


@dataclass
class Structure:
    """Where each control statement of a program leads (found before running)."""

    subs: dict[str, tuple[int, int]] = field(default_factory=dict)
    jump: dict[int, int] = field(default_factory=dict)
    """statement index -> the index it leads to (endsub after sub, endwhile after while,
    the next branch after an if/elseif, endif after a taken branch, ...)."""
    back: dict[int, int] = field(default_factory=dict)
    """loop end -> loop start (endwhile -> while, closing while -> do, END -> WHILE)."""
    loop_of: dict[int, int] = field(default_factory=dict)
    """break / continue -> the index of its loop's start."""
    labels: dict[int, list[int]] = field(default_factory=dict)
    """N number -> the line indices that carry it."""
    programs: dict[int, int] = field(default_factory=dict)
    """Fanuc program number -> the index of its O line."""
    branches: dict[int, list[int]] = field(default_factory=dict)
    """if index -> its elseif/else indices and its endif."""
    endif: dict[int, int] = field(default_factory=dict)
    """elseif/else index -> its endif."""


def scan(src: GcodeText, err, linuxcnc: bool) -> Structure:
    """The control structure of ``src``; ``err(index, msg)`` builds the errors. O-words
    are LinuxCNC's (``linuxcnc``), macro B statements the others'."""
    st = Structure()
    stack: list[tuple[str, str, int]] = []  # (kind, label, index)
    do_stack: list[tuple[int, int]] = []  # Fanuc WHILE DOm: (m, index)
    for i, line in enumerate(src.lines):
        n_word = line.words[0] if line.words and line.words[0].letter == "N" else None
        if n_word is not None and n_word.expr is None:
            st.labels.setdefault(int(n_word.value), []).append(i)
        first = line.words[0] if line.words else None
        if first is not None and first.letter == "O" and first.expr is None:
            st.programs.setdefault(int(first.value), i)
        if line.macro is not None and linuxcnc and line.macro.kind in _FLOW:
            what = line.macro.kind.split("_")[0].upper()
            raise err(i, f"macro B statements ({what}) are Fanuc's; this program is read as "
                      "linuxcnc")  # fmt: skip
        if line.oword is not None and not linuxcnc:
            o = line.oword
            raise err(i, f"O-word statements (o{o.label} {o.keyword}) are LinuxCNC's; this "
                      "program is not read as linuxcnc")  # fmt: skip
        if line.macro is not None:
            m = line.macro
            if m.kind == "while":
                do_stack.append((m.loop, i))
            elif m.kind == "end":
                if not do_stack or do_stack[-1][0] != m.loop:
                    raise err(i, f"END{m.loop} without WHILE [...] DO{m.loop}")
                _, start = do_stack.pop()
                st.jump[start] = i
                st.back[i] = start
        o = line.oword
        if o is None:
            continue
        kw, label = o.keyword, o.label
        top = stack[-1] if stack else None
        if kw == "sub":
            if any(k == "sub" for k, _, _ in stack):
                raise err(i, f"o{label} sub inside another subroutine")
            if label in st.subs:
                raise err(i, f"o{label} sub is defined twice")
            stack.append(("sub", label, i))
        elif kw == "endsub":
            if top is None or top[:2] != ("sub", label):
                raise err(i, f"o{label} endsub without o{label} sub" + _open(top))
            stack.pop()
            st.subs[label] = (top[2], i)
            st.jump[top[2]] = i
        elif kw in ("if", "do", "repeat"):
            stack.append((kw, label, i))
            if kw == "if":
                st.branches[i] = []
        elif kw in ("elseif", "else"):
            if top is None or top[:2] != ("if", label):
                raise err(i, f"o{label} {kw} without o{label} if" + _open(top))
            st.branches[top[2]].append(i)
        elif kw == "endif":
            if top is None or top[:2] != ("if", label):
                raise err(i, f"o{label} endif without o{label} if" + _open(top))
            stack.pop()
            chain = [top[2], *st.branches[top[2]], i]
            for a in chain[1:-1]:
                st.endif[a] = i
            st.branches[top[2]].append(i)
        elif kw == "while":
            if top is not None and top[:2] == ("do", label):
                stack.pop()
                st.jump[top[2]] = i
                st.back[i] = top[2]
            else:
                stack.append(("while", label, i))
        elif kw == "endwhile":
            if top is None or top[:2] != ("while", label):
                raise err(i, f"o{label} endwhile without o{label} while" + _open(top))
            stack.pop()
            st.jump[top[2]] = i
            st.back[i] = top[2]
        elif kw == "endrepeat":
            if top is None or top[:2] != ("repeat", label):
                raise err(i, f"o{label} endrepeat without o{label} repeat" + _open(top))
            stack.pop()
            st.jump[top[2]] = i
            st.back[i] = top[2]
        elif kw in ("break", "continue"):
            loop = next(
                ((k, idx) for k, lab, idx in reversed(stack) if lab == label and k != "if"), None
            )
            if loop is None or loop[0] == "sub":
                raise err(i, f"o{label} {kw} outside an o{label} while or do loop")
            if loop[0] == "repeat":
                raise err(i, f"o{label} {kw}: LinuxCNC breaks and continues while and do "
                          "loops, not repeat")  # fmt: skip
            loop = loop[1]
            st.loop_of[i] = loop
        elif kw == "return":
            if not any(k == "sub" for k, _, _ in stack):
                raise err(i, f"o{label} return outside a subroutine")
    if stack:
        kind, label, i = stack[-1]
        end = {"sub": "endsub", "if": "endif", "while": "endwhile", "do": "while",
               "repeat": "endrepeat"}[kind]  # fmt: skip
        raise err(i, f"o{label} {kind} has no o{label} {end} (the program ends first)")
    if do_stack:
        m, i = do_stack[-1]
        raise err(i, f"WHILE [...] DO{m} has no END{m} (the program ends first)")
    return st


_FULL, _STRAIGHT, _ASSIGN = 0, 1, 2
_STRAIGHT_LETTERS = frozenset("XZFN")


def _kind_of(line: SourceLine, linuxcnc: bool) -> int:
    """How the interpreter runs a line: ``_STRAIGHT`` (G0/G1, X, Z, F, N words, their
    values maybe computed: `ModalMachine.straight`), ``_ASSIGN`` (parameter assignments
    only), else ``_FULL`` (`Interpreter.step`, every question asked)."""
    if (
        line.oword is not None
        or line.macro is not None
        or line.header is not None
        or line.block_delete
        or line.percent
        or line.error is not None
        or (linuxcnc and any(c.text.strip().upper().startswith("ABORT,") for c in line.comments))
    ):
        return _FULL
    if not line.words:
        return _ASSIGN if line.assignments and linuxcnc else _FULL
    if line.assignments:
        return _FULL
    for w in line.words:
        if w.letter == "G":
            if w.expr is not None or w.code not in ("G0", "G1"):
                return _FULL
        elif w.letter not in _STRAIGHT_LETTERS or (w.letter == "N" and w.expr is not None):
            return _FULL
    return _STRAIGHT


def _open(top) -> str:
    return "" if top is None else f" (o{top[1]} {top[0]} is still open)"


def _fmt(v: float) -> str:
    text = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


class Interpreter:
    """Runs ``src`` through ``machine`` (module docstring).

    **Arguments:**

    - `src`: the lexed program.
    - `table`: the dialect's table (its expression rules, its parameters).
    - `options`: the resolved read options (``step_limit``, ``block_delete``).
    - `machine`: the modal machine that executes the blocks.
    """

    def __init__(
        self, src: GcodeText, table: DialectTable, options: ReadOptions, machine: ModalMachine
    ):
        self.src = src
        self.lines = src.lines
        self.table = table
        self.linuxcnc = table.name == "linuxcnc"
        self.options = options
        self.machine = machine
        self.params = Parameters(table.name, table.local_params, self._predefined)
        machine.probe_sink = self._probe_result
        self.runs = [0] * len(self.lines)
        self.computed: set[int] = set()
        self.states: dict[int, object] = {}
        self.frames: list[_Frame] = []
        self.main_repeats: dict[int, int] = {}
        self.compiled: dict[int, object] = {}
        self.plain: dict[int, Block] = {}
        self.loop_line: int | None = None
        self.noted_delete: set[int] = set()
        self.current: SourceLine | None = None
        self.steps = 0
        self.first: int | None = None
        self.tape = False
        self.cycles: list = []  # CycleContour records, in the order the cycles ran
        self.finished: set[int] = set()  # line indices a G70 cut
        self.cycle_setup: dict[str, dict[str, float]] = {}  # Fanuc two-block form
        self.in_cycle: int | None = None  # the line of the cycle whose contour runs
        self.cycle_codes = table.cycles
        self.cycle_lines: set[int] = set()  # lines that call a canned cycle
        self.special_lines: set[int] = set()  # lines with G65 or M73
        self.computed_g: set[int] = set()  # lines with a G or M code computed
        self.flow_lines: set[int] = set()  # lines that end, call or return (M codes)
        self.fast = bytes(_kind_of(ln, table.name == "linuxcnc") for ln in src.lines)
        for ln in src.lines:
            for w in ln.words:
                if w.letter not in "GM":
                    continue
                if w.expr is not None:
                    self.computed_g.add(ln.number)
                    continue
                if w.code in table.cycles:
                    self.cycle_lines.add(ln.number)
                elif w.code in ("M2", "M30", "M97", "M98", "M99"):
                    self.flow_lines.add(ln.number)
                elif w.code in ("G65", "M73"):
                    self.special_lines.add(ln.number)
        self.structure = scan(src, self._err_at, self.linuxcnc)

    # -- errors and values ------------------------------------------------------------------

    def _err_at(self, index: int, msg: str) -> InputError:
        return self.err(self.lines[index], msg)

    def err(self, line: SourceLine, msg: str) -> InputError:
        return InputError(
            f"{msg}: {line.text.strip()!r}", file=self.src.name or "<program>", line=line.number
        )

    def _probe_result(self, values: tuple[float, ...]) -> None:
        """A probing move ended: #5061-#5069 get its end, #5070 its result (LinuxCNC)."""
        for k, v in enumerate(values):
            self.params.numbered[5061 + k] = v

    def _predefined(self, ref):
        if ref == "_call_level":
            return float(len(self.frames))
        if ref == "_line":
            return float(self.current.number) if self.current is not None else 0.0
        return self.machine.predefined(ref)

    def value(self, node, line: SourceLine, what: str) -> float:
        fn = self.compiled.get(id(node)) or self._compile(node)
        try:
            return fn()
        except (ExpressionError, ParameterError) as exc:
            raise self.err(line, f"{what}: {exc}") from None

    def _compile(self, node):
        fn = compile_value(node, self.table.rules, self.params.get, self.params.exists)
        self.compiled[id(node)] = fn
        return fn

    # -- running ----------------------------------------------------------------------------

    def run(self) -> None:
        lines = self.lines
        n = len(lines)
        self.first = next((i for i, ln in enumerate(lines) if not ln.is_blank), None)
        self.tape = (
            self.first is not None and lines[self.first].percent and not lines[self.first].words
        )
        self.current = None
        pc, ended = self._loop(0, 0)
        if self.frames and not ended:
            frame = self.frames[-1]
            raise self.err(
                lines[min(pc, n - 1)],
                f"the program ends inside {frame.label} (called from line "
                f"{lines[frame.back - 1].number}) without returning",
            )
        finish_cycles(self)
        self.machine.finish()

    def _loop(self, pc: int, depth: int) -> tuple[int, bool]:
        """Run from line ``pc`` to the program's end or, with ``depth``, until the call
        at that depth returns; ``(where it stopped, whether the program ended)``."""
        lines = self.lines
        n = len(lines)
        limit = self.options.step_limit
        skip_deleted = self.options.block_delete
        fast = self.fast
        machine = self.machine
        straight, execute, block_of = machine.straight, machine.execute, self.block
        runs, states, frames = self.runs, self.states, self.frames
        while pc < n:
            if depth and len(frames) < depth:
                return pc, False
            line = lines[pc]
            self.current = line
            if line.error is not None:
                self.lex_error(line)
            if line.block_delete and skip_deleted:
                pc += 1
                continue
            self.steps += 1
            if self.steps > limit:
                where = f" (inside the loop of line {self.loop_line})" if self.loop_line else ""
                raise self.err(
                    line,
                    f"the program ran {limit:,} blocks without ending{where}: an endless "
                    "loop? (raise step_limit if it is not)",
                )
            runs[pc] += 1
            kind = fast[pc]
            if kind == _STRAIGHT:  # the common blocks, without step's questions
                block = block_of(line)
                if not straight(block):
                    execute(block)
                nxt = pc + 1
            elif kind == _ASSIGN:
                values = [(a, self.value(a.value, line, a.text)) for a in line.assignments]
                self.assign(values, line)
                nxt = pc + 1
            elif line.percent and not line.words and pc != self.first and self.tape:
                return pc, True  # the tape's end
            else:
                nxt = self.step(pc, line)
            if line.number not in states:
                states[line.number] = machine.state()
            if nxt is None or (line.percent and pc != self.first):
                return pc, True
            if nxt <= pc and nxt != pc + 1:
                self.loop_line = lines[nxt].number
            pc = nxt
        return pc, False

    def run_call(self, start: int, pc: int, label: str) -> None:
        """Run the subroutine whose ``sub`` line is ``start`` (a G7x contour), to its
        return; the caller is line ``pc``."""
        line = self.lines[pc]
        frame = _Frame("sub", pc + 1, label, start)
        self.call(frame, line, start + 1)
        self.params.push({})
        pc, ended = self._loop(start + 1, len(self.frames))
        if ended:
            raise self.err(self.lines[min(pc, len(self.lines) - 1)],
                           f"the program ends inside {label}, the contour of line "
                           f"{line.number}")  # fmt: skip

    def run_lines(self, first: int, last: int, *, count: bool, what: str) -> None:
        """Run lines ``first``..``last`` (indices) in order, as a cycle's P..Q blocks;
        ``count``: they count as run. A block that leads elsewhere is refused."""
        for i in range(first, last + 1):
            line = self.lines[i]
            self.current = line
            if line.error is not None:
                self.lex_error(line)
            if line.block_delete and self.options.block_delete:
                continue
            if count:
                self.runs[i] += 1
            nxt = self.step(i, line)
            if line.number not in self.states:
                self.states[line.number] = self.machine.state()
            if nxt != i + 1 and not (i == last and nxt is not None):
                raise self.err(line, f"{what}: a block of the contour that jumps, calls or "
                               "ends the program is not read")  # fmt: skip

    def lex_error(self, line: SourceLine) -> None:
        for w in line.words:
            if w.letter == "G" and w.expr is None and w.code in self.table.refused:
                raise self.err(line, f"{w.code}: {self.table.refused[w.code]}")
        raise self.err(line, line.error)

    def step(self, pc: int, line: SourceLine) -> int | None:
        """Execute line ``pc``; the index of the next line, None at the program's end."""
        if line.block_delete and line.number not in self.noted_delete:
            self.noted_delete.add(line.number)
            self.machine.note(line.number, "/", "block delete: the line runs (switch off)")
        if line.oword is not None:
            if line.words and not all(w.letter == "N" for w in line.words):
                raise self.err(line, "an O-word statement takes no other words")
            return self.oword(pc, line)
        if line.header is not None:
            self.machine.note(line.number, line.header, "Okuma program header")
            return pc + 1
        if line.macro is not None and line.macro.kind not in ("popen", "pclos", "dprnt", "bprnt"):
            if line.words and not all(w.letter == "N" for w in line.words):
                raise self.err(line, "a macro statement takes no other words than N")
            return self.macro(pc, line)
        if line.macro is not None:
            self.machine.note(line.number, line.macro.kind.upper(), "output statement recorded")
        for c in line.comments:
            body = c.text.strip()
            if c.kind == "paren" and body.upper().startswith("ABORT,") and self.linuxcnc:
                raise self.err(line, f"the program aborts: {body[6:].strip()}")
        if not line.words and not line.assignments:
            return pc + 1
        block = self.block(line)
        codes = self.cycle_codes
        if line.number in self.cycle_lines or (
            line.number in self.computed_g
            and any(w.letter == "G" and w.code in codes for w in block.words)
        ):
            if line.assignments:
                raise self.err(line, "a canned cycle block with parameter assignments")
            return run_cycle(self, pc, line, block)
        values = (
            [(a, self.value(a.value, line, a.text)) for a in line.assignments]
            if line.assignments
            else ()
        )  # evaluated before the line runs (LinuxCNC: set after it is read)
        special = line.number in self.special_lines or line.number in self.computed_g
        if special and any(w.letter == "G" and w.code == "G65" for w in block.words):
            self.assign(values, line)
            return self.g65(pc, line, block)
        if block.words:
            self.machine.execute(block)
            if (
                special
                and self.frames
                and any(w.letter == "M" and w.code == "M73" for w in block.words)
            ):
                self.frames[-1].modes = self.machine.saved  # restored when the call returns
        if values:
            self.assign(values, line)
        return self.flow(pc, line, block)

    def block(self, line: SourceLine) -> Block:
        if not line.computed:
            b = self.plain.get(line.number)
            if b is None:
                b = self.plain[line.number] = Block.plain(line)
            return b
        self.computed.add(line.number)
        words = []
        compiled = self.compiled
        for k, w in enumerate(line.words):
            expr = w.expr
            if expr is None:
                words.append(w)  # a lexed word has what a block word has
                continue
            if (
                not self.linuxcnc
                and isinstance(expr, Param)
                and isinstance(expr.ref, int)
                and not self.params.is_set(expr.ref)
            ):
                continue  # Fanuc: a word whose variable is vacant is as if absent
            fn = compiled.get(id(expr)) or self._compile(expr)
            try:
                v = fn()
            except (ExpressionError, ParameterError) as exc:
                raise self.err(line, f"word {w.letter}{w.text}: {exc}") from None
            letter = w.letter
            # its text: as written ([#1 + 2]) for messages; a T word's number for its digits
            text = _fmt(v) if letter == "T" else w.text
            code = code_of(letter, v) if letter in "GM" else ""
            words.append(BlockWord(letter, v, text, k, code))
        return Block.of(line, tuple(words))

    def assign(self, values, line: SourceLine) -> None:
        for a, v in values:
            ref = a.target.ref
            if not isinstance(ref, (int, str)):
                ref = int(self.value(ref, line, f"parameter number in {a.text}"))
            if not self.linuxcnc and isinstance(ref, int) and ref in (3000, 3006, 3901, 3902):
                if ref == 3000:
                    msg = line.comments[0].text.strip() if line.comments else ""
                    raise self.err(
                        line, f"the program raises alarm {_fmt(v)} (#3000) {msg}".strip()
                    )
                self.machine.note(line.number, f"#{ref}", f"set to {_fmt(v)} (recorded)")
                continue
            try:
                self.params.set(ref, v)
            except ParameterError as exc:
                raise self.err(line, f"{a.text}: {exc}") from None

    # -- what ends, calls and returns --------------------------------------------------------

    def flow(self, pc: int, line: SourceLine, block: Block) -> int | None:
        if line.number not in self.flow_lines and line.number not in self.computed_g:
            return pc + 1  # no M2/M30/M97/M98/M99: on to the next line
        codes = {w.code for w in block.words if w.letter == "M"}
        if codes & {"M2", "M30"}:
            if self.frames and not self.linuxcnc:
                raise self.err(line, "M30/M02 inside a subprogram (M99 returns)")
            return None
        if self.linuxcnc:
            return pc + 1
        words = {w.letter: w for w in block.words}
        if "M98" in codes or "M97" in codes:
            return self.m98(pc, line, words, "M97" if "M97" in codes else "M98")
        if "M99" in codes:
            return self.m99(pc, line, words)
        return pc + 1

    def find_label(self, line: SourceLine, n: int, start: int, what: str) -> int:
        found = self.structure.labels.get(n, [])
        if not found:
            raise self.err(line, f"{what}: there is no block N{n}")
        if len(found) > 1:
            where = ", ".join(str(self.lines[i].number) for i in found)
            raise self.err(line, f"{what}: N{n} is on several lines ({where}): which is meant?")
        return found[0]

    def m98(self, pc, line, words, code) -> int:
        if "P" not in words:
            raise self.err(line, f"{code} needs P (the program or the N label to call)")
        p = int(words["P"].value)
        count = int(words["L"].value) if "L" in words else 1
        if code == "M97":
            if self.table.name != "haas":
                raise self.err(line, "M97 (a local subprogram call) is Haas's")
            target = self.find_label(line, p, pc, f"M97 P{p}")
            start, label = target, f"N{p}"
        else:
            if "L" not in words and p >= 10000:
                count, p = p // 10000, p % 10000
            if p not in self.structure.programs:
                raise self.err(
                    line,
                    f"M98 P{p}: program O{p} is not in this file (subprograms in other files "
                    "are not read)",
                )
            start, label = self.structure.programs[p], f"O{p}"
        if count < 1:
            return pc + 1
        return self.call(
            _Frame(code.lower(), pc + 1, label, start, count), line, start + (code == "M98")
        )

    def m99(self, pc, line, words) -> int | None:
        if not self.frames:
            self.machine.note(line.number, "M99", "M99 in the main program: the control would "
                              "run it again from the top; read once")  # fmt: skip
            return None
        frame = self.frames[-1]
        if frame.passes > 1 and "P" not in words:
            frame.passes -= 1
            return frame.start + (frame.kind != "m97")
        self.ret(line)
        if "P" in words:
            return self.find_label(
                line, int(words["P"].value), frame.back, f"M99 P{_fmt(words['P'].value)}"
            )
        return frame.back

    def g65(self, pc, line, block) -> int:
        words = {}
        for w in block.words:
            if w.letter in words and w.letter != "G":
                raise self.err(line, f"G65: word {w.letter} appears twice")
            words[w.letter] = w
        if "P" not in words:
            raise self.err(line, "G65 needs P (the macro program)")
        p = int(words["P"].value)
        if p not in self.structure.programs:
            raise self.err(line, f"G65 P{p}: program O{p} is not in this file")
        args = {}
        for letter, w in words.items():
            if letter in ("G", "P", "L", "N", "O"):
                continue
            if letter not in _G65_ARGS:
                raise self.err(line, f"G65: word {letter} is not an argument")
            args[_G65_ARGS[letter]] = w.value
        count = int(words["L"].value) if "L" in words else 1
        start = self.structure.programs[p]
        frame = _Frame("g65", pc + 1, f"O{p}", start, count)
        nxt = self.call(frame, line, start + 1)
        try:
            self.params.push(args)
        except ParameterError as exc:
            raise self.err(line, str(exc)) from None
        return nxt

    def call(self, frame: _Frame, line: SourceLine, target: int) -> int:
        if len(self.frames) >= _MAX_CALL_DEPTH:
            raise self.err(line, f"calls nested deeper than {_MAX_CALL_DEPTH} (endless recursion?)")
        self.frames.append(frame)
        return target

    def ret(self, line: SourceLine) -> _Frame:
        frame = self.frames.pop()
        if frame.kind in ("sub", "g65"):
            self.params.pop()
        if frame.modes is not None:
            self.machine.restore_modes(frame.modes)
        return frame

    # -- LinuxCNC O-words -------------------------------------------------------------------

    def oword(self, pc: int, line: SourceLine) -> int:
        o = line.oword
        kw, label = o.keyword, o.label
        st = self.structure
        if not self.linuxcnc:
            raise self.err(line, f"O-word statements (o{label} {kw}) are LinuxCNC's; this "
                           f"program is read as {self.table.name}")  # fmt: skip
        if kw == "sub":
            return st.jump[pc] + 1  # a definition: skipped where it stands
        if kw in ("endsub", "return"):
            if not self.frames or self.frames[-1].kind != "sub":
                raise self.err(line, f"o{label} {kw} outside a call")
            value = self.value(o.args[0], line, f"o{label} {kw}") if o.args else None
            frame = self.ret(line)
            self.params.set_returned(value)
            return frame.back
        if kw == "call":
            if label not in st.subs:
                raise self.err(
                    line,
                    f"o{label} call: no o{label} sub in this program (subroutines in other "
                    "files are not read)",
                )
            args = {k + 1: self.value(a, line, f"argument {k + 1}") for k, a in enumerate(o.args)}
            if len(args) > 30:
                raise self.err(line, f"o{label} call takes at most 30 arguments")
            start, _ = st.subs[label]
            frame = _Frame("sub", pc + 1, f"o{label}", start)
            nxt = self.call(frame, line, start + 1)
            self.params.push(args)
            return nxt
        if kw == "if":
            return self._branch(pc, line)
        if kw in ("elseif", "else"):
            return st.endif[pc] + 1  # the branch before it ran: on past endif
        if kw == "endif":
            return pc + 1
        if kw == "while":
            if pc in st.back:  # the closing while of a do ... while
                cond = self.value(o.args[0], line, f"o{label} while")
                return st.back[pc] + 1 if cond != 0.0 else pc + 1
            cond = self.value(o.args[0], line, f"o{label} while")
            return pc + 1 if cond != 0.0 else st.jump[pc] + 1
        if kw == "endwhile":
            return st.back[pc]
        if kw == "do":
            return pc + 1
        if kw == "repeat":
            count = self.value(o.args[0], line, f"o{label} repeat")
            reps = self._repeats()
            reps[pc] = int(count)
            return pc + 1 if reps[pc] > 0 else st.jump[pc] + 1
        if kw == "endrepeat":
            start = st.back[pc]
            reps = self._repeats()
            reps[start] = reps.get(start, 1) - 1
            return start + 1 if reps[start] > 0 else pc + 1
        if kw == "break":
            loop = st.loop_of[pc]
            self._repeats().pop(loop, None)
            return st.jump[loop] + 1
        if kw == "continue":
            loop = st.loop_of[pc]
            end = st.jump[loop]
            return loop if self.lines[loop].oword.keyword == "while" else end  # do: its while
        raise self.err(line, f"o{label} {kw} is not understood")  # pragma: no cover

    def _repeats(self) -> dict[int, int]:
        return self.frames[-1].repeats if self.frames else self.main_repeats

    def _branch(self, pc: int, line: SourceLine) -> int:
        st = self.structure
        chain = [pc, *st.branches[pc]]  # if, elseif..., else?, endif
        for i in chain[:-1]:
            o = self.lines[i].oword
            if i != pc:
                self.runs[i] += 1
            if o.keyword == "else":
                return i + 1
            if self.value(o.args[0], self.lines[i], f"o{o.label} {o.keyword}") != 0.0:
                return i + 1
        return chain[-1] + 1

    # -- Fanuc macro B ----------------------------------------------------------------------

    def macro(self, pc: int, line: SourceLine) -> int:
        m = line.macro
        st = self.structure
        if self.linuxcnc:
            raise self.err(line, f"macro B statements ({m.kind.split('_')[0].upper()}) are "
                           "Fanuc's; this program is read as linuxcnc")  # fmt: skip
        if m.kind == "goto":
            return self._goto(pc, line, m.target)
        if m.kind in ("if_goto", "if_then"):
            cond = self.value(m.cond, line, "IF [...]")
            if cond == 0.0:
                return pc + 1
            if m.kind == "if_goto":
                return self._goto(pc, line, m.target)
            self.assign([(m.then, self.value(m.then.value, line, m.then.text))], line)
            return pc + 1
        if m.kind == "while":
            cond = self.value(m.cond, line, "WHILE [...]")
            return pc + 1 if cond != 0.0 else st.jump[pc] + 1
        if m.kind == "end":
            return st.back[pc]
        raise self.err(line, f"{m.kind} is not understood")  # pragma: no cover

    def _goto(self, pc: int, line: SourceLine, target) -> int:
        n = self.value(target, line, "GOTO")
        if n != int(n) or n < 0:
            raise self.err(line, f"GOTO {n:g}: not a sequence number")
        return self.find_label(line, int(n), pc, f"GOTO {int(n)}")
