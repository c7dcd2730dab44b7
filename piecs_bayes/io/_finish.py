"""Finished-part measurements (the post-process loop of `piecs-bayes feedback`).

[`read_finish_csv`][] reads a CMM-style CSV per part (or several parts in one file with
a ``part`` column): one row per feature, the finished part's deviation at the feature's
characteristic point and its standard uncertainty (required columns ``feature,
deviation, u``; optional ``part``, default the file name without extension, and ``on``:
``drawn``, default, on the feature's ``tolerance_on``, or ``normal``). Lengths are in the
study's units and are returned as normal deviations in mm ([`FinishData`][],
`geometry.drawn_scale`). [`read_finish_files`][] concatenates files in the given order.
Every bad cell is an `InputError` naming the file, line, column and value (a missing,
unknown or repeated column, a wrong cell count, an empty or non-finite cell,
``u <= 0``, an unknown feature or ``on``, a part and feature measured twice, both
places named, a file without data rows).

The format, with an example: docs/formats.md, "Finished-part measurements".
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry import drawn_scale
from ._text import decode, read_bytes

#: required, then optional columns of a finished-part CSV
FINISH_COLUMNS = (("feature", "deviation", "u"), ("part", "on"))
_MM_PER = {"mm": 1.0, "in": 25.4}
_ON = ("drawn", "normal")


@dataclass(frozen=True, eq=False)
class FinishData:
    """Finished-part measurements: one row per part and feature, in file order.

    `deviation` and `u` are normal deviations δ and their standard uncertainties
    (mm); `files` and `lines` say where each row was read (for messages).
    """

    part: np.ndarray
    feature: np.ndarray
    deviation: np.ndarray
    u: np.ndarray
    files: np.ndarray
    lines: np.ndarray

    def __len__(self) -> int:
        return len(self.part)

    @property
    def parts(self) -> tuple[str, ...]:
        """The parts measured, in the order first read."""
        return tuple(dict.fromkeys(self.part.tolist()))

    def where(self, i: int) -> str:
        """`file:line` of row `i`."""
        return f"{self.files[i]}:{int(self.lines[i])}"

    def for_feature(self, feature: str) -> dict[str, tuple[float, float, int]]:
        """`{part: (deviation, u, row)}` of one feature."""
        idx = np.flatnonzero(self.feature == feature)
        return {str(self.part[i]): (float(self.deviation[i]), float(self.u[i]), int(i))
                for i in idx}  # fmt: skip

    def rows(self) -> list[dict]:
        """One row per measurement: part, feature, deviation_mm, u_mm (normal), file, line."""
        return [
            {"part": str(p), "feature": str(f), "deviation_mm": float(d), "u_mm": float(u),
             "file": str(fl), "line": int(ln)}
            for p, f, d, u, fl, ln in zip(self.part, self.feature, self.deviation, self.u,
                                          self.files, self.lines, strict=True)
        ]  # fmt: skip

    def __repr__(self) -> str:
        return f"FinishData({len(self)} measurements, {len(self.parts)} parts)"


def _header(raw: str, lineno: int, name: str) -> list[str]:
    header = [h.strip().lower() for h in next(csv.reader([raw]))]
    required, optional = FINISH_COLUMNS
    for col in header:
        if header.count(col) > 1:
            raise InputError("column appears twice in the header", file=name, line=lineno,
                             column=col)  # fmt: skip
        if col not in required + optional:
            raise InputError(
                f"unknown column {col!r}; allowed: {', '.join(required + optional)}",
                file=name, line=lineno, column=col, value=col,
            )  # fmt: skip
    for col in required:
        if col not in header:
            raise InputError(
                f"missing required column {col!r}; header is {','.join(header)!r}, expected "
                "at least 'feature,deviation,u'",
                file=name, line=lineno, column=col,
            )  # fmt: skip
    return header


def _number(cell: str, col: str, lineno: int, name: str) -> float:
    try:
        val = float(cell)
    except ValueError:
        what = "empty cell" if not cell else f"not a number: {cell!r}"
        raise InputError(what, file=name, line=lineno, column=col, value=cell) from None
    if not math.isfinite(val):
        raise InputError(f"value must be finite, got {cell!r}", file=name, line=lineno,
                         column=col, value=cell)  # fmt: skip
    return val


def read_finish_csv(
    path, *, profile, units: str = "mm", default_part: str | None = None,
    encoding: str = "utf-8",
) -> FinishData:  # fmt: skip
    """Read and validate one finished-part CSV (see the module doc).

    **Arguments:**

    - `path`: the file.
    - `profile`: the study's profile (feature ids, and each feature's `tolerance_on`
      for deviations as drawn).
    - `units`: the study's units (`"mm"` or `"in"`).
    - `default_part`: part id for a file without a `part` column (default: the stem).
    - `encoding`: the file's text encoding.

    **Returns:** a [`FinishData`][] of normal deviations in mm.

    **Raises:** `InputError` naming file, line, column and value.
    """
    path = Path(path)
    name = str(path)
    if units not in _MM_PER:
        raise InputError(f"unknown unit {units!r}; expected 'mm' or 'in'", file=name)
    scale = _MM_PER[units]
    text = decode(read_bytes(path, what="finished-part file"), file=name, encoding=encoding)
    rows = []
    for lineno, raw in enumerate(text.split("\n"), start=1):
        raw = raw.rstrip("\r")
        if raw.strip() and not raw.strip().startswith("#"):
            rows.append((lineno, raw))
    if not rows:
        raise InputError("finished-part file is empty (a header row 'feature,deviation,u' is "
                         "required)", file=name)  # fmt: skip
    header = _header(rows[0][1], rows[0][0], name)
    if len(rows) == 1:
        raise InputError("finished-part file has a header but no data rows", file=name)
    ids = tuple(profile.ids)
    part_default = default_part if default_part is not None else path.stem
    out: dict[str, list] = {k: [] for k in ("part", "feature", "deviation", "u", "line")}
    seen: dict[tuple[str, str], int] = {}
    for lineno, raw in rows[1:]:
        cells = [c.strip() for c in next(csv.reader([raw]))]
        if len(cells) != len(header):
            raise InputError(
                f"row has {len(cells)} cells, the header has {len(header)}: {raw.strip()!r}",
                file=name, line=lineno,
            )  # fmt: skip
        row = dict(zip(header, cells, strict=True))
        fid = row["feature"]
        if not fid:
            raise InputError("empty cell", file=name, line=lineno, column="feature")
        if fid not in ids:
            raise InputError(
                f"unknown feature id {fid!r}; the study's profile has {', '.join(ids)}",
                file=name, line=lineno, column="feature", feature=fid, value=fid,
            )  # fmt: skip
        part = row.get("part", part_default)
        if not part:
            raise InputError("empty cell", file=name, line=lineno, column="part")
        on = row.get("on", "drawn").lower()
        if on not in _ON:
            raise InputError(f"unknown value {row['on']!r}; expected 'drawn' or 'normal'",
                             file=name, line=lineno, column="on", value=row["on"])  # fmt: skip
        dev = _number(row["deviation"], "deviation", lineno, name)
        u = _number(row["u"], "u", lineno, name)
        if u <= 0:
            raise InputError(f"u must be > 0 (a standard uncertainty), got {row['u']!r}",
                             file=name, line=lineno, column="u", value=row["u"])  # fmt: skip
        if (part, fid) in seen:
            raise InputError(
                f"{part} {fid} is measured twice (also line {seen[part, fid]})",
                file=name, line=lineno, feature=fid, value=part,
            )  # fmt: skip
        seen[part, fid] = lineno
        k = 1.0 if on == "normal" else drawn_scale(profile[fid])
        out["part"].append(part)
        out["feature"].append(fid)
        out["deviation"].append(dev * scale / k)
        out["u"].append(u * scale / abs(k))
        out["line"].append(lineno)
    n = len(out["part"])
    return FinishData(
        part=np.array(out["part"], dtype=object).astype(str),
        feature=np.array(out["feature"], dtype=object).astype(str),
        deviation=np.array(out["deviation"], dtype=float),
        u=np.array(out["u"], dtype=float),
        files=np.array([name] * n, dtype=object).astype(str),
        lines=np.array(out["line"], dtype=int),
    )


def read_finish_files(
    paths: Sequence, *, profile, units: str = "mm", encoding: str = "utf-8"
) -> FinishData:
    """[`read_finish_csv`][] of every file, concatenated in the given order; a (part,
    feature) measured in two files is an `InputError` naming both places."""
    if not paths:
        raise InputError("no finished-part files given")
    datas = [read_finish_csv(p, profile=profile, units=units, encoding=encoding) for p in paths]
    names = ("part", "feature", "deviation", "u", "files", "lines")
    cat = FinishData(*(np.concatenate([getattr(d, k) for d in datas]) for k in names))
    seen: dict[tuple[str, str], int] = {}
    for i, key in enumerate(zip(cat.part.tolist(), cat.feature.tolist(), strict=True)):
        if key in seen:
            j = seen[key]
            raise InputError(
                f"{key[0]} {key[1]} is measured twice (also {cat.where(j)})",
                file=str(cat.files[i]), line=int(cat.lines[i]), feature=key[1], value=key[0],
            )  # fmt: skip
        seen[key] = i
    return cat
