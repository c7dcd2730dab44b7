"""Vectorised reading of plain CSV rows: the fast path of the probe reader.

The row-by-row reader (`_probe`) reads each line with ``csv.reader`` and converts
numeric cells with ``float``. This module reads the same lines with NumPy, a whole
column at a time ([`split_lines`][] -> [`Lines`][], [`read_rows`][] -> [`Rows`][]), and
*vouches* only for the rows it can read exactly as that reader would, without an error
and to the same values: a plain line (ASCII, no quote, no control character, as many
commas as the header) whose cells are non-empty strings (at most `MAX_STRING`
characters; a feature id of the study where one is required) or numbers
``[+-]digits[.digits][e[+-]digits]`` read to exactly Python's ``float`` of the cell.
Every other line that holds a row is handed back to the row reader, in file order, with
its line number: its checks and messages are the only ones, so a bad cell is named
exactly as before.

Which lines and cells, and why the values are exact: docs/models/probe_files.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided

#: the longest string cell vouched for (longer cells go to the row reader)
MAX_STRING = 256
#: the longest numeric cell vouched for (characters, spaces stripped)
_MAX_NUMBER = 40
#: rows per block of the numeric conversion (bounds the temporary arrays)
_BLOCK = 1 << 16
#: exact powers of ten as doubles: 10**k for k <= 22 is representable
_POW10 = np.array([float(10**k) for k in range(23)])
_TWO53 = 2**53


@dataclass(frozen=True, eq=False)
class Lines:
    """A text as lines of UTF-8 bytes (see `split_lines`).

    ``buf``: the bytes, ``size`` of them, then zeros; ``start``/``end``: byte
    offsets of each line in ``buf`` (``end`` before the trailing ``"\\r"``);
    ``plain``: the lines the fast path may read; ``other``: ``(line, raw)`` of the
    other lines that hold a row (not blank, not a comment), in file order;
    ``comma``: every comma's offset; ``comma_before[i]``: how many come before
    line ``i`` (0-based; one more entry, all of them).
    """

    buf: np.ndarray
    size: int
    start: np.ndarray
    end: np.ndarray
    plain: np.ndarray
    other: list[tuple[int, str]]
    comma: np.ndarray
    comma_before: np.ndarray

    def raw(self, i: int) -> str:
        """Line ``i`` (0-based) as text, trailing ``"\\r"`` dropped."""
        return self.buf[self.start[i] : self.end[i]].tobytes().decode("utf-8")

    def first_row(self) -> tuple[int, str] | None:
        """``(line, raw)`` of the first line that holds a row (the header), or None."""
        if self.plain.any():
            i = int(self.plain.argmax())
            if not self.other or i + 1 < self.other[0][0]:
                return i + 1, self.raw(i)
        return self.other[0] if self.other else None


@dataclass(frozen=True, eq=False)
class Rows:
    """The rows `read_rows` vouches for, and the rest.

    ``lines``: 1-based file line of each row read here; ``numbers[j]``: column
    ``j`` as float64; ``strings[j]``: ``(codes, values)``, the cell of row ``i``
    being ``values[codes[i]]``; ``rest``: ``(line, raw)`` of every other data row,
    in file order, for the row reader.
    """

    lines: np.ndarray
    numbers: dict[int, np.ndarray]
    strings: dict[int, tuple[np.ndarray, list[str]]]
    rest: list[tuple[int, str]]


def split_lines(data: bytes) -> Lines:
    """Split a text, ``data`` in UTF-8, into lines as the row reader does (module doc)."""
    size = len(data)
    # zeros past the end: cells are read in windows of up to `MAX_STRING` bytes
    buf = np.frombuffer(data + bytes(MAX_STRING + 8), dtype=np.uint8)
    text_bytes = buf[:size]
    pos = np.flatnonzero(text_bytes <= 44)  # controls, '"', ',' (and a few others)
    code = text_bytes[pos]
    keep = (code < 32) | (code == 34) | (code == 44)
    pos, code = pos[keep], code[keep]
    if not data.isascii():
        pos = np.union1d(pos, np.flatnonzero(text_bytes >= 128))
        code = text_bytes[pos]
    is_nl = code == 10
    is_comma = code == 44
    nl = pos[is_nl]
    start = np.concatenate(([0], nl + 1)).astype(np.int64)
    end = np.concatenate((nl, [size])).astype(np.int64)
    while True:  # rstrip("\r")
        cr = (end > start) & (buf[np.maximum(end - 1, 0)] == 13)
        if not cr.any():
            break
        end -= cr
    odd = np.flatnonzero(~(is_nl | is_comma))
    op = pos[odd]
    ol = np.searchsorted(nl, op)
    bad = ~((code[odd] == 13) & (op >= end[ol]))  # a "\r" before the end, any other
    odd_line = np.zeros(len(start), dtype=bool)
    odd_line[ol[bad]] = True
    # specials before each line: its newlines, the others, the commas
    first_special = np.concatenate(([0], np.flatnonzero(is_nl) + 1))
    others = np.searchsorted(odd, first_special)
    comma = pos[is_comma]
    comma_before = np.append(first_special - np.arange(len(start)) - others, len(comma))
    first = buf[start]
    skip = (end == start) | (first == 35)  # blank, or a comment ("#" first)
    plain = ~skip & ~odd_line & (first != 32)
    lines = Lines(buf, size, start, end, plain, [], comma, comma_before)
    for i in np.flatnonzero(~skip & ~plain).tolist():
        raw = lines.raw(i)
        stripped = raw.strip()
        if stripped and not stripped.startswith("#"):
            lines.other.append((i + 1, raw))
    return lines


def read_rows(lines: Lines, header_line: int, kinds, features=None) -> Rows:
    """The data rows after ``header_line`` (1-based) with ``len(kinds)`` cells each.

    ``kinds[j]``: ``"number"``, ``"string"`` (non-empty), ``"feature"`` (one of
    ``features`` when given, else any non-empty string) or ``"skip"`` (a cell that is
    not read: the caller vouches for it).
    """
    ncols = len(kinds)
    nlines = len(lines.start)
    count = np.diff(lines.comma_before)
    cand = lines.plain.copy()
    cand[:header_line] = False
    good = cand & (count == ncols - 1)
    rows = np.flatnonzero(good)
    spaces = bool(np.any(lines.buf[lines.start[min(header_line, nlines - 1)] : lines.size] == 32))
    commas = _commas(lines, rows, header_line, ncols - 1)
    ok = np.ones(len(rows), dtype=bool)
    numbers: dict[int, np.ndarray] = {}
    strings: dict[int, tuple[np.ndarray, list[str]]] = {}
    for j, kind in enumerate(kinds):
        if kind == "skip":
            continue
        s = lines.start[rows] if j == 0 else commas[:, j - 1] + 1
        stop = lines.end[rows] if j == ncols - 1 else commas[:, j]
        s, e = _strip(lines.buf, s, stop) if spaces else (s, stop)
        if kind == "number":
            numbers[j], okj = _numbers(lines.buf, s, e, stop)
        else:
            codes, values, okj = _strings(lines.buf, s, e)
            if kind == "feature" and features is not None:
                known = np.array([v in features for v in values] + [False], dtype=bool)
                okj &= known[codes]
            strings[j] = (codes, values)
        ok &= okj
    declined = rows[~ok]
    rows = rows[ok]
    numbers = {j: v[ok] for j, v in numbers.items()}
    strings = {j: _used(c[ok], v) for j, (c, v) in strings.items()}
    rest_idx = np.flatnonzero(cand & (count != ncols - 1))
    rest = [(i + 1, lines.raw(i)) for i in np.union1d(declined, rest_idx).tolist()]
    rest += [r for r in lines.other if r[0] > header_line]
    rest.sort(key=lambda r: r[0])
    return Rows(rows + 1, numbers, strings, rest)


def _commas(lines: Lines, rows: np.ndarray, header_line: int, k: int) -> np.ndarray:
    """``(n, k)``: the offsets of the commas of each row (a view where the rows hold
    every comma after the header)."""
    after = lines.comma[lines.comma_before[min(header_line, len(lines.start))] :]
    if len(after) == len(rows) * k:
        return after.reshape(len(rows), k)
    return lines.comma[lines.comma_before[rows][:, None] + np.arange(k)]


def _strip(buf: np.ndarray, s: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cells ``s:e`` without leading and trailing spaces."""
    s, e = s.copy(), e.copy()
    while True:
        m = (s < e) & (buf[s] == 32)
        if not m.any():
            break
        s += m
    while True:
        m = (e > s) & (buf[np.maximum(e - 1, 0)] == 32)
        if not m.any():
            break
        e -= m
    return s, e


