"""The gauge-study file: one measuring system (here the machine's probe) on one
characteristic, its type-1 study and its gauge R&R (docs/formats.md, "Gauge study").

[`read_gauge_study`][] reads the TOML file (`[gauge]`, `[type1]`, `[grr]`,
`[uncertainty]`, `[settings]`) and the readings' CSVs it names, and returns a
[`GaugeStudyFile`][] in mm. Every key is checked; an unknown key or column, a missing
certificate U or k, too few readings, an unbalanced or incomplete gauge R&R design
(a missing part x appraiser cell, unequal trials) are an `InputError` naming the file,
the line and what is missing.
"""

from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass, fields
from numbers import Real
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import read_bytes
from ..msa import MsaSettings, Reference
from ._gauge_program import PLAN_NAME, Type1Program, type1_program, type1_readings

_MM_PER = {"mm": 1.0, "in": 25.4}
_KEYS = {
    "gauge": ("name", "units", "tolerance", "resolution"),
    "type1": (
        "readings",
        "reference",
        "expanded_uncertainty",
        "coverage_factor",
        "probe_file",
        "probe_format",
        "plan",
        "program",
    ),  # fmt: skip
    "grr": ("readings", "appraiser"),
    "uncertainty": ("bias_corrected", "system", "process"),
    "settings": tuple(f.name for f in fields(MsaSettings)),
}
#: a source's spread given as a half-width: the divisor to its standard uncertainty
_DIVISORS = {"rectangular": math.sqrt(3.0), "triangular": math.sqrt(6.0)}


@dataclass(frozen=True, eq=False)
class Type1Data:
    """The type-1 readings (mm) of the reference, and where they were read."""

    readings: np.ndarray
    reference: Reference
    file: str
    program: Type1Program | None = None


@dataclass(frozen=True, eq=False)
class GrrData:
    """The gauge R&R readings (mm) as (parts, appraisers, trials), the names in file
    order, what an appraiser is, and where they were read."""

    readings: np.ndarray
    parts: tuple[str, ...]
    appraisers: tuple[str, ...]
    appraiser_is: str
    file: str


@dataclass(frozen=True, eq=False)
class GaugeStudyFile:
    """A gauge-study file, read and checked; lengths in mm (`units`: the file's)."""

    path: Path
    name: str
    units: str
    tolerance: float
    resolution: float
    type1: Type1Data | None
    grr: GrrData | None
    system: dict[str, float]
    process: dict[str, float]
    bias_corrected: bool
    settings: MsaSettings

    @property
    def inputs(self) -> list[str]:
        """Every file the study reads (never overwritten by an output)."""
        data = [d.file for d in (self.type1, self.grr) if d is not None]
        return [str(self.path), *dict.fromkeys(data)]

    def __repr__(self) -> str:
        has = [k for k in ("type1", "grr") if getattr(self, k) is not None]
        return f"GaugeStudyFile({self.name!r}, T={self.tolerance:g} mm, studies {has})"


