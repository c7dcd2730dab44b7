"""Probe CSV files: one row per trigger, ball-centre machine coordinates.

Required columns ``feature,x,z``; optional ``part``, ``approach_x``,
``approach_z``, ``time``, ``temperature``. A header row is required; lines
starting with ``#`` (and blank lines) are comments. X is a diameter or a radius
as the study's ``[probe] x_mode`` says; lengths are in the study's units and
are converted to millimetres and radius here, at the boundary.
"""

from __future__ import annotations

import codecs
import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, shown_files
from ._fastcsv import read_rows, split_lines
from ._text import decode, read_bytes

REQUIRED_COLUMNS = ("feature", "x", "z")
OPTIONAL_COLUMNS = ("part", "approach_x", "approach_z", "time", "temperature")
_NUMERIC = ("x", "z", "approach_x", "approach_z", "time", "temperature")
_MM_PER = {"mm": 1.0, "in": 25.4}


@dataclass(frozen=True, eq=False)
class ProbeData:
    """Probe triggers of one file (or of several, concatenated), in millimetres, X as
    radius, machine frame.

    ``file`` is the tuple of the files' paths (as given; one for `read_probe_csv`,
    each of a run for `jobs.load_probe_data`; a single path given is made a 1-tuple)
    and ``file_text`` how messages show it; ``points`` is ``(n, 2)`` ``(x, z)`` ball
    centres; ``lines`` the 1-based file line of each row (for messages);
    ``approach`` ``(n, 2)`` or None.
    """

    file: tuple[str, ...]
    feature: np.ndarray
    points: np.ndarray
    lines: np.ndarray
    part: np.ndarray
    approach: np.ndarray | None = None
    time: np.ndarray | None = None
    temperature: np.ndarray | None = None

    def __post_init__(self):
        f = self.file
        files = (str(f),) if isinstance(f, (str, Path)) else tuple(str(p) for p in f)
        object.__setattr__(self, "file", files)

    @property
    def file_text(self) -> str:
        """The file(s) as a message shows them (`errors.shown_files`)."""
        return shown_files(self.file)

    def __len__(self) -> int:
        return len(self.feature)

    @property
    def parts(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.part.tolist()))

    def select(self, mask) -> ProbeData:
        """The rows where ``mask`` is true (a new ProbeData)."""
        m = np.asarray(mask)

        def sub(a):
            return None if a is None else a[m]

        return ProbeData(
            self.file,
            self.feature[m],
            self.points[m],
            self.lines[m],
            self.part[m],
            sub(self.approach),
            sub(self.time),
            sub(self.temperature),
        )

    def for_part(self, part: str) -> ProbeData:
        return self.select(self.part == part)

    def __repr__(self) -> str:
        feats = dict(zip(*np.unique(self.feature, return_counts=True), strict=True))
        body = ", ".join(f"{k}: {v}" for k, v in feats.items())
        n, parts = len(self), len(self.parts)
        return f"ProbeData({self.file_text!r}, {n} points, parts={parts}, {{{body}}})"


def _lines_without_comments(text: str):
    # lines end at "\n" only (a form feed in a comment is not a new row), "\r\n" too
    for lineno, raw in enumerate(text.split("\n"), start=1):
        raw = raw.rstrip("\r")
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        yield lineno, raw


def read_probe_csv(
    path,
    *,
    units: str = "mm",
    x_mode: str = "diameter",
    features: tuple[str, ...] | None = None,
    default_part: str | None = None,
    encoding: str = "utf-8",
) -> ProbeData:
    """Read and validate a probe CSV file.

    **Arguments:**

    - `path`: the file.
    - `units`: ``"mm"`` or ``"in"`` (lengths in the file).
    - `x_mode`: ``"diameter"`` or ``"radius"``: how X is written in the file.
    - `features`: the study's feature ids; any other id is an error.
    - `default_part`: part id for rows without a ``part`` column (default: file stem).
    - `encoding`: the file's text encoding (UTF-8 with or without a BOM by default;
      ``"cp1252"`` for Windows/Excel exports); an invalid byte is an `InputError`
      naming the line, column and byte.

    **Returns:** a :class:`ProbeData` in mm, radius X.

    **Raises:** :class:`InputError` naming file, line, column and value for a missing
    column, a non-numeric or non-finite cell, an unknown feature id or an empty file.

    Plain rows are read a column at a time (`_fastcsv`, over a million rows a
    second); every row it does not vouch for is read by `read_probe_csv_by_rows`'s
    row reader, whose checks and messages are the only ones.
    """
    return _read(path, units, x_mode, features, default_part, encoding, fast=True)


