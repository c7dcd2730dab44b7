"""Rewrite a Fanuc/Haas lathe program into LinuxCNC's dialect, so that `rs274 -g` runs it.

A test helper, not package code (issue 38): the acceptance of the canned-cycle expansion is
that our reading of a Fanuc program gives the moves rs274 makes from the same program written
here in LinuxCNC's G7x form. [`rewrite_fanuc`][] takes the text of a Fanuc 0i / Haas program
(lathe G-code system A) and returns a [`Rewrite`][]: the LinuxCNC text and the notes of what
could not be carried over exactly. What it does:

- the blocks `N(P)` to `N(Q)` of a G70/G71/G72/G73 become `o<n> sub` ... `o<n> endsub` at
  the top of the program (rs274 refuses a sub defined after the G7x that uses it: "sub found
  in illegal location"); when they follow the roughing block, they leave the main flow, as on
  the control (after G71/G72/G73 it goes on after the Q block). Inside the sub every move
  carries its absolute X and Z (U/W resolved from the cycle's start point); G41/G42/G40 go
  out of it (rs274 ignores them there) to the caller: `G42` before the G70, `G40` after it;
  `,C` / `,R` become rs274's `C` / `A` (the same corner only where the corner is square:
  Fanuc's chamfer is C along each leg, rs274's ends where a fillet of radius C would touch);
- `G71 U(depth) R(retract)` + `G71 P Q U W F` (and Haas's one block `G71 P Q U W D F`) become
  `G71 Q<n> X Z D I R` (I = depth, R = retract, D = U/2: rs274 keeps one distance all round
  the profile where Fanuc shifts it by U/2 in X and W in Z, a note says so); G72 alike with
  D = W; the tool then goes back to the start point, as Fanuc's cycles end;
- G73 (pattern repeat; rs274's G73 is a drilling cycle) is written out pass by pass: the
  contour shifted by $\\Delta i (d-k)/(d-1) + U/2$ in X and $\\Delta k (d-k)/(d-1) + W$ in Z
  for pass $k$ of $d$, each from the start point and back to it;
- `G70 P Q [F]` becomes `F`, `G70 Q<n> X Z` and a rapid back to the start point (Fanuc's G70
  returns there; rs274's stops at the profile's end): the programmed contour, uncompensated,
  which is what our reading of the G70 gives before nose compensation. With
  `compensation=True` the contour's `G41/G42` goes before the G70 and `G40` after it; rs274
  then makes the G70's rapid to X Z (where the tool already stands) the entry move: with a
  zero-radius tool it runs, with a real radius it refuses it ("Length of cutter compensation
  entry move is not greater than the tool radius"). The
  feed is the G70's F, else the first F of the contour (rs274 ignores F inside the sub);
- diameter X: `G7` (I, K, R stay radii in both); U/W: absolute X/Z from the tracked position;
  `T0101`: `T1 M6` (no G43: the standalone rs274's own tool table gives tool 1 a length of
  0.511 in); `T0100` (offset cancel): a comment; G98/G99: G94/G95; `G50 S`: the clamp, written
  as `G96 D`; `G50 X Z`: `G92 X Z`; `G28 U0 W0`: `G91 G28 X0 Z0` then `G90` (through the
  point where the tool stands, as U0 W0 say);
  `G53 X`: `G53 G0 X` and the motion mode restored; G80 with a motion code in the block
  (Haas's safe-start line): dropped; M31/M33 (Haas chip conveyor): comments; `M98 P` /
  `O..` ... `M99`: `o<n> call` / `o<n> sub` ... `o<n> endsub`; `%`, `O1234`, `:0100`: gone or
  comments.

Markers: the rewritten text puts `(PIECS ROUGH G71 P10 Q20)` / `(PIECS FINISH G70 P10 Q20)`
and `(PIECS END ...)` around each cycle; rs274 prints them as `COMMENT("...")` canon lines, which
[`cycle_parts`][] uses to cut its output into the cycles' moves.

Anything else (macro B, G90/G92/G94 box cycles, G74-G76, an unknown word) raises
`RewriteError` naming the line: the helper rewrites our corpus, not every program.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

__all__ = ["Rewrite", "RewriteError", "cycle_parts", "rewrite_fanuc"]


class RewriteError(ValueError):
    """A construct the helper does not rewrite (the message names the line)."""


@dataclass(frozen=True)
class Rewrite:
    """The LinuxCNC text, the sub of each (P, Q) contour, and what is not carried exactly."""

    text: str
    subs: dict[tuple[int, int], int]
    notes: tuple[str, ...] = field(default=())


_TOKEN = re.compile(r"\s*(,[CR][+-]?[0-9.]+|[A-Z][+-]?[0-9.]*|%)")
_MACRO = re.compile(r"#|\[|\bIF\b|\bWHILE\b|\bGOTO\b|\bEND\d|\bDO\d")
_KEEP_M = {0, 1, 2, 3, 4, 5, 8, 9, 30}


@dataclass
class _Block:
    number: int  # 1-based line in the source
    n: int | None  # N label
    g: list[str]  # G codes, normalised ("G0", "G71")
    m: list[int]
    words: dict[str, str]  # letter (or ",C" / ",R") -> number text
    comment: str
    raw: str

    def num(self, letter: str) -> float:
        return float(self.words[letter])


def _num(v: float) -> str:
    text = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _parse(number: int, raw: str) -> _Block | None:
    line = raw.rstrip("\r\n")
    comments = re.findall(r"\(([^)]*)\)", line)
    code = re.sub(r"\([^)]*\)", " ", line).upper().strip()
    if code in ("%", ""):
        return _Block(number, None, [], [], {}, " ".join(comments), raw) if comments else None
    if _MACRO.search(code):
        raise RewriteError(f"line {number}: macro B is not rewritten: {line.strip()!r}")
    if code.startswith(":") or (code.startswith("O") and re.match(r"O\d+\s*$", code)):
        label = code.lstrip(":O").strip()
        return _Block(number, None, ["O"], [], {"O": label}, " ".join(comments), raw)
    pos, words, g, m, n = 0, {}, [], [], None
    while pos < len(code):
        t = _TOKEN.match(code, pos)
        if t is None:
            raise RewriteError(f"line {number}: cannot read {code[pos:]!r}")
        pos = t.end()
        tok = t.group(1)
        if tok == "%":
            continue
        letter, value = (tok[:2], tok[2:]) if tok.startswith(",") else (tok[0], tok[1:])
        if letter == "G":
            g.append("G" + _num(float(value)))
        elif letter == "M":
            m.append(int(float(value)))
        elif letter == "N" and n is None and not words and not g and not m:
            n = int(value)
        else:
            if letter in words:
                raise RewriteError(f"line {number}: word {letter} twice")
            words[letter] = value
    return _Block(number, n, g, m, words, " ".join(comments), raw)


def _comment(text: str) -> str:
    return "(" + text.replace("(", "[").replace(")", "]") + ")" if text else ""


class _Writer:
    def __init__(self, blocks: list[_Block], units: str, compensation: bool = False):
        self.blocks = blocks
        self.compensation = compensation
        self.units = units
        self.x: float | None = None  # diameter
        self.z: float | None = None
        self.motion = "G0"
        self.clamp: float | None = None
        self.rough: dict[str, tuple[float, float | None]] = {}  # G71/G72/G73 first blocks
        self.subs: dict[tuple[int, int], int] = {}
        self.sub_text: list[str] = []
        self.notes: list[str] = []
        self.out: list[str] = []
        self.skip: set[int] = set()  # block indexes that left the main flow
        self.calls: dict[int, int] = {}  # M98 program number -> o number

    # ------------------------------------------------------------------ helpers
    def err(self, b: _Block, msg: str) -> RewriteError:
        return RewriteError(f"line {b.number}: {msg}: {b.raw.strip()!r}")

    def find(self, n: int, after: int, b: _Block) -> int:
        for k in range(after + 1, len(self.blocks)):
            if self.blocks[k].n == n:
                return k
        raise self.err(b, f"N{n} does not come after this block")

    def target(self, b: _Block, x0, z0) -> tuple[float | None, float | None]:
        x, z = x0, z0
        if "X" in b.words:
            x = b.num("X")
        if "U" in b.words:
            if x0 is None:
                raise self.err(b, "U with no known X position")
            x = x0 + b.num("U")
        if "Z" in b.words:
            z = b.num("Z")
        if "W" in b.words:
            if z0 is None:
                raise self.err(b, "W with no known Z position")
            z = z0 + b.num("W")
        return x, z

    def axes(self, b: _Block, x, z) -> str:
        parts = []
        if "X" in b.words or "U" in b.words:
            parts.append(f"X{_num(x)}")
        if "Z" in b.words or "W" in b.words:
            parts.append(f"Z{_num(z)}")
        return " ".join(parts)

    def arc_words(self, b: _Block) -> str:
        return " ".join(f"{k}{_num(b.num(k))}" for k in ("I", "K", "R") if k in b.words)

    # ------------------------------------------------------------------ contours
    def contour(self, b: _Block, p: int, q: int, ip: int, iq: int):
        """The blocks N(P)..N(Q) as (motion, x, z, arc words, corner words, feed) from the
        position at the cycle, the comp code found in them, and the block's F."""
        x, z, motion = self.x, self.z, self.motion
        if x is None or z is None:
            raise self.err(b, "a canned cycle with no known start point")
        moves, comp, feed = [], None, None
        for blk in self.blocks[ip : iq + 1]:
            for code in blk.g:
                if code in ("G0", "G1", "G2", "G3"):
                    motion = code
                elif code in ("G41", "G42"):
                    comp = code
                elif code != "G40":
                    raise self.err(blk, f"{code} inside the contour N{p}-N{q} is not rewritten")
            if blk.m:
                raise self.err(blk, "an M code inside the contour is not rewritten")
            if "F" in blk.words and feed is None:
                feed = blk.num("F")
            if not ({"X", "Z", "U", "W"} & blk.words.keys()):
                continue
            x, z = self.target(blk, x, z)
            corner = ""
            if ",C" in blk.words:
                corner = f"C{_num(blk.num(',C'))}"
            elif ",R" in blk.words:
                corner = f"A{_num(blk.num(',R'))}"
            arc = self.arc_words(blk) if motion in ("G2", "G3") else ""
            moves.append((motion, x, z, arc, corner, blk))
        points = [(self.x, self.z)] + [(mv[1], mv[2]) for mv in moves]
        for k in range(len(moves) - 1):
            (m1, *_, c1, _), (m2, *_, blk) = moves[k], moves[k + 1]
            if c1 or m1 not in ("G0", "G1") or m2 not in ("G0", "G1"):
                continue
            (x0, z0), (x1, z1), (x2, z2) = points[k : k + 3]
            if abs((x1 - x0) * (z2 - z1) - (z1 - z0) * (x2 - x1)) < 1e-12:
                raise self.err(
                    blk,
                    "two collinear moves in a row in the contour (rs274's G7x refuses them: "
                    "'Cannot intersect parallel lines')",
                )
        return moves, comp, feed

    def sub_for(self, b: _Block, p: int, q: int, moves) -> int:
        if (p, q) in self.subs:
            return self.subs[(p, q)]
        number = 100 + len(self.subs)
        self.subs[(p, q)] = number
        lines = [f"o{number} sub (N{p}-N{q})"]
        for motion, x, z, arc, corner, blk in moves:
            label = f"N{blk.n} " if blk.n is not None else ""
            words = " ".join(w for w in (motion, f"X{_num(x)} Z{_num(z)}", arc, corner) if w)
            lines.append(f"{label}{words}")
        lines.append(f"o{number} endsub")
        self.sub_text += lines
        return number

    def cycle(self, i: int, b: _Block, code: str) -> None:
        if "P" not in b.words:  # the first block of the two-block form
            if code == "G70":
                raise self.err(b, "G70 without P and Q")
            depth_letter = "W" if code == "G72" else "U"
            if code == "G73":
                self.rough[code] = (b.num("U"), b.num("W"), b.num("R"))
            else:
                retract = b.num("R") if "R" in b.words else None
                self.rough[code] = (b.num(depth_letter), retract)
            self.out.append(_comment(f"{b.raw.strip()}: the next block's depth and retract"))
            return
        p, q = int(b.num("P")), int(b.num("Q"))
        ip = self.find(p, i, b) if code != "G70" else self.find_any(p, b)
        iq = self.find(q, ip, b)
        moves, comp, feed = self.contour(b, p, q, ip, iq)
        if code != "G70" and ip == i + 1:
            self.skip.update(range(ip, iq + 1))
        sub = self.sub_for(b, p, q, moves)
        ax, az = _num(self.x), _num(self.z)
        tag = f"{code} P{p} Q{q}"
        if code == "G70":
            f = b.num("F") if "F" in b.words else feed
            self.out.append(f"(PIECS FINISH {tag})")
            if f is not None:
                self.out.append(f"F{_num(f)}")
            comp = comp if self.compensation else None
            if comp:
                self.out.append(comp)
            self.out.append(f"G70 Q{sub} X{ax} Z{az}")
            if comp:
                self.out.append("G40")
            self.out.append(f"G0 X{ax} Z{az}")
            self.out.append(f"(PIECS END {tag})")
            self.motion = "G0"
            return
        if code == "G73":
            self.pattern_repeat(b, tag, moves)
            return
        if code in self.rough:
            depth, retract = self.rough.pop(code)
        elif "D" in b.words:  # Haas's one-block form
            depth, retract = b.num("D"), None
        else:
            raise self.err(b, f"{code} with P/Q needs its first block or a D word")
        allow_u = abs(b.num("U")) / 2 if "U" in b.words else 0.0
        allow_w = abs(b.num("W")) if "W" in b.words else 0.0
        allow = allow_w if code == "G72" else allow_u
        other = allow_u if code == "G72" else allow_w
        if other and other != allow:
            self.notes.append(
                f"line {b.number}: {tag} leaves U{_num(2 * allow_u)} W{_num(allow_w)}; rs274 "
                f"keeps one distance D{_num(allow)} all round the profile"
            )
        self.out.append(f"(PIECS ROUGH {tag})")
        if "F" in b.words:
            self.out.append(f"F{_num(b.num('F'))}")
        words = f"{code} Q{sub} X{ax} Z{az} D{_num(allow)} I{_num(abs(depth))}"
        if retract is not None:
            words += f" R{_num(retract)}"
        self.out += [words, f"G0 X{ax} Z{az}", f"(PIECS END {tag})"]
        self.motion = "G0"

    def find_any(self, n: int, b: _Block) -> int:
        hits = [k for k, blk in enumerate(self.blocks) if blk.n == n]
        if not hits:
            raise self.err(b, f"no block N{n}")
        return hits[0]

    def pattern_repeat(self, b: _Block, tag: str, moves) -> None:
        if "G73" not in self.rough:
            raise self.err(b, "G73 P Q without its first block G73 U W R")
        di, dk, d = self.rough.pop("G73")
        d = int(round(d))
        u = b.num("U") if "U" in b.words else 0.0
        w = b.num("W") if "W" in b.words else 0.0
        ax, az = self.x, self.z
        self.out.append(f"(PIECS ROUGH {tag})")
        if "F" in b.words:
            self.out.append(f"F{_num(b.num('F'))}")
        for k in range(1, d + 1):
            share = (d - k) / (d - 1) if d > 1 else 0.0
            sx, sz = 2 * di * share + u, dk * share + w  # X shift as a diameter
            self.out.append(f"(PASS {k} OF {d}: X+{_num(sx)} Z+{_num(sz)})")
            for motion, x, z, arc, corner, blk in moves:
                if corner:
                    raise self.err(blk, "a ,C/,R corner in a G73 contour is not rewritten")
                self.out.append(
                    " ".join(w for w in (motion, f"X{_num(x + sx)} Z{_num(z + sz)}", arc) if w)
                )
            self.out.append(f"G0 X{_num(ax)} Z{_num(az)}")
        self.out.append(f"(PIECS END {tag})")
        self.motion = "G0"

    # ------------------------------------------------------------------ main flow
    def block(self, i: int, b: _Block) -> None:
        if b.g == ["O"]:
            self.out.append(_comment(f"O{b.words['O']} {b.comment}".strip()))
            return
        head = f"N{b.n} " if b.n is not None else ""
        cycles = [c for c in b.g if c in ("G70", "G71", "G72", "G73")]
        if cycles:
            self.cycle(i, b, cycles[0])
            return
        g_out, extra_after = [], []
        special = None
        for code in b.g:
            if code in ("G0", "G1", "G2", "G3"):
                self.motion = code
                g_out.append(code)
            elif code in ("G18", "G20", "G21", "G40", "G41", "G42", "G54", "G97"):
                g_out.append(code)
            elif code == "G96":
                g_out.append(f"G96 D{_num(self.clamp)}" if self.clamp else "G96")
            elif code == "G98":
                g_out.append("G94")
            elif code == "G99":
                g_out.append("G95")
            elif code == "G80":
                if not any(c in ("G0", "G1", "G2", "G3") for c in b.g):
                    g_out.append("G80")
            elif code in ("G28", "G50", "G53"):
                special = code
            else:
                raise self.err(b, f"{code} is not rewritten")
        words = []
        for letter in ("S", "F"):
            if letter in b.words:
                if not (special == "G50" and letter == "S"):
                    words.append(f"{letter}{_num(b.num(letter))}")
        tool = ""
        if "T" in b.words:
            digits = b.words["T"]
            value = int(float(digits))
            t, off = (value // 100, value % 100) if len(digits) > 2 else (value, value)
            if off == 0 or t == 0:
                extra_after.append(_comment(f"T{digits}: offset cancel"))
            else:
                tool = f"T{t} M6"
                extra_after.append(_comment(f"T{digits}: tool {t}, offset {off}"))
        m_out = []
        for m in b.m:
            if m in _KEEP_M:
                m_out.append(f"M{m}")
            elif m in (31, 33):
                extra_after.append(_comment(f"M{m}: Haas chip conveyor"))
            elif m == 98:
                prog = int(b.num("P"))
                if prog > 9999 or "L" in b.words:
                    raise self.err(b, "M98 with a repeat count is not rewritten")
                self.calls.setdefault(prog, prog)
                m_out.append(f"o{prog} call")
            else:
                raise self.err(b, f"M{m} is not rewritten")
        axes = ""
        if special == "G50":
            if "S" in b.words:
                self.clamp = b.num("S")
                extra_after.append(_comment(f"G50 S{b.words['S']}: spindle clamp, G96 D"))
            if {"X", "Z"} & b.words.keys():
                self.x, self.z = self.target(b, self.x, self.z)
                axes = f"G92 {self.axes(b, self.x, self.z)}"
        elif special == "G28":
            incremental = {"U", "W"} & b.words.keys()
            if incremental and {"X", "Z"} & b.words.keys():
                raise self.err(b, "G28 with both absolute and incremental words")
            if incremental:  # through the point where the tool is (plus U/W): G91 G28
                named = [
                    f"{a}{_num(b.num(k))}" for k, a in (("U", "X"), ("W", "Z")) if k in b.words
                ]
                axes = "G91 G28 " + " ".join(named)
                extra_after.insert(0, "G90")
            else:
                axes = "G28 " + self.axes(
                    b,
                    b.num("X") if "X" in b.words else None,
                    b.num("Z") if "Z" in b.words else None,
                )
            if "X" in b.words or "U" in b.words:
                self.x = None
            if "Z" in b.words or "W" in b.words:
                self.z = None
        elif special == "G53":
            if {"U", "W"} & b.words.keys():
                raise self.err(b, "G53 with U/W")
            named = [f"{a}{_num(b.num(a))}" for a in ("X", "Z") if a in b.words]
            axes = "G53 G0 " + " ".join(named)
            if "X" in b.words:
                self.x = None
            if "Z" in b.words:
                self.z = None
            if self.motion != "G0":
                extra_after.append(self.motion)
        elif {"X", "Z", "U", "W"} & b.words.keys():
            x, z = self.target(b, self.x, self.z)
            axes = self.axes(b, x, z)
            if self.motion in ("G2", "G3"):
                axes += " " + self.arc_words(b)
            self.x, self.z = x, z
        unknown = set(b.words) - set("XZUWIKRSFTP") - {"O"}
        if unknown:
            raise self.err(b, f"word {sorted(unknown)[0]} is not rewritten")
        parts = [p for p in (" ".join(g_out), axes, " ".join(words), " ".join(m_out)) if p]
        if tool:
            self.out.append(f"{head}{tool}".strip())
            head = ""
        if parts:
            self.out.append(
                head + " ".join(parts) + (f" {_comment(b.comment)}" if b.comment else "")
            )
        elif b.comment:
            self.out.append((head + _comment(b.comment)).strip())
        elif head and extra_after and extra_after[0].startswith("("):
            extra_after[0] = head + extra_after[0]
        elif head:
            self.out.append(head.strip())
        self.out += extra_after


def rewrite_fanuc(text: str, *, units: str = "mm", compensation: bool = False) -> Rewrite:
    """`text` (a Fanuc 0i / Haas lathe program, system A) rewritten for LinuxCNC's rs274.

    **Arguments:**

    - `text`: the program.
    - `units`: the units before the program's first G20/G21 (the control's setting).
    - `compensation`: keep a G70 contour's G41/G42 (before the G70) and G40 (after it).

    **Returns:** a [`Rewrite`][].

    **Raises:** `RewriteError` naming the line for what it does not rewrite.
    """
    if units not in ("mm", "in"):
        raise ValueError(f"units must be 'mm' or 'in', got {units!r}")
    blocks = [b for k, raw in enumerate(text.splitlines(), 1) if (b := _parse(k, raw))]
    main, programs, current = [], {}, None
    ended = False
    for b in blocks:
        if b.g == ["O"] and ended:
            current = int(b.words["O"])
            programs[current] = []
            continue
        if current is not None:
            if 99 in b.m:
                current = None
                continue
            programs[current].append(b)
            continue
        main.append(b)
        if 30 in b.m or 2 in b.m:
            ended = True
    w = _Writer(main, units, compensation)
    w.out.append("G18 G7 G95 " + ("G21" if units == "mm" else "G20"))
    for i, b in enumerate(main):
        if i in w.skip:
            continue
        w.block(i, b)
    subs = []
    for number, body in programs.items():
        if number not in w.calls:
            continue
        inner = _Writer(body, units)
        for i, b in enumerate(body):
            if {"U", "W"} & b.words.keys():
                raise inner.err(b, "U/W in a subprogram is not rewritten")
            inner.block(i, b)
        subs += [f"o{number} sub", *inner.out, f"o{number} endsub"]
    head = ["(rewritten for LinuxCNC by tests/gcode/fanuc_rewrite.py)"]
    body = head + w.sub_text + subs + w.out
    if not any(re.match(r"(N\d+ )?.*\bM(2|30)\b", ln) for ln in w.out):
        body.append("M2")
    return Rewrite("\n".join(body) + "\n", dict(w.subs), tuple(w.notes))


def cycle_parts(output: str) -> dict[str, list[str]]:
    """rs274's output cut at the helper's markers: ``{"FINISH G70 P10 Q20": [canon lines],
    "ROUGH G71 P10 Q20": [...]}``, each part opening with the units line in force (for
    `parse_canon`); a cycle met twice gets `` #2`` after its name."""
    parts: dict[str, list[str]] = {}
    current, units = None, None
    for line in output.splitlines():
        if "USE_LENGTH_UNITS(" in line:
            units = line
        m = re.search(r'COMMENT\("PIECS (.*)"\)', line)
        if m and m.group(1).startswith(("FINISH ", "ROUGH ")):
            name = m.group(1)
            k = 2
            while name in parts:
                name, k = f"{m.group(1)} #{k}", k + 1
            current = name
            parts[current] = [units] if units else []
            continue
        if m and m.group(1).startswith("END "):
            current = None
            continue
        if current is not None:
            parts[current].append(line)
    return parts
