"""The dialects of lathe part programs: LinuxCNC, Fanuc (system A), Haas and Okuma.

A [`Dialect`][] is a name and the reason it was chosen; [`detect_dialect`][] finds it
from what a lexed program contains (an Okuma ``$NAME.MIN%`` header; LinuxCNC's G7/G8,
O-word subroutines and named parameters; Fanuc's U/W words, G50, macro B and P/Q
blocks; Haas's codes on top of Fanuc's). [`DialectTable`][] holds what the reader needs
to know of each: its G-code groups and what several codes of one group in a block
mean, the defaults (diameter or radius X, feed per minute or per revolution), what
G98/G99 and G90 mean, how parameters evaluate, and what it refuses by name.

The tables and the sources they were checked against: docs/models/part_programs.md,
"Dialects".
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

from ._expr import FANUC_RULES, LINUXCNC_RULES, Rules

DIALECTS = ("linuxcnc", "fanuc", "haas", "okuma")


@dataclass(frozen=True)
class Dialect:
    """The dialect a program is read in: ``name`` (one of ``DIALECTS``) and ``reason``
    (``"given"`` or what in the program made it: ``"G71 P/Q blocks, U/W words"``)."""

    name: str
    reason: str = "given"

    def __str__(self) -> str:
        return f"{self.name} ({self.reason})"


@dataclass(frozen=True)
class DialectTable:
    """What the reader needs to know of a dialect (module docstring)."""

    name: str
    groups: dict[str, str]
    """G code -> its modal group (``"motion"``, ``"units"``, ``"nonmodal"``, ...)."""
    same_group: str
    """``"refuse"`` (LinuxCNC: an error) or ``"last"`` (Fanuc: the last code is valid)."""
    diameter: bool
    """X words are diameters unless the program says otherwise."""
    feed_per_rev: bool
    """Feed per revolution unless the program says otherwise."""
    rules: Rules
    refused: dict[str, str] = field(default_factory=dict)
    """G code -> why it is refused (canned cycles not expanded, other planes, ...)."""
    m_codes: frozenset[str] | None = None
    """The M codes understood; None: any M code (recorded, machine-specific)."""
    incremental_uw: bool = False
    """U and W are incremental X (in the X mode) and Z."""
    turret: bool = False
    """T words index a turret (``T0101`` = tool 1, offset 1); else T selects and M6 changes."""
    local_params: int = 30
    """Numbered parameters local to a subroutine or macro call: #1 .. this."""
    cycles: frozenset[str] = frozenset()
    """The canned-cycle codes the reader runs (G70-G73: ``_cycle_run``)."""


_LATHE_PLANE = "only the XZ plane (G18) is read for a lathe"
_THREAD = (
    "threading is not understood: a thread is a helix synchronised with the spindle, "
    "not a contour of lines and arcs"
)
_GROOVE = "is a grooving or peck drilling cycle, not a contour: not read"
_LINUXCNC_CYCLES = frozenset(
    ("G70", "G71", "G71.1", "G71.2", "G72", "G72.1", "G72.2", "G76")  # G76: threads, read
)
_FANUC_CYCLES = frozenset(("G70", "G71", "G72", "G73"))
_DRILL = "drilling cycles (G81-G89) are not read: they drill, they do not cut a contour"

#: LinuxCNC's drilling cycles the reader runs (in the XY plane, G17: along Z, as a
#: lathe drills on its axis) and its probing moves
LINUXCNC_DRILLING = frozenset(("G73", "G81", "G82", "G83", "G85", "G89"))
LINUXCNC_PROBING = frozenset(("G38.2", "G38.3", "G38.4", "G38.5"))