def read_probe_csv_by_rows(
    path,
    *,
    units: str = "mm",
    x_mode: str = "diameter",
    features: tuple[str, ...] | None = None,
    default_part: str | None = None,
    encoding: str = "utf-8",
) -> ProbeData:
    """`read_probe_csv` one row at a time (``csv.reader`` and ``float`` on every row):
    the reference of the fast path, for tests and benchmarks."""
    return _read(path, units, x_mode, features, default_part, encoding, fast=False)


def _read(path, units, x_mode, features, default_part, encoding, *, fast: bool) -> ProbeData:
    path = Path(path)
    name = str(path)
    if units not in _MM_PER:
        raise InputError(f"unknown unit {units!r}; expected 'mm' or 'in'", file=name)
    if x_mode not in ("diameter", "radius"):
        raise InputError(f"unknown x_mode {x_mode!r}; expected 'diameter' or 'radius'", file=name)
    data = read_bytes(path, what="probe file")
    scale = _MM_PER[units]
    xscale = scale / 2.0 if x_mode == "diameter" else scale
    part_default = default_part if default_part is not None else path.stem
    if fast:
        if not (data.isascii() and codecs.lookup(encoding).name in _ASCII_SAME):
            data = decode(data, file=name, encoding=encoding).encode("utf-8")
        header_line, header, cols, lines = _fast_columns(data, name, features)
    else:
        rows = list(_lines_without_comments(decode(data, file=name, encoding=encoding)))
        if not rows:
            raise InputError(_EMPTY, file=name)
        header_line, header = _header(rows[0], name)
        if len(rows) == 1:
            raise InputError(_NO_ROWS, file=name)
        cols, lines = _columns(rows[1:], header, name, features)
    n = len(lines)
    pts = np.column_stack([np.array(cols["x"]) * xscale, np.array(cols["z"]) * scale])
    approach = _approach(cols, lines, name, header_line)
    return ProbeData(
        file=(name,),
        feature=_strings(cols["feature"]),
        points=pts,
        lines=np.array(lines, dtype=int),
        part=_strings(cols["part"]) if "part" in cols else _repeat(part_default, n),
        approach=approach,
        time=np.array(cols["time"]) if "time" in cols else None,
        temperature=np.array(cols["temperature"]) if "temperature" in cols else None,
    )


#: encodings that read ASCII bytes as ASCII (the fast path then reads the bytes as they are)
_ASCII_SAME = ("utf-8", "utf-8-sig", "ascii", "iso8859-1", "cp1252")
_EMPTY = "probe file is empty (a header row 'feature,x,z' is required)"
_NO_ROWS = "probe file has a header but no data rows"


def _strings(col) -> np.ndarray:
    """A string column as the row reader makes it (``<U`` as wide as its longest cell)."""
    if isinstance(col, tuple):  # (codes, values) of the fast path
        codes, values = col
        return np.array(values, dtype=object).astype(str)[codes]
    return np.array(col, dtype=object).astype(str)


def _repeat(value: str, n: int) -> np.ndarray:
    return np.array([value], dtype=object).astype(str).repeat(n)


