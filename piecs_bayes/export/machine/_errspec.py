"""Error specification files (PIECS option 1), native format: one JSON file for the
structure and one CSV file per table, beside it.

**Native format** (version 1, documented in `docs/errspec.md`): each row is a correction
(mm, added to the commanded position of the table's `axis`) with its standard
uncertainty and the machine position of `position_axis` where it applies; X positions
are radii. The data classes are [`CompensationTable`][piecs_bayes.compensate.CompensationTable]
and [`ErrorSpec`][piecs_bayes.compensate.ErrorSpec]; LinuxCNC comp tables are in
`_linuxcnc.py`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Mapping
from pathlib import Path

from ...compensate import ERRSPEC_FORMAT_VERSION as FORMAT_VERSION
from ...compensate import CompensationTable, ErrorSpec
from ...errors import InputError
from ...io import write_text_atomic

FORMAT_NAME = "piecs-bayes-errspec"
# file stems use the alphabet of table names (they become parts of file names too)
_STEM = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


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
    if not isinstance(stem, str) or not _STEM.match(stem):
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
