"""The report's content model: blocks (paragraphs, tables, preformatted text,
figures) that the HTML and PDF renderers both draw, and the number formats the
sections share."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class _Para:
    text: str
    kind: str = "p"  # "p" | "note" | "warn"


@dataclass
class _Table:
    headers: list[str]
    rows: list[list[str]]
    caption: str = ""
    classes: list[str] = field(default_factory=list)  # per row css class ("" for none)
    short: list[str] | None = None  # headers of the PDF's narrower text tables


@dataclass
class _Pre:
    lines: list[str]
    caption: str = ""
    diff: bool = False


@dataclass
class _Fig:
    name: str
    make: Callable
    caption: str


def _f(x, fmt="+.2f", scale=1e3) -> str:
    """A number in display units, or an en dash when missing."""
    if x is None:
        return "–"
    try:
        x = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(x):
        return "–"
    return format(x * scale, fmt)


def _ci(iv, fmt=".2f") -> str:
    lo, hi = iv
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "–"
    return f"[{lo:{fmt}}, {hi:{fmt}}]"


def _is_num(s: str) -> bool:
    s = s.replace("±", "").replace("[", "").replace("]", "").replace(",", " ").strip()
    try:
        [float(t) for t in s.split() if t not in ("–",)]
    except ValueError:
        return False
    return bool(s)