def read_gauge_study(path, *, readings: bool = True) -> GaugeStudyFile:
    """Read and check a gauge-study file and the CSVs it names (module docstring);
    `readings=False`: not the type-1 readings (to write the program that takes them)."""
    path = Path(path)
    name = str(path)
    try:
        tree = tomllib.loads(_read(path, "gauge study file"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", file=name) from None
    _known(tree, name)
    gauge = _table(tree, "gauge", name, required=True)
    units = gauge.get("units", "mm")
    if units not in _MM_PER:
        raise InputError(f"[gauge] units: expected 'mm' or 'in', got {units!r}", file=name)
    mm = _MM_PER[units]
    unc = _table(tree, "uncertainty", name)
    bias_corrected = unc.get("bias_corrected", False)
    if not isinstance(bias_corrected, bool):
        raise InputError(
            f"[uncertainty] bias_corrected: expected true or false, got {bias_corrected!r}",
            file=name,
        )
    return GaugeStudyFile(
        path=path, name=_text(gauge, "name", "gauge", name), units=units,
        tolerance=_number(gauge, "tolerance", "gauge", name) * mm,
        resolution=_number(gauge, "resolution", "gauge", name) * mm,
        type1=_type1(tree, path, mm, readings), grr=_grr(tree, path, mm),
        system=_sources(unc, "system", name, mm), process=_sources(unc, "process", name, mm),
        bias_corrected=bias_corrected, settings=_settings(tree, name),
    )  # fmt: skip


def _read(path: Path, what: str) -> str:
    """The file's text (UTF-8, a BOM dropped); a byte that is not UTF-8 names the file."""
    data = read_bytes(path, what=what)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{what} is not UTF-8 text (byte {exc.start})", file=str(path)) from None


def _known(tree: dict, name: str) -> None:
    for section, body in tree.items():
        if section not in _KEYS:
            raise InputError(
                f"unknown section [{section}]; expected one of "
                f"{', '.join(f'[{k}]' for k in _KEYS)}",
                file=name,
            )
        if not isinstance(body, dict):
            raise InputError(f"[{section}] must be a table", file=name)
        for key in body:
            if key not in _KEYS[section]:
                raise InputError(
                    f"[{section}] unknown key {key!r}; expected one of {', '.join(_KEYS[section])}",
                    file=name,
                )
    if "type1" not in tree and "grr" not in tree:
        raise InputError("the file has neither a [type1] nor a [grr] study", file=name)


def _table(tree: dict, section: str, name: str, *, required: bool = False) -> dict:
    if section not in tree and required:
        raise InputError(f"section [{section}] is missing", file=name)
    return tree.get(section, {})


def _number(table: dict, key: str, section: str, name: str, *, why: str = "") -> float:
    if key not in table:
        raise InputError(f"[{section}] {key} is missing{why}", file=name)
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v):
        raise InputError(f"[{section}] {key}: expected a number, got {v!r}", file=name, value=v)
    if key != "reference" and v <= 0:
        raise InputError(f"[{section}] {key} must be > 0, got {v!r}", file=name, value=v)
    return float(v)


def _text(table: dict, key: str, section: str, name: str) -> str:
    v = table.get(key)
    if not isinstance(v, str) or not v.strip():
        raise InputError(f"[{section}] {key}: expected a non-empty string, got {v!r}", file=name)
    return v.strip()


def _type1(tree: dict, path: Path, mm: float, readings: bool = True) -> Type1Data | None:
    if "type1" not in tree:
        return None
    t, name = tree["type1"], str(path)
    cert = ": the reference's certified U and k (its calibration certificate) are required"
    ref = Reference(
        _number(t, "reference", "type1", name) * mm,
        _number(t, "expanded_uncertainty", "type1", name, why=cert) * mm,
        _number(t, "coverage_factor", "type1", name, why=cert),
    )
    program = t.get("program")
    if program is not None:
        if not isinstance(program, dict):
            raise InputError("[type1] program must be a table ([type1.program])", file=name)
        program = type1_program(program, ref.value, mm, name)
    if not readings:
        return Type1Data(np.empty(0), ref, name, program)
    if "probe_file" in t:  # the control's file of the type-1 program, read against its plan
        if "readings" in t:
            raise InputError("[type1] has both readings and probe_file: give one", file=name)
        files = {k: t.get(k, d) for k, d in (("probe_file", None), ("plan", PLAN_NAME))}
        for key, v in files.items():
            if not isinstance(v, str) or not v.strip():
                raise InputError(f"[type1] {key}: expected a file name, got {v!r}", file=name)
        fmt = t.get("probe_format")
        if fmt is not None and not isinstance(fmt, str):
            raise InputError(f"[type1] probe_format: expected a name, got {fmt!r}", file=name)
        probe = path.parent / files["probe_file"]
        x = type1_readings(probe, path.parent / files["plan"], fmt)
        return Type1Data(x, ref, str(probe), program)
    if isinstance(t.get("readings"), list):  # inline: [type1] readings = [40.0012, ...]
        x = [_float(v, f"readings[{i}]", None, name) for i, v in enumerate(t["readings"])]
        return Type1Data(np.array(x) * mm, ref, name, program)
    values, file = _readings(t, "type1", path, ("reading",), ("time",))
    x = np.array([_float(row["reading"], "reading", line, file) for line, row in values]) * mm
    return Type1Data(x, ref, file, program)


def _readings(t: dict, section: str, path: Path, required, optional):
    """`(rows, file)`: [(line, {column: text})] of the CSV named by `readings`."""
    src = t.get("readings")
    if not isinstance(src, str):
        what = "a CSV file name" + (" or an array of numbers" if section == "type1" else "")
        raise InputError(f"[{section}] readings: expected {what}, got {src!r}", file=str(path))
    file = path.parent / src
    text = _read(file, f"[{section}] readings file")
    return _csv_rows(text, str(file), required, optional), str(file)


def _csv_rows(text: str, file: str, required, optional) -> list[tuple[int, dict]]:
    lines = [
        (i, raw)
        for i, raw in enumerate(text.splitlines(), start=1)
        if raw.strip() and not raw.lstrip().startswith("#")
    ]
    if not lines:
        raise InputError(f"empty; a header row ({','.join(required)}) is required", file=file)
    head_line, head = lines[0][0], [h.strip().lower() for h in next(csv.reader([lines[0][1]]))]
    for col in head:
        if col not in required + optional or head.count(col) > 1:
            why = "appears twice" if head.count(col) > 1 else "unknown column"
            raise InputError(
                f"{why}; expected {','.join(required)} (optional {','.join(optional)})",
                file=file,
                line=head_line,
                column=col,
            )
    for col in required:
        if col not in head:
            raise InputError(
                f"missing column {col!r}; the header is {','.join(head)!r}",
                file=file,
                line=head_line,
                column=col,
            )
    rows = []
    for line, raw in lines[1:]:
        cells = [c.strip() for c in next(csv.reader([raw]))]
        if len(cells) != len(head):
            raise InputError(
                f"{len(cells)} cells, the header has {len(head)}", file=file, line=line
            )
        rows.append((line, dict(zip(head, cells, strict=True))))
    return rows


def _float(cell, column: str, line: int | None, file: str) -> float:
    try:
        v = math.nan if isinstance(cell, bool) else float(cell)
    except (TypeError, ValueError):
        what = "empty cell" if cell == "" else f"not a number: {cell!r}"
        raise InputError(what, file=file, line=line, column=column, value=cell) from None
    if not math.isfinite(v):
        raise InputError(
            f"not a finite number: {cell!r}", file=file, line=line, column=column, value=cell
        )
    return v


def _grr(tree: dict, path: Path, mm: float) -> GrrData | None:
    if "grr" not in tree:
        return None
    t = tree["grr"]
    who = t.get("appraiser", "appraiser")
    if not isinstance(who, str) or not who.strip():
        raise InputError(
            f"[grr] appraiser: expected what an appraiser is (e.g. 'setup'), got {who!r}",
            file=str(path),
        )
    rows, file = _readings(t, "grr", path, ("part", "appraiser", "value"), ("trial",))
    if not rows:
        raise InputError("a header but no readings", file=file)
    cells = _cells(rows, file, who.strip(), mm)
    y, parts, apprs = _balanced(cells, file, who.strip())
    return GrrData(y, parts, apprs, who.strip(), file)


def _cells(rows, file: str, who: str, mm: float) -> dict[tuple[str, str], list]:
    """`{(part, appraiser): [(trial, value, line)]}` in file order."""
    cells: dict[tuple[str, str], list] = {}
    for line, row in rows:
        for col in ("part", "appraiser"):
            if not row[col]:
                raise InputError("empty cell", file=file, line=line, column=col)
        key = (row["part"], row["appraiser"])
        trial = row.get("trial") or str(len(cells.get(key, ())) + 1)
        for t, _, first in cells.get(key, ()):
            if t == trial:
                raise InputError(
                    f"part {key[0]!r}, {who} {key[1]!r}, trial {trial} read twice "
                    f"(also line {first})",
                    file=file,
                    line=line,
                )
        value = _float(row["value"], "value", line, file) * mm
        cells.setdefault(key, []).append((trial, value, line))
    return cells


def _balanced(cells: dict, file: str, who: str):
    parts = tuple(dict.fromkeys(k[0] for k in cells))
    apprs = tuple(dict.fromkeys(k[1] for k in cells))
    for p in parts:
        for a in apprs:
            if (p, a) not in cells:
                raise InputError(
                    f"part {p!r} has no reading by {who} {a!r}: a crossed gauge R&R needs every "
                    f"part read by every {who} (unbalanced design)",
                    file=file,
                )
    counts = {k: len(v) for k, v in cells.items()}
    usual = max(set(counts.values()), key=list(counts.values()).count)
    for (p, a), n in counts.items():
        if n != usual:
            raise InputError(
                f"part {p!r}, {who} {a!r}: {n} trials, the other cells have {usual} (unbalanced "
                f"design: every part x {who} cell needs the same number of trials)",
                file=file,
            )
    y = np.array([[[v for _, v, _ in cells[p, a]] for a in apprs] for p in parts])
    return y, parts, apprs


def _sources(unc: dict, key: str, name: str, mm: float) -> dict[str, float]:
    """`[uncertainty] system` / `process`: {name: standard uncertainty (mm)}; each a
    number, `{ U = .., k = .. }` or `{ half_width = .., distribution = .. }`."""
    table = unc.get(key, {})
    if not isinstance(table, dict):
        raise InputError(f"[uncertainty] {key}: expected a table of sources", file=name)
    out = {}
    for src, v in table.items():
        where = f"[uncertainty] {key}.{src}"
        if isinstance(v, dict):
            u = _spread(v, where, name)
        elif isinstance(v, bool) or not isinstance(v, Real) or not 0 <= v < math.inf:
            raise InputError(
                f"{where}: expected a standard uncertainty >= 0, U and k, or a "
                f"half_width and distribution, got {v!r}",
                file=name,
            )
        else:
            u = float(v)
        out[src] = u * mm
    return out


def _spread(v: dict, where: str, name: str) -> float:
    keys = set(v)
    if keys == {"U", "k"}:
        return _number(v, "U", where, name) / _number(v, "k", where, name)
    if keys == {"half_width", "distribution"} and v["distribution"] in _DIVISORS:
        return _number(v, "half_width", where, name) / _DIVISORS[v["distribution"]]
    raise InputError(
        f"{where}: expected {{ U = .., k = .. }} or {{ half_width = .., "
        f"distribution = {' | '.join(map(repr, _DIVISORS))} }}, got {v!r}",
        file=name,
    )


def _settings(tree: dict, name: str) -> MsaSettings:
    try:
        return MsaSettings(**tree.get("settings", {}))
    except InputError as exc:
        raise InputError(f"[settings] {exc.reason}", file=name, value=exc.value) from None
