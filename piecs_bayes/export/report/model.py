"""The report's content model: blocks (paragraphs, tables, lists, preformatted text,
figures, page breaks) that the HTML and PDF renderers both draw, the colours of
their pass/fail classes, and the number formats the sections share."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class Para:
    text: str
    kind: str = "p"  # "p" | "note" | "warn"


@dataclass
class Table:
    headers: list[str]
    rows: list[list[str]]
    caption: str = ""
    classes: list[str] = field(default_factory=list)  # per row css class ("" for none)
    short: list[str] | None = None  # narrower headers for the PDF, where given
    cells: list[list[str]] | None = None  # per cell css class (pass/fail colour), "" none
    title: str = ""  # a heading above the table
    emphasis: bool = False  # larger type (the verdict page)


@dataclass
class Tables:
    """Small tables side by side."""

    tables: list[Table]


@dataclass
class Bullets:
    """A titled list (the reasons behind a verdict)."""

    title: str
    items: list[str]
    kind: str = ""  # css class of the title (a verdict)


@dataclass
class PageBreak:
    """The PDF starts a new page here (the HTML ignores it)."""


@dataclass
class Pre:
    lines: list[str]
    caption: str = ""
    diff: bool = False
    pdf: bool = True  # False: in the HTML only (the PDF says where it is)


@dataclass
class Fig:
    name: str
    make: Callable
    caption: str
    full: bool = False  # may fill a whole PDF page (else at most about 60 % of one)
    shrink: float = 0.75  # the PDF may draw it down to this share of its size to fit a page


def num(x, fmt="+.2f", scale=1e3) -> str:
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


def interval_text(iv, fmt=".2f") -> str:
    lo, hi = iv
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "–"
    return f"[{lo:{fmt}}, {hi:{fmt}}]"


def is_num(s: str) -> bool:
    s = s.replace("±", "").replace("[", "").replace("]", "").replace(",", " ").strip()
    try:
        [float(t) for t in s.split() if t not in ("–",)]
    except ValueError:
        return False
    return bool(s)


#: background colour of a table cell or row by class (HTML and PDF alike)
CLASS_COLOURS = {
    "conforms": "#d9f2d9",
    "does-not-conform": "#f8d0d0",
    "ambiguous": "#ffe9b3",
    "compensate": "#ffe6c7",
    "measure-more": "#dbe7ff",
    "do-not-compensate": "#eeeeee",
    "bad": "#f8d0d0",
    "ok": "#d9f2d9",
}


def css_class(text: str) -> str:
    """The class of a verdict or conformance state (`"does not conform"` ->
    `"does-not-conform"`)."""
    return text.split(" (")[0].strip().replace(" ", "-")


def micro(text: str) -> str:
    """`"1.75 um"` -> `"1.75 µm"`: one spelling of the micrometre in the report (texts
    made by other layers write the ASCII form)."""
    return re.sub(r"(\d)\s?um\b", r"\1 µm", text)