_LINUXCNC_GROUPS = {
    **dict.fromkeys(("G0", "G1", "G2", "G3", "G80"), "motion"),
    **dict.fromkeys(LINUXCNC_DRILLING | LINUXCNC_PROBING, "motion"),
    **dict.fromkeys(("G17", "G18", "G19"), "plane"),
    **dict.fromkeys(("G20", "G21"), "units"),
    **dict.fromkeys(("G7", "G8"), "diameter"),
    **dict.fromkeys(("G40", "G41", "G42", "G41.1", "G42.1"), "comp"),
    **dict.fromkeys(("G43", "G43.1", "G43.2", "G49"), "length"),
    **dict.fromkeys(("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"), "coord"),
    **dict.fromkeys(("G61", "G61.1", "G64"), "path"),
    **dict.fromkeys(("G90", "G91"), "distance"),
    **dict.fromkeys(("G90.1", "G91.1"), "arc_distance"),
    **dict.fromkeys(("G94", "G95"), "feed_mode"),
    **dict.fromkeys(("G96", "G97"), "spindle_mode"),
    **dict.fromkeys(("G98", "G99"), "return_mode"),
    **dict.fromkeys(
        ("G4", "G10", "G28", "G28.1", "G30", "G30.1", "G53", "G92", "G92.1", "G92.2", "G92.3"),
        "nonmodal",
    ),
}
_LINUXCNC_REFUSED = {
    "G17.1": _LATHE_PLANE,
    "G18.1": _LATHE_PLANE,
    "G19.1": _LATHE_PLANE,
    "G93": "inverse-time feed (G93) is not read",
    "G5": "splines (G5) are not read",
    "G5.1": "splines (G5.1) are not read",
    "G5.2": "NURBS (G5.2) are not read",
    **dict.fromkeys(("G32", "G33", "G33.1"), _THREAD),
    **dict.fromkeys(
        ("G74", "G84"), "tapping cycles (G74/G84) are synchronised with the spindle: not read"
    ),
    **dict.fromkeys(
        ("G86", "G87", "G88"),
        "boring cycles that stop or orient the spindle (G86-G88) are not read",
    ),
}
_LINUXCNC_M = frozenset(
    "M0 M1 M2 M3 M4 M5 M6 M7 M8 M9 M19 M30 M48 M49 M50 M51 M52 M53 M60 M61 M62 M63 M64 "
    "M65 M66 M67 M68 M70 M71 M72 M73".split()
    + [f"M{n}" for n in range(100, 200)]
)

# Fanuc 0i/30i lathe, G-code system A (Fanuc 0i-TF operator's manual, "G code list")
_FANUC_GROUPS = {
    **dict.fromkeys(("G0", "G1", "G2", "G3"), "motion"),
    **dict.fromkeys(("G96", "G97"), "spindle_mode"),
    **dict.fromkeys(("G98", "G99"), "feed_mode"),
    **dict.fromkeys(("G20", "G21"), "units"),
    **dict.fromkeys(("G40", "G41", "G42"), "comp"),
    **dict.fromkeys(("G22", "G23"), "stroke"),
    **dict.fromkeys(("G25", "G26"), "spindle_check"),
    "G80": "cycle",
    **dict.fromkeys(("G54", "G55", "G56", "G57", "G58", "G59"), "coord"),
    **dict.fromkeys(("G61", "G62", "G63", "G64"), "path"),
    **dict.fromkeys(("G17", "G18", "G19"), "plane"),
    **dict.fromkeys(("G43", "G49"), "length"),
    **dict.fromkeys(("G4", "G9", "G10", "G11", "G28", "G30", "G50", "G53"), "nonmodal"),
}
_FANUC_REFUSED = {
    "G17": _LATHE_PLANE,
    "G19": _LATHE_PLANE,
    **dict.fromkeys(("G32", "G34", "G76", "G92"), _THREAD),
    "G74": f"G74 (face grooving / peck drilling along Z) {_GROOVE}",
    "G75": f"G75 (grooving along X) {_GROOVE}",
    "G90": "G90 on a Fanuc lathe (G-code system A) is the turning box cycle: not expanded "
    "yet (absolute and incremental are X/Z and U/W)",
    "G94": "G94 on a Fanuc lathe (G-code system A) is the facing box cycle: not expanded yet "
    "(feed per minute is G98)",
    "G91": "G91 does not exist in Fanuc lathe G-code system A (incremental moves use U/W)",
    **dict.fromkeys(("G83", "G84", "G85", "G87", "G88", "G89"), _DRILL),
    "G31": "skip moves (G31) are not read in a part program",
    "G66": "modal macro calls (G66) are not read",
    "G12.1": "polar coordinate interpolation (G12.1) is not read",
    "G7.1": "cylindrical interpolation (G7.1) is not read",
}
_HAAS_GROUPS = {
    **_FANUC_GROUPS,
    **dict.fromkeys(("G103", "G187"), "haas_path"),
    "G154": "coord",
    **{f"G{n}": "coord" for n in range(110, 130)},
}
_OKUMA_GROUPS = {
    **dict.fromkeys(("G0", "G1", "G2", "G3"), "motion"),
    **dict.fromkeys(("G20", "G21"), "units"),
    **dict.fromkeys(("G40", "G41", "G42"), "comp"),
    **dict.fromkeys(("G90", "G91"), "distance"),
    **dict.fromkeys(("G94", "G95"), "feed_mode"),
    **dict.fromkeys(("G96", "G97"), "spindle_mode"),
    **dict.fromkeys(("G4", "G50"), "nonmodal"),
    **dict.fromkeys(("G13", "G14"), "turret"),
    "G18": "plane",
    "G80": "cycle",
}
_OKUMA_REFUSED = {
    **dict.fromkeys(
        ("G85", "G86", "G87", "G88"), "Okuma LAP cycles (G85-G88) are not expanded yet"
    ),
    **dict.fromkeys(("G33", "G71", "G76"), _THREAD),
    "G17": _LATHE_PLANE,
    "G19": _LATHE_PLANE,
}

