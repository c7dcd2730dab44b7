r"""LinuxCNC joint compensation tables (error specification files, PIECS option 1).

[`linuxcnc_comp_text`][] writes a [`CompensationTable`][piecs_bayes.compensate.CompensationTable]
(corrections of one axis as a function of its own machine position) as a
`COMP_FILE_TYPE` 0 or 1 table: a correction $c$ is written as the trim $c$ (type 1) or
as `forward = nominal - c` (type 0), with optional `#` notes after the last entry (the
only place LinuxCNC does not stop reading early). It refuses (`AnalysisError`) what the
format cannot express (another axis' position, more than 256 rows after merging, a slope
$|\Delta c/\Delta p| \ge 1$), re-reads its own text by LinuxCNC's rules and refuses to
return a table LinuxCNC would load differently. [`parse_linuxcnc_comp`][] gives what
LinuxCNC would load and the problems by line; `validate_linuxcnc_comp`,
`read_linuxcnc_comp` raise `InputError` on the first; `write_linuxcnc_comp` writes
atomically and re-reads the file.

How LinuxCNC reads the file, and what is refused: docs/errspec.md.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...compensate import CompensationTable
from ...errors import AnalysisError, InputError
from ...io import write_text_atomic

LINUXCNC_MAX_ROWS = 256  # EMCMOT_COMP_SIZE
LINUXCNC_LINELEN = 255  # LINELEN of emc/linuxcnc.h; fgets keeps LINELEN - 1 characters


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


_C_SPACE = " \t\n\v\f\r"
_C_FLOAT = re.compile(
    r"""[+-]?(?:
        0[xX](?:[0-9a-fA-F]+(?:\.[0-9a-fA-F]*)?|\.[0-9a-fA-F]+)(?:[pP][+-]?[0-9]+)?
      | (?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?
      | [iI][nN][fF](?:[iI][nN][iI][tT][yY])?
      | [nN][aA][nN](?:\([0-9A-Za-z_]*\))?
    )""",
    re.X,
)
_DEC = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_CANONICAL = re.compile(rf"^[ \t]*{_DEC}[ \t]+{_DEC}[ \t]+{_DEC}[ \t]*\r?\n?$")


def _c_number(token: str) -> float:
    t = token.lstrip("+-")
    sign = -1.0 if token.startswith("-") else 1.0
    if t[:2].lower() == "0x":
        return sign * float.fromhex(t)
    if t[:3].lower() == "nan":
        return math.nan
    return sign * float(t)


def _sscanf3(buf: str) -> tuple[int, list[float], int]:
    """Emulate `sscanf(buf, "%lf %lf %lf")`: (count or -1 for EOF, values, end index)."""
    pos, vals = 0, []
    for _ in range(3):
        while pos < len(buf) and buf[pos] in _C_SPACE:
            pos += 1
        if pos >= len(buf) or buf[pos] == "\0":
            return (-1 if not vals else len(vals)), vals, pos
        m = _C_FLOAT.match(buf, pos)
        if m is None:
            return len(vals), vals, pos
        vals.append(_c_number(m.group(0)))
        pos = m.end()
    return 3, vals, pos


def _fgets(text: str) -> list[str]:
    """Split `text` the way repeated `fgets(buf, LINELEN, fp)` calls read it."""
    out, i, cap = [], 0, LINUXCNC_LINELEN - 1
    while i < len(text):
        j = text.find("\n", i, i + cap)
        end = j + 1 if j != -1 else min(i + cap, len(text))
        out.append(text[i:end])
        i = end
    return out


@dataclass(frozen=True, eq=False)
class LinuxCNCComp:
    """A LinuxCNC comp table as LinuxCNC would load it, with the problems found.

    `nominal`, `forward_trim`, `reverse_trim` are the entries kept by the motion
    controller (trims are added to the commanded joint position); `columns` are the
    raw numbers of those lines; `problems` lists, by line, everything that makes the
    file differ from "three numbers per line, nominal strictly ascending, at most 256
    rows, nothing else"; `valid` is True when there is none.
    """

    comp_type: int
    nominal: np.ndarray
    forward_trim: np.ndarray
    reverse_trim: np.ndarray
    columns: np.ndarray
    lines: int
    problems: tuple[str, ...]

    @property
    def valid(self) -> bool:
        return not self.problems

    def trim(self, position, *, reverse: bool = False) -> np.ndarray:
        """The trim LinuxCNC adds at commanded `position`: linear between entries,
        constant beyond the ends (as `control.c` interpolates)."""
        y = self.reverse_trim if reverse else self.forward_trim
        if y.size == 0:
            return np.zeros_like(np.asarray(position, dtype=float))
        return np.interp(np.asarray(position, dtype=float), self.nominal, y)

    def __len__(self) -> int:
        return int(self.nominal.size)

    def __repr__(self) -> str:
        state = "valid" if self.valid else f"{len(self.problems)} problem(s)"
        return (
            f"LinuxCNCComp(type {self.comp_type}, {len(self)} entries loaded from "
            f"{self.lines} line(s), {state})"
        )


def _read_entries(chunks: list[str], problems: list[str]) -> list[tuple[int, list[float]]]:
    """`usrmotLoadComp`'s reading loop: the three numbers of each line up to the first
    line that has not three; what differs from a plain table goes to `problems`."""
    raw: list[tuple[int, list[float]]] = []
    for idx, buf in enumerate(chunks):
        lineno = idx + 1
        if len(buf) >= LINUXCNC_LINELEN - 1 and not buf.endswith("\n"):
            problems.append(
                f"line {lineno}: longer than {LINUXCNC_LINELEN - 2} characters; fgets splits it"
            )
        count, vals, end = _sscanf3(buf)
        if count != 3:
            rest = [c for c in chunks[idx:] if c.strip(_C_SPACE)]
            if rest and not all(c.lstrip(" \t").startswith("#") for c in rest):
                what = buf.rstrip("\r\n")
                problems.append(
                    f"line {lineno}: {what[:40]!r} is not three numbers; LinuxCNC stops "
                    f"reading here and ignores {len(rest)} non-blank line(s) from here on"
                )
            break
        tail = buf[end:]
        if tail.strip(_C_SPACE + "\0"):
            problems.append(
                f"line {lineno}: text after the third number ({tail.strip()[:30]!r}); "
                "LinuxCNC ignores it"
            )
        elif not _CANONICAL.match(buf):
            problems.append(
                f"line {lineno}: {buf.strip()[:40]!r} is not three plain decimal numbers "
                "separated by blanks (no hex, inf or nan)"
            )
        if not all(math.isfinite(v) for v in vals):
            problems.append(f"line {lineno}: non-finite value in {vals}")
        raw.append((lineno, vals))
    return raw


def _keep_entries(raw, problems: list[str]) -> list[tuple[int, list[float]]]:
    """The motion controller: at most 256 entries, strictly increasing nominal; the
    entries it drops go to `problems`."""
    kept: list[tuple[int, list[float]]] = []
    last = -math.inf
    for lineno, vals in raw:
        nom = vals[0]
        if len(kept) >= LINUXCNC_MAX_ROWS:
            problems.append(
                f"line {lineno}: entry {len(kept) + 1} exceeds the {LINUXCNC_MAX_ROWS}-entry "
                "limit; LinuxCNC drops it ('too many compensation entries')"
            )
            continue
        if not nom > last:  # also catches NaN
            problems.append(
                f"line {lineno}: nominal {nom!r} is not above the previous {last!r}; LinuxCNC "
                "drops it ('compensation values must increase')"
            )
            continue
        kept.append((lineno, vals))
        last = nom
    return kept


def _slope_problems(kept, nominal, fwd, rev, problems: list[str]) -> None:
    """The commanded -> motor mapping must not reverse: |d trim / d nominal| < 1."""
    dn = np.diff(nominal)
    for name, trim in (("forward", fwd), ("reverse", rev)):
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = np.diff(trim) / dn
        for j in np.flatnonzero(~(np.abs(slope) < 1.0)):
            problems.append(
                f"line {kept[j + 1][0]}: {name} trim slope {slope[j]:.3g} between nominal "
                f"{float(nominal[j])!r} and {float(nominal[j + 1])!r}; |slope| >= 1 makes the "
                "motor command or the axis' actual position run backwards"
            )


def parse_linuxcnc_comp(text: str, *, comp_type: int = 0) -> LinuxCNCComp:
    """Parse a comp file's text by LinuxCNC's rules (see the module docstring).

    Never raises on content: what LinuxCNC would do is returned with the problems.
    """
    if comp_type not in (0, 1):
        raise InputError(f"COMP_FILE_TYPE must be 0 or 1, got {comp_type!r}", value=comp_type)
    chunks = _fgets(text)
    problems: list[str] = []
    kept = _keep_entries(_read_entries(chunks, problems), problems)
    cols = np.array([v for _, v in kept], dtype=float).reshape(-1, 3)
    nominal = cols[:, 0]
    if comp_type == 0:
        fwd, rev = nominal - cols[:, 1], nominal - cols[:, 2]
    else:
        fwd, rev = cols[:, 1].copy(), cols[:, 2].copy()
    if not kept:
        problems.append("no entry would be loaded: the table is empty for LinuxCNC")
    _slope_problems(kept, nominal, fwd, rev, problems)
    problems.sort(
        key=lambda msg: int(m.group(1)) if (m := re.match(r"line (\d+):", msg)) else 10**9
    )
    return LinuxCNCComp(
        comp_type=comp_type,
        nominal=_ro(nominal),
        forward_trim=_ro(fwd),
        reverse_trim=_ro(rev),
        columns=_ro(cols),
        lines=len(chunks),
        problems=tuple(problems),
    )


def validate_linuxcnc_comp(
    text: str, *, comp_type: int = 0, file: str | None = None
) -> LinuxCNCComp:
    """Parse by LinuxCNC's rules and raise `InputError` on the first problem."""
    comp = parse_linuxcnc_comp(text, comp_type=comp_type)
    if comp.problems:
        first = comp.problems[0]
        m = re.match(r"line (\d+): (.*)", first)
        extra = f" (+{len(comp.problems) - 1} more)" if len(comp.problems) > 1 else ""
        if m:
            raise InputError(m.group(2) + extra, file=file, line=int(m.group(1)))
        raise InputError(first + extra, file=file)
    return comp


def read_linuxcnc_comp(path, *, comp_type: int = 0) -> LinuxCNCComp:
    """Read and validate a LinuxCNC comp file (see [`validate_linuxcnc_comp`][])."""
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii")
    except FileNotFoundError:
        raise InputError("file not found", file=str(path)) from None
    except UnicodeDecodeError as e:
        raise InputError(f"not plain ASCII text (byte {e.start})", file=str(path)) from None
    return validate_linuxcnc_comp(text, comp_type=comp_type, file=str(path))


def _merge(pos, c, u, c_rev, u_rev, tol):
    """Merge runs of sorted positions closer than `tol` (each gap < tol) into one row:
    mean position, inverse-variance weighted corrections (rows with u = 0 dominate)."""
    out = []
    i, n = 0, pos.size
    while i < n:
        j = i
        while j + 1 < n and pos[j + 1] - pos[j] < tol:
            j += 1
        sl = slice(i, j + 1)

        def wmean(v, uu, sl=sl):
            uu = uu[sl]
            if np.any(uu == 0):
                return float(np.mean(v[sl][uu == 0]))
            w = 1.0 / uu**2
            return float(np.sum(w * v[sl]) / np.sum(w))

        out.append((float(np.mean(pos[sl])), wmean(c, u), wmean(c_rev, u_rev)))
        i = j + 1
    return out


def _refuse_inexpressible(table: CompensationTable, what: str) -> None:
    """Raise `AnalysisError` for a table no LinuxCNC joint compensation can express."""
    if table.axis != table.position_axis:
        raise AnalysisError(
            f"{what}: it corrects {table.axis} as a function of {table.position_axis}, but a "
            "LinuxCNC joint compensation depends only on the joint's own position"
        )
    if table.frame != "machine":
        raise AnalysisError(
            f"{what}: positions are in {table.frame} coordinates; LinuxCNC needs machine "
            "(joint) positions: transform them first"
        )
    if len(table) == 0:
        raise AnalysisError(f"{what}: the table has no rows")


def _comp_lines(rows, comp_type: int, decimals: int) -> tuple[str, list]:
    """The file text of merged `rows` (position, forward and reverse correction) and the
    intended (nominal, forward trim, reverse trim) of each line."""
    q = 10.0**-decimals
    lines = []
    cols = []
    for p, cf, cr in rows:
        a = p - cf if comp_type == 0 else cf
        b = p - cr if comp_type == 0 else cr
        vals = [round(float(v) / q) * q + 0.0 for v in (p, a, b)]
        txt = [f"{v:.{decimals}f}" for v in vals]
        txt = ["0." + "0" * decimals if float(t) == 0.0 else t for t in txt]
        lines.append(" ".join(txt))
        cols.append((p, cf, cr))
    return "\n".join(lines) + "\n", cols


def _check_read_back(text: str, cols, comp_type: int, q: float, what: str) -> None:
    """Re-read `text` by LinuxCNC's rules; raise `AnalysisError` unless it loads the
    intended trims `cols` (within the printing's rounding)."""
    comp = parse_linuxcnc_comp(text, comp_type=comp_type)
    if comp.problems:
        raise AnalysisError(f"{what}: {comp.problems[0]}")
    want = np.array(cols, dtype=float)
    atol = 1.5 * q  # printing rounds each number by at most q/2
    if len(comp) != want.shape[0] or not (
        np.allclose(comp.nominal, want[:, 0], rtol=0, atol=atol)
        and np.allclose(comp.forward_trim, want[:, 1], rtol=0, atol=2 * atol)
        and np.allclose(comp.reverse_trim, want[:, 2], rtol=0, atol=2 * atol)
    ):
        raise AnalysisError(f"{what}: the written table does not read back as intended")


def _notes(table: CompensationTable, rows, comp_type: int, decimals: int, units: str, extra):
    """The trailing `#` lines of a table: what it is, its range and what LinuxCNC does
    outside it and on which moves (LinuxCNC stops reading at the first of them)."""
    lo, hi = (f"{rows[i][0]:.{decimals}f}" for i in (0, -1))
    x = ", X as radius" if table.axis == "x" else ""
    lines = [
        f"piecs-bayes: LinuxCNC joint compensation of {table.axis.upper()}, table "
        f"{table.name!r} (COMP_FILE_TYPE {comp_type}, {units}{x}).",
        "LinuxCNC stops reading at the first line that is not three numbers:",
        "these notes are not loaded.",
        f"Range: nominal {lo} to {hi} {units}. Outside it LinuxCNC holds the end",
        f"values: the trim at {lo} below it, the trim at {hi} above it.",
        "It acts on every move of this joint, rapids, cuts and probing moves alike:",
        "probe points taken with it loaded are shifted by its trim; unload it",
        "before probing, or allow for it.",
        *extra,
    ]
    return "".join(f"# {line}\n" for line in lines)


def linuxcnc_comp_text(
    table: CompensationTable,
    *,
    comp_type: int = 0,
    decimals: int = 6,
    machine_units: str = "mm",
    merge_tolerance: float | None = None,
    notes: bool | Sequence[str] = False,
) -> str:
    """The LinuxCNC joint compensation table of `table` (three numbers per line).

    **Arguments:**

    - `table`: corrections of an axis as a function of its own machine position.
    - `comp_type`: `COMP_FILE_TYPE` 0 (`nominal forward reverse` positions) or 1
      (`nominal forward_trim reverse_trim`).
    - `decimals`: digits after the decimal point (6 = 1 nm in mm).
    - `machine_units`: `"mm"` or `"inch"` (the INI `LINEAR_UNITS` of the joint).
    - `merge_tolerance`: rows whose positions are closer than this (machine units;
      default one unit of the last printed digit) are merged into one entry: mean
      position, inverse-variance weighted corrections.
    - `notes`: append the notes after the last entry (`#` lines: the range, the end
      values held outside it, every move including probing); a sequence of strings
      adds those lines too. LinuxCNC stops reading at the first note.

    **Returns:** the file text. Raises `AnalysisError` when the format cannot express
    the table (the message says why) and `InputError` for bad arguments.
    """
    if comp_type not in (0, 1):
        raise InputError(f"COMP_FILE_TYPE must be 0 or 1, got {comp_type!r}", value=comp_type)
    if isinstance(decimals, bool) or not isinstance(decimals, int) or not 1 <= decimals <= 12:
        raise InputError(f"decimals must be an integer 1..12, got {decimals!r}", value=decimals)
    if machine_units not in ("mm", "inch"):
        raise InputError(f"machine_units must be 'mm' or 'inch', got {machine_units!r}")
    what = f"LinuxCNC compensation table for {table.name!r} refused"
    _refuse_inexpressible(table, what)
    scale = 1.0 if machine_units == "mm" else 1.0 / 25.4
    pos = table.position * scale
    c = table.correction * scale
    u = table.u_correction * scale
    c_rev = c if table.correction_reverse is None else table.correction_reverse * scale
    u_rev = u if table.u_correction_reverse is None else table.u_correction_reverse * scale
    q = 10.0**-decimals
    tol = q if merge_tolerance is None else float(merge_tolerance)
    if not (math.isfinite(tol) and tol >= q):
        raise InputError(
            f"merge_tolerance must be >= {q:g} (one printed digit), got {merge_tolerance!r}"
        )
    rows = _merge(pos, c, u, c_rev, u_rev, tol)
    if len(rows) > LINUXCNC_MAX_ROWS:
        raise AnalysisError(
            f"{what}: {len(rows)} rows after merging positions closer than {tol:g}; "
            f"LinuxCNC loads at most {LINUXCNC_MAX_ROWS} (EMCMOT_COMP_SIZE): resample the "
            "table to fewer positions or merge more (merge_tolerance)"
        )
    text, cols = _comp_lines(rows, comp_type, decimals)
    if notes is not False:
        extra = () if notes is True else tuple(str(n) for n in notes)
        text += _notes(table, rows, comp_type, decimals, machine_units, extra)
    _check_read_back(text, cols, comp_type, q, what)
    return text


def write_linuxcnc_comp(
    path,
    table: CompensationTable,
    *,
    comp_type: int = 0,
    decimals: int = 6,
    machine_units: str = "mm",
    merge_tolerance: float | None = None,
    notes: bool | Sequence[str] = False,
    protect=None,
) -> Path:
    """Write [`linuxcnc_comp_text`][] to `path` atomically, then re-read and validate the
    file. Returns the path."""
    text = linuxcnc_comp_text(
        table,
        comp_type=comp_type,
        decimals=decimals,
        machine_units=machine_units,
        merge_tolerance=merge_tolerance,
        notes=notes,
    )
    out = write_text_atomic(path, text, protect=protect)
    read_linuxcnc_comp(out, comp_type=comp_type)
    return out
