"""Error specification files (PIECS option 1): a native format and LinuxCNC comp tables.

**Native format** (version 1, documented in `docs/errspec.md`): one JSON file for the
structure and one CSV file per table, beside it. Each row is a correction (mm, added to
the commanded position of the table's `axis`) with its standard uncertainty and the
machine position of `position_axis` where it applies; X positions are radii.

**LinuxCNC joint compensation table** (`[JOINT_n]COMP_FILE`, `COMP_FILE_TYPE`), as read
by `usrmotLoadComp` (src/emc/motion/usrmotintf.cc) and stored by `EMCMOT_SET_JOINT_COMP`
(src/emc/motion/command.c):

- each line is read with `fgets(buf, LINELEN=255)` and `sscanf("%lf %lf %lf")`; the
  first line that does not give three numbers **silently ends the table** (a header,
  a comment or a blank line in the middle drops everything after it), and text after
  the third number is ignored;
- type 0: `nominal forward reverse`, the positions the joint actually reaches
  travelling forward/in reverse when `nominal` is commanded; LinuxCNC stores the trims
  `nominal - forward`, `nominal - reverse`;
- type 1: `nominal forward_trim reverse_trim`, the trims themselves;
- the trim is **added** to the commanded joint position (motor = commanded + trim),
  interpolated linearly between entries and held constant beyond the first and last;
- at most 256 entries (`EMCMOT_COMP_SIZE`), `nominal` strictly increasing: an entry
  that breaks either rule is dropped with an error message, the others are kept.

A correction $c$ is therefore written as trim $c$ (type 1) or as
`forward = nominal - c` (type 0). The writer refuses what this cannot express
(another axis' position, NaN, more than 256 rows after merging rows that share a
printed nominal, a slope $|\\Delta c/\\Delta p| \\ge 1$ that would make the motor
command or the type-0 position column run backwards), re-reads its own text by the
rules above and refuses to return a table LinuxCNC would load differently.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import AnalysisError, InputError
from ._atomic import write_text_atomic

__all__ = [
    "CompensationTable",
    "ErrorSpec",
    "LinuxCNCComp",
    "errspec_texts",
    "linuxcnc_comp_text",
    "parse_linuxcnc_comp",
    "read_errspec",
    "read_linuxcnc_comp",
    "validate_linuxcnc_comp",
    "write_errspec",
    "write_linuxcnc_comp",
]

FORMAT_NAME = "piecs-bayes-errspec"
FORMAT_VERSION = 1
AXES = ("x", "z")
FRAMES = ("machine", "part")
LINUXCNC_MAX_ROWS = 256  # EMCMOT_COMP_SIZE
LINUXCNC_LINELEN = 255  # LINELEN of emc/linuxcnc.h; fgets keeps LINELEN - 1 characters
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class CompensationTable:
    """Corrections of one machine axis as a function of one axis position.

    **Fields:**

    - `name`: identifier (letters, digits, `_.-`), used in file names.
    - `axis`: corrected machine axis, `"x"` (radius) or `"z"`.
    - `position_axis`: axis whose position indexes the table (the LinuxCNC table
      needs `position_axis == axis`).
    - `position`: positions (mm) of `position_axis` where the corrections apply; X as
      radius. Rows are kept sorted by position (stable).
    - `correction`: mm added to the commanded `axis` position (travelling forward, or
      both ways when no reverse column is given); `u_correction` its standard uncertainty.
    - `correction_reverse`, `u_correction_reverse`: optional, for reverse travel.
    - `feature`: optional feature id per row; `frame`: `"machine"` (default) or
      `"part"` coordinates; `description`: free text.
    """

    name: str
    axis: str
    position_axis: str
    position: np.ndarray
    correction: np.ndarray
    u_correction: np.ndarray
    correction_reverse: np.ndarray | None = None
    u_correction_reverse: np.ndarray | None = None
    feature: tuple[str, ...] | None = None
    frame: str = "machine"
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise InputError(
                f"table name must be letters, digits, '_', '.', '-' (got {self.name!r})",
                value=self.name,
            )
        for attr in ("axis", "position_axis"):
            if getattr(self, attr) not in AXES:
                raise InputError(
                    f"table {self.name!r}: {attr} must be one of {AXES}, got "
                    f"{getattr(self, attr)!r}",
                    value=getattr(self, attr),
                )
        if self.frame not in FRAMES:
            raise InputError(
                f"table {self.name!r}: frame must be one of {FRAMES}, got {self.frame!r}"
            )
        pos = np.asarray(self.position, dtype=float).ravel()
        n = pos.size
        arrays = {"position": pos}
        for attr in ("correction", "u_correction", "correction_reverse", "u_correction_reverse"):
            v = getattr(self, attr)
            if v is None:
                continue
            v = np.asarray(v, dtype=float).ravel()
            if v.size != n:
                raise InputError(
                    f"table {self.name!r}: {attr} has {v.size} values, position has {n}"
                )
            arrays[attr] = v
        if (self.correction_reverse is None) != (self.u_correction_reverse is None):
            raise InputError(
                f"table {self.name!r}: give both correction_reverse and u_correction_reverse"
            )
        for attr, v in arrays.items():
            bad = np.flatnonzero(~np.isfinite(v))
            if bad.size:
                i = int(bad[0])
                raise InputError(
                    f"table {self.name!r}: {attr}[{i}] is {float(v[i])!r}; expected a finite "
                    "number",
                    value=float(v[i]),
                )
            if attr.startswith("u_") and np.any(v < 0):
                i = int(np.flatnonzero(v < 0)[0])
                raise InputError(
                    f"table {self.name!r}: {attr}[{i}] = {float(v[i])!r} is negative",
                    value=float(v[i]),
                )
        feature = self.feature
        if feature is not None:
            feature = tuple(str(f) for f in feature)
            if len(feature) != n:
                raise InputError(f"table {self.name!r}: {len(feature)} feature ids for {n} rows")
        order = np.argsort(pos, kind="stable")
        for attr, v in arrays.items():
            object.__setattr__(self, attr, _ro(v[order]))
        if feature is not None:
            object.__setattr__(self, "feature", tuple(feature[i] for i in order))

    @property
    def directional(self) -> bool:
        """True when reverse travel has its own corrections."""
        return self.correction_reverse is not None

    def __len__(self) -> int:
        return int(self.position.size)

    def __repr__(self) -> str:
        span = f"{self.position[0]:.4g}..{self.position[-1]:.4g}" if len(self) else "empty"
        cmax = float(np.max(np.abs(self.correction))) if len(self) else 0.0
        return (
            f"CompensationTable({self.name!r}, corrects {self.axis} vs {self.position_axis} "
            f"({self.frame}), {len(self)} rows over {span} mm, |c| <= {cmax:.3g} mm"
            f"{', directional' if self.directional else ''})"
        )


@dataclass(frozen=True)
class ErrorSpec:
    """A set of compensation tables with metadata; `units` is always `"mm"` (internal)."""

    tables: tuple[CompensationTable, ...]
    description: str = ""
    source: Mapping[str, Any] = field(default_factory=dict)
    units: str = "mm"

    def __post_init__(self):
        object.__setattr__(self, "tables", tuple(self.tables))
        if self.units != "mm":
            raise InputError(f"error specifications are in mm, got units {self.units!r}")
        names = [t.name for t in self.tables]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise InputError(f"table names must be unique; repeated: {sorted(dup)}")

    def table(self, name: str) -> CompensationTable:
        """The table called `name`."""
        for t in self.tables:
            if t.name == name:
                return t
        raise KeyError(name)

    def __repr__(self) -> str:
        inner = "".join(f"\n  {t!r}" for t in self.tables)
        return f"ErrorSpec({len(self.tables)} table(s), format v{FORMAT_VERSION}){inner}"


# --------------------------------------------------------------------------- native


def _f(v: float) -> str:
    """Shortest text that reads back to the same float64."""
    v = float(v)
    return "0.0" if v == 0.0 else repr(v)


def _csv_columns(t: CompensationTable) -> list[str]:
    cols = ["position", "correction", "u_correction"]
    if t.directional:
        cols += ["correction_reverse", "u_correction_reverse"]
    if t.feature is not None:
        cols.append("feature")
    return cols


def _csv_text(t: CompensationTable) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = _csv_columns(t)
    w.writerow(cols)
    for i in range(len(t)):
        row = [_f(getattr(t, c)[i]) if c != "feature" else t.feature[i] for c in cols]
        w.writerow(row)
    return buf.getvalue()


def errspec_texts(spec: ErrorSpec, stem: str) -> dict[str, str]:
    """The native files of `spec` as `{file name: text}`: `stem.errspec.json` and one
    `stem.<table>.csv` per table (pure: nothing is written)."""
    if not isinstance(stem, str) or not _NAME.match(stem):
        raise InputError(f"file stem must be letters, digits, '_', '.', '-', got {stem!r}")
    files: dict[str, str] = {}
    tables = []
    for t in spec.tables:
        fname = f"{stem}.{t.name}.csv"
        files[fname] = _csv_text(t)
        tables.append(
            {
                "name": t.name,
                "axis": t.axis,
                "position_axis": t.position_axis,
                "frame": t.frame,
                "file": fname,
                "rows": len(t),
                "columns": _csv_columns(t),
                "directional": t.directional,
                "description": t.description,
            }
        )
    doc = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "units": "mm",
        "x_positions": "radius",
        "correction": "added to the commanded position of `axis` (= -gain x estimated error)",
        "uncertainty": "standard uncertainty (k = 1)",
        "description": spec.description,
        "source": dict(spec.source),
        "tables": tables,
    }
    files[f"{stem}.errspec.json"] = json.dumps(doc, indent=2, sort_keys=False) + "\n"
    return files


def write_errspec(spec: ErrorSpec, path, *, protect=None) -> list[Path]:
    """Write `spec` as `path` (`*.errspec.json`) and its CSV tables beside it, atomically
    file by file (tables first). Returns the written paths."""
    path = Path(path)
    name = path.name
    if not name.endswith(".errspec.json"):
        raise InputError(
            f"error-spec path must end in '.errspec.json', got {name!r}", file=str(path)
        )
    stem = name[: -len(".errspec.json")]
    texts = errspec_texts(spec, stem)
    out = []
    for fname, text in texts.items():
        if fname.endswith(".csv"):
            out.append(write_text_atomic(path.parent / fname, text, protect=protect))
    out.append(write_text_atomic(path, texts[name], protect=protect))
    return out


def _req(doc: Mapping, key: str, typ, file: str, where: str = ""):
    if key not in doc:
        raise InputError(f"missing key {key!r}{where}", file=file)
    v = doc[key]
    if typ is float:
        ok = isinstance(v, int | float) and not isinstance(v, bool)
    else:
        ok = isinstance(v, typ) and not (typ is int and isinstance(v, bool))
    if not ok:
        raise InputError(
            f"key {key!r}{where} must be {getattr(typ, '__name__', typ)}, got {v!r}",
            file=file,
            value=v,
        )
    return v


def _read_table_csv(path: Path, meta: Mapping, json_file: str) -> CompensationTable:
    fname = str(path)
    if not path.is_file():
        raise InputError(f"table file {meta['file']!r} named in {json_file} not found", file=fname)
    text = path.read_text(encoding="utf-8")
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise InputError("empty table file; expected a header line", file=fname)
    header = [h.strip() for h in rows[0]]
    expected = list(meta["columns"])
    if header != expected:
        raise InputError(f"header is {header}, expected {expected}", file=fname, line=1)
    data = {c: [] for c in header}
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or all(not cell.strip() for cell in row):
            raise InputError("blank line inside the table", file=fname, line=lineno)
        if len(row) != len(header):
            raise InputError(
                f"{len(row)} cells, expected {len(header)} ({', '.join(header)})",
                file=fname,
                line=lineno,
            )
        for c, cell in zip(header, row, strict=True):
            if c == "feature":
                data[c].append(cell)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise InputError(
                    f"not a number: {cell!r}", file=fname, line=lineno, column=c, value=cell
                ) from None
            if not math.isfinite(v):
                raise InputError(
                    f"{cell!r} is not finite", file=fname, line=lineno, column=c, value=cell
                )
            if c.startswith("u_") and v < 0:
                raise InputError(
                    f"standard uncertainty {v!r} is negative",
                    file=fname,
                    line=lineno,
                    column=c,
                    value=v,
                )
            data[c].append(v)
    n = len(rows) - 1
    if n != meta["rows"]:
        raise InputError(f"{n} rows, but {json_file} says {meta['rows']}", file=fname)
    return CompensationTable(
        name=meta["name"],
        axis=meta["axis"],
        position_axis=meta["position_axis"],
        position=data["position"],
        correction=data["correction"],
        u_correction=data["u_correction"],
        correction_reverse=data.get("correction_reverse"),
        u_correction_reverse=data.get("u_correction_reverse"),
        feature=tuple(data["feature"]) if "feature" in data else None,
        frame=meta["frame"],
        description=meta.get("description", ""),
    )


def read_errspec(path) -> ErrorSpec:
    """Read and validate a native error specification (`*.errspec.json` + CSV tables).

    Raises `InputError` naming the file, line and column of the first problem.
    """
    path = Path(path)
    fname = str(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("file not found", file=fname) from None
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e.msg}", file=fname, line=e.lineno) from None
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object at the top level", file=fname)
    fmt = doc.get("format")
    if fmt != FORMAT_NAME:
        raise InputError(f"format is {fmt!r}, expected {FORMAT_NAME!r}", file=fname, value=fmt)
    version = _req(doc, "version", int, fname)
    if version != FORMAT_VERSION:
        raise InputError(
            f"format version {version} is not supported (this reader knows {FORMAT_VERSION})",
            file=fname,
            value=version,
        )
    units = _req(doc, "units", str, fname)
    if units != "mm":
        raise InputError(f"units must be 'mm', got {units!r}", file=fname, value=units)
    if doc.get("x_positions", "radius") != "radius":
        raise InputError(f"x_positions must be 'radius', got {doc['x_positions']!r}", file=fname)
    tables_meta = _req(doc, "tables", list, fname)
    tables = []
    for i, meta in enumerate(tables_meta):
        where = f" in tables[{i}]"
        if not isinstance(meta, dict):
            raise InputError(f"tables[{i}] must be an object, got {meta!r}", file=fname)
        for key in ("name", "axis", "position_axis", "frame", "file"):
            _req(meta, key, str, fname, where)
        _req(meta, "rows", int, fname, where)
        cols = _req(meta, "columns", list, fname, where)
        required = ["position", "correction", "u_correction"]
        allowed = [*required, "correction_reverse", "u_correction_reverse", "feature"]
        if cols[:3] != required or any(c not in allowed for c in cols):
            raise InputError(
                f"columns{where} must start with {required} and use only {allowed}; got {cols}",
                file=fname,
            )
        if "/" in meta["file"] or "\\" in meta["file"] or meta["file"].startswith("."):
            raise InputError(
                f"table file{where} must be a plain file name beside the JSON, "
                f"got {meta['file']!r}",
                file=fname,
            )
        tables.append(_read_table_csv(path.parent / meta["file"], meta, fname))
    return ErrorSpec(
        tables=tuple(tables),
        description=str(doc.get("description", "")),
        source=dict(doc.get("source", {}) or {}),
    )


# --------------------------------------------------------------------------- LinuxCNC

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


def parse_linuxcnc_comp(text: str, *, comp_type: int = 0) -> LinuxCNCComp:
    """Parse a comp file's text by LinuxCNC's rules (see the module docstring).

    Never raises on content: what LinuxCNC would do is returned with the problems.
    """
    if comp_type not in (0, 1):
        raise InputError(f"COMP_FILE_TYPE must be 0 or 1, got {comp_type!r}", value=comp_type)
    chunks = _fgets(text)
    problems: list[str] = []
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
            if rest:
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
    # the motion controller: at most 256 entries, strictly increasing nominal
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
    cols = np.array([v for _, v in kept], dtype=float).reshape(-1, 3)
    nominal = cols[:, 0]
    if comp_type == 0:
        fwd, rev = nominal - cols[:, 1], nominal - cols[:, 2]
    else:
        fwd, rev = cols[:, 1].copy(), cols[:, 2].copy()
    if not kept:
        problems.append("no entry would be loaded: the table is empty for LinuxCNC")
    # the commanded -> motor mapping must not reverse: |d trim / d nominal| < 1
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


def linuxcnc_comp_text(
    table: CompensationTable,
    *,
    comp_type: int = 0,
    decimals: int = 6,
    machine_units: str = "mm",
    merge_tolerance: float | None = None,
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
    text = "\n".join(lines) + "\n"
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
    return text


def write_linuxcnc_comp(
    path,
    table: CompensationTable,
    *,
    comp_type: int = 0,
    decimals: int = 6,
    machine_units: str = "mm",
    merge_tolerance: float | None = None,
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
    )
    out = write_text_atomic(path, text, protect=protect)
    read_linuxcnc_comp(out, comp_type=comp_type)
    return out