_TABLES = {
    "linuxcnc": DialectTable(
        "linuxcnc",
        _LINUXCNC_GROUPS,
        "refuse",
        diameter=False,
        feed_per_rev=False,
        rules=LINUXCNC_RULES,
        refused=_LINUXCNC_REFUSED,
        m_codes=_LINUXCNC_M,
        cycles=_LINUXCNC_CYCLES,
    ),
    "fanuc": DialectTable(
        "fanuc",
        _FANUC_GROUPS,
        "last",
        diameter=True,
        feed_per_rev=True,
        rules=FANUC_RULES,
        refused=_FANUC_REFUSED,
        incremental_uw=True,
        turret=True,
        local_params=33,
        cycles=_FANUC_CYCLES,
    ),
    "okuma": DialectTable(
        "okuma",
        _OKUMA_GROUPS,
        "last",
        diameter=True,
        feed_per_rev=True,
        rules=FANUC_RULES,
        refused=_OKUMA_REFUSED,
        turret=True,
        local_params=33,
    ),
}


def dialect_table(name: str) -> DialectTable:
    """The table of dialect ``name`` (one of ``DIALECTS``)."""
    try:
        return _TABLES[name]
    except KeyError:
        known = ", ".join(DIALECTS)
        raise ValueError(f"unknown dialect {name!r}; expected one of {known}") from None


# -- detection --------------------------------------------------------------------------

_STRONG, _MEDIUM, _WEAK = 10, 5, 1
# Haas is Fanuc with its own G-code table (several group codes in a safe-start block)
_TABLES["haas"] = replace(_TABLES["fanuc"], name="haas", groups=_HAAS_GROUPS)

_LINUXCNC_ONLY = {
    "G7": "G7/G8 diameter/radius mode",
    "G8": "G7/G8 diameter/radius mode",
    "G41.1": "G41.1/G42.1",
    "G42.1": "G41.1/G42.1",
    "G90.1": "G90.1/G91.1",
    "G91.1": "G90.1/G91.1",
    "G61.1": "G61.1",
    "G33.1": "G33.1",
    "G71.1": "G71.1/G71.2 cycles",
    "G71.2": "G71.1/G71.2 cycles",
    "G72.1": "G72.1/G72.2 cycles",
    "G72.2": "G72.1/G72.2 cycles",
    "G64": "G64 path blending",
}
_FANUC_ONLY = {"G50": "G50", "G98": "G98/G99 feed modes", "G99": "G98/G99 feed modes"}
_HAAS_ONLY = {"G103": "G103", "G187": "G187", "G154": "G154 work offsets", "M97": "M97"}
_OKUMA_VARIABLE = re.compile(r"\bV[CS]\d+\s*=", re.I)
# G and M codes that tell a dialect: code -> (dialect, weight, what)
_EVIDENCE = {
    **{c: ("linuxcnc", _STRONG, what) for c, what in _LINUXCNC_ONLY.items()},
    **{c: ("fanuc", _STRONG, what) for c, what in _FANUC_ONLY.items()},
    **{c: ("haas", _STRONG, what) for c, what in _HAAS_ONLY.items()},
    "M98": ("fanuc", _STRONG, "M98/M99 subprograms"),
    "M99": ("fanuc", _STRONG, "M98/M99 subprograms"),
    "M6": ("linuxcnc", _WEAK, "M6 tool changes"),
}