def _strings(buf: np.ndarray, s: np.ndarray, e: np.ndarray):
    """``(codes, values, ok)`` of a string column: ``ok`` where the cell is non-empty
    and at most `MAX_STRING` characters; ``codes`` of the others is ``len(values)``."""
    length = e - s
    ok = (length > 0) & (length <= MAX_STRING)
    n = len(s)
    if not ok.any():
        return np.zeros(n, dtype=np.intp), [], ok
    length = np.where(ok, length, 0)
    width = -(-int(length.max()) // 8) * 8
    # the cells' bytes (zero past a cell's end) as 8-byte words, and runs of equal cells
    # (probe files come feature by feature): one head per run
    m = _windows(buf, s, width)
    m[np.arange(width) >= length[:, None]] = 0
    words = m.view(np.uint64)
    head = np.ones(n, dtype=bool)
    head[1:] = words[1:, 0] != words[:-1, 0]
    for k in range(1, words.shape[1]):
        head[1:] |= words[1:, k] != words[:-1, k]
    heads = np.flatnonzero(head)
    cells = m[heads].view(f"S{width}").ravel()
    uniq, inv = np.unique(cells, return_inverse=True)
    values = [u.decode("ascii") for u in uniq.tolist()]
    codes = inv.reshape(-1)[np.cumsum(head) - 1]
    codes = np.where(ok, codes, len(values))
    return codes, values, ok


def _used(codes: np.ndarray, values: list[str]) -> tuple[np.ndarray, list[str]]:
    """Only the values that some row holds (so that string widths are the row reader's)."""
    if not len(values):
        return codes, values
    used = np.bincount(codes, minlength=len(values))[: len(values)] > 0
    if used.all():
        return codes, values
    new = np.cumsum(used) - 1
    return new[codes], [v for v, u in zip(values, used, strict=True) if u]


# A number cell as a finite automaton over its bytes, read up to the byte after it
# (",", "\r", "\n" or the zero past the text): classes of bytes ...
_DIG, _DOT, _SIGN, _EXP, _END, _SPACE, _OTHER = range(7)
_CLASS = np.full(256, _OTHER, dtype=np.uint8)
_CLASS[48:58] = _DIG
_CLASS[ord(".")] = _DOT
_CLASS[[ord("+"), ord("-")]] = _SIGN
_CLASS[[ord("e"), ord("E")]] = _EXP
_CLASS[[0, ord(","), ord("\r"), ord("\n")]] = _END
_CLASS[ord(" ")] = _SPACE
# ... and states: [sign] int [. [frac]] | [sign] . frac, then [e [sign] digits], spaces
(_START, _SIGNED, _INT, _POINT, _BARE_POINT, _FRAC, _E, _E_SIGN, _E_DIG, _TRAIL, _E_TRAIL,
 _DONE, _DONE_E, _BAD) = range(14)  # fmt: skip
_MOVES = {
    _START: {_DIG: _INT, _DOT: _BARE_POINT, _SIGN: _SIGNED},
    _SIGNED: {_DIG: _INT, _DOT: _BARE_POINT},
    _INT: {_DIG: _INT, _DOT: _POINT, _EXP: _E, _END: _DONE, _SPACE: _TRAIL},
    _POINT: {_DIG: _FRAC, _EXP: _E, _END: _DONE, _SPACE: _TRAIL},
    _BARE_POINT: {_DIG: _FRAC},
    _FRAC: {_DIG: _FRAC, _EXP: _E, _END: _DONE, _SPACE: _TRAIL},
    _E: {_DIG: _E_DIG, _SIGN: _E_SIGN},
    _E_SIGN: {_DIG: _E_DIG},
    _E_DIG: {_DIG: _E_DIG, _END: _DONE_E, _SPACE: _E_TRAIL},
    _TRAIL: {_SPACE: _TRAIL, _END: _DONE},
    _E_TRAIL: {_SPACE: _E_TRAIL, _END: _DONE_E},
    _DONE: dict.fromkeys(range(7), _DONE),
    _DONE_E: dict.fromkeys(range(7), _DONE_E),
}
#: by state (times 256) + byte: the next state (times 256), what the byte does to the
#: mantissa (``m -> m * _MUL + _ADD``: a digit of it, or nothing) and to the count
#: of fraction digits
_NEXT = np.full(14 * 256, _BAD * 256, dtype=np.intp)
for _st, _moves in _MOVES.items():
    for _cls, _to in _moves.items():
        _NEXT[_st * 256 + np.flatnonzero(_CLASS == _cls)] = _to * 256
_MANTISSA = np.isin(_NEXT, [_INT * 256, _FRAC * 256])
_MUL = np.where(_MANTISSA, 10.0, 1.0)
_ADD = np.where(_MANTISSA, np.tile(np.arange(256.0) - 48.0, 14), 0.0)
_FRAC_DIGIT = (_NEXT == _FRAC * 256).astype(np.uint8)


def _numbers(buf, s, e, stop) -> tuple[np.ndarray, np.ndarray]:
    """``(values, ok)`` of a numeric column (cells ``s:e``, spaces then ``stop`` after
    them): ``ok`` where the row reader takes the cell, its value exactly ``float`` of
    the cell (see the module doc)."""
    n = len(s)
    vals = np.zeros(n)
    state = np.zeros(n, dtype=np.intp)
    for a in range(0, n, _BLOCK):
        b = min(a + _BLOCK, n)
        vals[a:b], state[a:b] = _number_block(buf, s[a:b], int((stop[a:b] - s[a:b]).max()))
    ok = state == _DONE * 256
    slow = np.flatnonzero((state == _DONE_E * 256) | (ok & np.isnan(vals)))
    for i in slow.tolist():  # an exponent, or more digits than a double holds
        v = float(buf[s[i] : e[i]].tobytes())
        vals[i], ok[i] = v, math.isfinite(v)
    return vals, ok


def _number_block(buf, s, width):
    """Values and final states of one block of cells (NaN: not exact here)."""
    n = len(s)
    state = np.zeros(n, dtype=np.intp)
    idx = np.empty(n, dtype=np.intp)
    m = np.zeros(n)
    frac = np.zeros(n, dtype=np.uint8)
    for byte in np.ascontiguousarray(_windows(buf, s, min(width, _MAX_NUMBER) + 1).T):
        np.add(state, byte, out=idx)
        _NEXT.take(idx, out=state)
        m *= _MUL.take(idx)
        m += _ADD.take(idx)
        frac += _FRAC_DIGIT.take(idx)
    exact = (m < _TWO53) & (frac <= 22)
    val = m / _POW10[np.minimum(frac, 22)]
    val = np.where(buf[s] == 45, -val, val)
    return np.where(exact, val, np.nan), state


def _windows(buf: np.ndarray, s: np.ndarray, width: int) -> np.ndarray:
    """``(n, width)``: the ``width`` bytes from each offset in ``s`` (a copy)."""
    return as_strided(buf, (len(buf) - width + 1, width), (1, 1), writeable=False)[s]