def _fast_columns(data: bytes, name: str, features):
    """Header line, header, columns and line numbers as `_header` and `_columns` give
    them, plain rows read by `_fastcsv`, the others by `_columns` (in file order, so the
    first bad row is the one the row reader names)."""
    split = split_lines(data)
    first = split.first_row()
    if first is None:
        raise InputError(_EMPTY, file=name)
    header_line, header = _header(first, name)
    kinds = [
        "number" if c in _NUMERIC else "feature" if c == "feature" else "string" for c in header
    ]
    fast = read_rows(split, header_line, kinds, features)
    if not len(fast.lines) and not fast.rest:
        raise InputError(_NO_ROWS, file=name)
    slow, slow_lines = _columns(fast.rest, header, name, features)
    cols: dict = {}
    if not slow_lines:
        for j, c in enumerate(header):
            cols[c] = fast.numbers[j] if j in fast.numbers else fast.strings[j]
        return header_line, header, cols, fast.lines
    order = np.argsort(np.concatenate([fast.lines, slow_lines]), kind="stable")
    for j, c in enumerate(header):
        if j in fast.numbers:
            both = np.concatenate([fast.numbers[j], np.array(slow[c], dtype=float)])
        else:
            codes, values = fast.strings[j]
            fast_cells = np.array(values, dtype=object)[codes]
            both = np.concatenate([fast_cells, np.array(slow[c], dtype=object)])
        cols[c] = both[order]
    return header_line, header, cols, np.concatenate([fast.lines, slow_lines])[order]


def _header(row: tuple[int, str], name: str) -> tuple[int, list[str]]:
    """The header's line number and its column names (lower case): the required
    columns present, none twice, none unknown."""
    header_line, header_raw = row
    header = [h.strip().lower() for h in next(csv.reader([header_raw]))]
    for col in REQUIRED_COLUMNS:
        if col not in header:
            raise InputError(
                f"missing required column {col!r}; header is {','.join(header)!r}, "
                f"expected at least 'feature,x,z'",
                file=name,
                line=header_line,
                column=col,
            )
    for col in header:
        if header.count(col) > 1:
            raise InputError(
                "column appears twice in the header", file=name, line=header_line, column=col
            )
    unknown = [c for c in header if c not in REQUIRED_COLUMNS + OPTIONAL_COLUMNS]
    if unknown:
        raise InputError(
            f"unknown column {unknown[0]!r}; "
            f"allowed: {', '.join(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)}",
            file=name,
            line=header_line,
            column=unknown[0],
        )
    return header_line, header


def _columns(rows, header: list[str], name: str, features) -> tuple[dict[str, list], list[int]]:
    """The data rows' cells by column (numbers as floats) and their line numbers."""
    idx = {c: header.index(c) for c in header}
    cols: dict[str, list] = {c: [] for c in header}
    lines = []
    for lineno, raw in rows:
        cells = next(csv.reader([raw]))
        if len(cells) != len(header):
            raise InputError(
                f"row has {len(cells)} cells, the header has {len(header)}: {raw.strip()!r}",
                file=name,
                line=lineno,
            )
        for col, j in idx.items():
            cols[col].append(_cell(cells[j].strip(), col, lineno, name, features))
        lines.append(lineno)
    return cols, lines


def _cell(cell: str, col: str, lineno: int, name: str, features):
    """One cell: a finite float in a numeric column, else a non-empty string (a
    feature id of the study in the `feature` column)."""
    if col in _NUMERIC:
        try:
            val = float(cell)
        except ValueError:
            raise InputError(
                f"not a number: {cell!r}", file=name, line=lineno, column=col, value=cell
            ) from None
        if not math.isfinite(val):
            raise InputError(
                f"value must be finite, got {cell!r}",
                file=name,
                line=lineno,
                column=col,
                value=cell,
            )
        return val
    if not cell:
        raise InputError("empty cell", file=name, line=lineno, column=col)
    if col == "feature" and features is not None and cell not in features:
        raise InputError(
            f"unknown feature id {cell!r}; the study's profile has {', '.join(features)}",
            file=name,
            line=lineno,
            column=col,
            feature=cell,
            value=cell,
        )
    return cell


def _approach(cols: dict[str, list], lines: list[int], name: str, header_line: int):
    """Unit approach directions `(n, 2)` from `approach_x`, `approach_z`, or None."""
    if "approach_x" not in cols and "approach_z" not in cols:
        return None
    if not ("approach_x" in cols and "approach_z" in cols):
        raise InputError(
            "give both approach_x and approach_z, or neither", file=name, line=header_line
        )
    approach = np.column_stack([cols["approach_x"], cols["approach_z"]]).astype(float)
    norms = np.linalg.norm(approach, axis=1)
    bad = np.flatnonzero(norms == 0)
    if bad.size:
        raise InputError(
            "approach direction is the zero vector",
            file=name,
            line=int(lines[bad[0]]),
            column="approach_x",
        )
    return approach / norms[:, None]