def detect_dialect(source) -> Dialect:
    """The dialect of a lexed program (`GcodeText`), with the reason.

    Okuma: a ``$NAME.MIN%`` header. LinuxCNC: G7/G8, O-word statements, named
    parameters, G41.1/G42.1, G90.1/G91.1, M6. Fanuc: U/W words, G50, G98/G99, macro B
    statements, M98/M99, ``,C``/``,R``, G70-G73 with P/Q, ``:0100``. Haas: Fanuc's
    words and a Haas code (M97, G103, G187, G154) or a safe-start block with G80.
    With nothing of these: LinuxCNC, saying so.
    """
    score = dict.fromkeys(DIALECTS, 0)
    why: dict[str, list[str]] = {d: [] for d in DIALECTS}
    weights: dict[str, int] = {}

    def add(d: str, weight: int, what: str) -> None:
        if what not in why[d]:  # each kind of evidence counts once
            score[d] += weight
            why[d].append(what)
            weights[what] = weight

    safe_start = None
    seen: set[str] = set()  # a line's evidence is its text's: a repeated line adds nothing
    for line in source.lines:
        words = line.words
        if not (words or line.header or line.oword or line.macro or line.assignments):
            continue
        if line.text in seen:
            continue
        seen.add(line.text)
        if line.header is not None:
            add("okuma", 100, f"{line.header} header")
        if line.oword is not None:
            add("linuxcnc", _STRONG, f"O-word {line.oword.keyword}")
        if line.macro is not None and line.macro.kind in ("if_goto", "if_then", "goto", "while"):
            add("fanuc", _STRONG, "macro B " + line.macro.kind.split("_")[0].upper())
        if line.assignments:
            if _OKUMA_VARIABLE.search(line.text):
                add("okuma", _STRONG, "VC/VS variables")
            if any(isinstance(a.target.ref, str) for a in line.assignments):
                add("linuxcnc", _STRONG, "named parameters #<...>")
        gs: list[str] = []
        letters = ""
        for w in words:
            letter = w.letter
            letters += letter if len(letter) == 1 else "," + letter[1]
            if letter in "GM" and w.expr is None:
                c = w.code
                if letter == "G":
                    gs.append(c)
                hit = _EVIDENCE.get(c)
                if hit is not None:
                    add(*hit)
            elif letter == "T" and w.expr is None and len(w.text.lstrip("+")) == 4:
                add("fanuc", _MEDIUM, "Tttoo tool words")
        if ("U" in letters or "W" in letters) and "G4" not in gs:
            add("fanuc", _STRONG, "U/W words")
        if ",C" in letters or ",R" in letters:
            add("fanuc", _STRONG, ",C/,R corners")
        if "P" in letters and "Q" in letters and {"G70", "G71", "G72", "G73"} & set(gs):
            add("fanuc", _STRONG, "G7x P/Q blocks")
        if letters[:1] == "O" and words[0].expr is None:
            if line.text.lstrip().startswith(":"):
                add("fanuc", _STRONG, ":program number")
            add("fanuc", _WEAK, "O program number")
        if "G80" in gs and len(gs) >= 4 and safe_start is None:
            safe_start = " ".join(str(w) for w in words if w.letter == "G")
    for d in DIALECTS:  # the strongest reasons first, else in the order found
        why[d].sort(key=lambda what: -weights[what])
    fanuc_family = score["fanuc"] + score["haas"]
    if score["okuma"] >= 100:
        return Dialect("okuma", ", ".join(why["okuma"]))
    if fanuc_family > score["linuxcnc"] and fanuc_family >= _STRONG:
        if score["haas"] > 0 or safe_start is not None:
            extra = why["haas"] + ([f"safe-start block {safe_start}"] if safe_start else [])
            return Dialect("haas", ", ".join(extra + why["fanuc"][:2]))
        return Dialect("fanuc", ", ".join(why["fanuc"][:3]))
    if score["okuma"] > score["linuxcnc"]:
        return Dialect("okuma", ", ".join(why["okuma"]))
    if score["linuxcnc"] >= _STRONG:
        return Dialect("linuxcnc", ", ".join(why["linuxcnc"][:3]))
    return Dialect("linuxcnc", "nothing dialect-specific found: LinuxCNC assumed")
