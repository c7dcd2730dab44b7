"""The report's blocks placed on the PDF's pages (`_pdf_flow`): headings, paragraphs,
lists, tables with pass/fail colours, preformatted text, figures."""

from __future__ import annotations

import io

from ._pdf_flow import (
    BODY,
    CELL,
    END,
    HEAD,
    LEAD,
    LEFT,
    MONO,
    PAGE_H,
    PT,
    SMALL,
    TOP,
    WIDTH,
    Flow,
    box_op,
    text_op,
    text_width,
    wrap,
)
from .model import CLASS_COLOURS, Bullets, Para, Pre, Table, Tables, is_num

_PARA_STYLE = {
    "p": {},
    "note": {"color": "0.3"},
    "warn": {"color": "#9b1c1c"},
    "fail": {"color": "#7a0000", "weight": "bold"},
    "pass": {"color": "#0b5d1e", "weight": "bold"},
    "sign": {},
}
_PARA_BOX = {"fail": CLASS_COLOURS["does-not-conform"], "pass": CLASS_COLOURS["conforms"],
             "warn": "#fdecec"}  # fmt: skip
_GAP = 0.07  # inches after a paragraph, list or table


def _line_h(size: float) -> float:
    return size * LEAD * PT


def place_heading(flow: Flow, text: str, keep: float = 1.0) -> None:
    """A section heading, kept with `keep` inches of what follows."""
    flow.skip(0.14)
    h, draw = text_op([text], HEAD, weight="bold")
    flow.ensure(h + keep)
    flow.place(h + 0.06, draw)


def _place_lines(flow: Flow, lines, size, *, x=LEFT, box=None, **kw) -> None:
    """Lines of text, cut where a page ends."""
    i = 0
    while i < len(lines):
        fit = max(1, int((flow.room + 1e-9) // _line_h(size)))
        if flow.room < _line_h(size) and not flow.at_top:
            flow.new_page()
            continue
        chunk = lines[i : i + fit]
        h, draw = text_op(chunk, size, x=x, **kw)
        if box is not None:
            pad = 0.04
            back = box_op(LEFT - pad, WIDTH + 2 * pad, h + 2 * pad / 3, box)
            flow.place(h, lambda fig, y, d=draw, b=back: (b(fig, y - 0.02), d(fig, y)))
        else:
            flow.place(h, draw)
        i += len(chunk)


def _place_para(flow: Flow, p: Para) -> None:
    size = BODY + (0.6 if p.kind in ("pass", "fail") else 0.0)
    bold = p.kind in ("pass", "fail")
    if p.kind == "sign":
        flow.skip(0.35)
    lines = wrap(p.text, WIDTH, size, bold=bold)
    _place_lines(flow, lines, size, box=_PARA_BOX.get(p.kind), **_PARA_STYLE.get(p.kind, {}))
    flow.skip(_GAP + (0.04 if p.kind in _PARA_BOX else 0.0))


def _place_bullets(flow: Flow, b: Bullets) -> None:
    h, draw = text_op([b.title], BODY, weight="bold")
    colour = CLASS_COLOURS.get(b.kind)
    flow.ensure(h + 2 * _line_h(BODY))
    if colour:
        back = box_op(LEFT - 0.03, text_width(b.title, BODY, bold=True) + 0.08, h, colour)
        flow.place(h, lambda fig, y: (back(fig, y - 0.01), draw(fig, y)))
    else:
        flow.place(h, draw)
    for item in b.items:
        lines = wrap(item, WIDTH - 0.2, BODY - 0.4)
        flow.ensure(_line_h(BODY - 0.4))
        _, bullet = text_op(["•"], BODY - 0.4, x=LEFT + 0.06)
        flow.pages[-1].append((flow.y, bullet))
        _place_lines(flow, lines, BODY - 0.4, x=LEFT + 0.2)
    flow.skip(_GAP)


def _place_pre(flow: Flow, p: Pre) -> None:
    if not p.pdf:
        _place_para(flow, Para(f"{p.caption or 'This text'}: in the HTML report.", "note"))
        return
    if p.caption:
        cap = wrap(p.caption + ":", WIDTH, BODY, bold=True)
        flow.ensure(len(cap) * _line_h(BODY) + 2 * _line_h(MONO))
        _place_lines(flow, cap, BODY, weight="bold")
    lines: list[tuple[str, str]] = []
    for line in p.lines:
        colour = "0.1"
        if p.diff and line.startswith("+") and not line.startswith("+++"):
            colour = "#0a6b0a"
        elif p.diff and line.startswith("-") and not line.startswith("---"):
            colour = "#a00000"
        for part in wrap(line.expandtabs(4), WIDTH, MONO, mono=True, indent="    "):
            lines.append((part, colour))
    lh = _line_h(MONO)
    for text, colour in lines:
        h, draw = text_op([text or " "], MONO, family="monospace", color=colour)
        flow.place(lh, draw)
    flow.skip(_GAP)


# --------------------------------------------------------------------------- tables

_PAD = 0.045  # inches of padding in a table cell (horizontal; 70 % of it vertical)


def _widths(headers, rows, size: float, room: float) -> list[float]:
    """Column widths (inches): the widest cell or header word, water-filled to `room`."""
    nat = []
    for j, h in enumerate(headers):
        cell = max((text_width(r[j], size) for r in rows if j < len(r)), default=0.0)
        word = max(text_width(w, size, bold=True) for w in h.split(" "))
        head = text_width(h, size, bold=True) / 2  # a header on two lines at most, roughly
        nat.append(max(cell, word, min(head, 1.1), 0.25) + 2 * _PAD)
    if sum(nat) <= room:
        return nat
    lo, hi = 0.3, max(nat)
    for _ in range(40):  # the cap at which the capped widths fill the room
        cap = (lo + hi) / 2
        lo, hi = (cap, hi) if sum(min(w, cap) for w in nat) < room else (lo, cap)
    return [min(w, lo) for w in nat]


class _TableLayout:
    """A table's columns, header and rows as pieces `(height, draw)` at `x0`."""

    def __init__(self, t: Table, x0: float = LEFT, room: float = WIDTH):
        self.size = CELL + (1.3 if t.emphasis else 0.0)
        self.x0 = x0
        n = len(t.headers)
        rows = [list(r) + [""] * (n - len(r)) for r in t.rows]
        self.widths = _widths(t.headers, rows, self.size, room)
        self.width = sum(self.widths)
        self.head = self._row(list(t.headers), ["#e6e6e6"] * n, bold=True)
        self.rows = []
        for k, row in enumerate(rows):
            row_cls = t.classes[k] if k < len(t.classes) else ""
            cls = t.cells[k] if t.cells is not None and k < len(t.cells) else [""] * n
            colours = [CLASS_COLOURS.get(c or row_cls, "") for c in cls]
            self.rows.append(self._row(row, colours, align=[is_num(c) for c in row]))
        self.caption = (
            wrap(t.caption, self.width if x0 > LEFT else WIDTH, SMALL) if t.caption else []
        )

    @property
    def height(self) -> float:
        cap = len(self.caption) * _line_h(SMALL) + 0.04 if self.caption else 0.0
        return self.head[0] + sum(h for h, _ in self.rows) + cap

    def _row(self, cells, colours, *, bold=False, align=None):
        size, widths = self.size, self.widths
        lines = [wrap(c, w - 2 * _PAD, size, bold=bold) for c, w in zip(cells, widths, strict=True)]
        h = max(len(x) for x in lines) * _line_h(size) + 1.4 * _PAD

        def draw(fig, y):
            x = self.x0
            for j, (w, text) in enumerate(zip(widths, lines, strict=True)):
                box_op(x, w, h, colours[j] or "white", "#b8b8b8")(fig, y)
                right = align is not None and align[j]
                _, op = text_op(
                    text,
                    size,
                    x=x + w - _PAD if right else x + _PAD,
                    weight="bold" if bold else "normal",
                    ha="right" if right else "left",
                )
                op(fig, y + 0.7 * _PAD)
                x += w

        return h, draw

    def caption_op(self):
        return text_op(self.caption, SMALL, x=self.x0, color="0.3", style="italic")


def _place_table(flow: Flow, t: Table) -> None:
    if t.title:
        _place_lines(flow, wrap(t.title, WIDTH, BODY, bold=True), BODY, weight="bold")
    lay = _TableLayout(t)
    head_h, head = lay.head
    heights = [h for h, _ in lay.rows]
    # a short table stays together; a long one leaves no header with one or two rows alone
    flow.ensure(head_h + sum(heights if len(heights) <= 10 else heights[:3]))
    flow.place(head_h, head)
    here = 0  # rows on this page
    for k, (h, op) in enumerate(lay.rows):
        last_alone = k == len(heights) - 2 and h + heights[-1] > flow.room and here >= 3
        if h > flow.room or last_alone:  # no last row alone on the next page
            flow.new_page()
            flow.place(head_h, head)
            here = 0
        flow.place(h, op)
        here += 1
    if lay.caption:
        flow.skip(0.04)
        _place_lines(flow, lay.caption, SMALL, color="0.3", style="italic")
    flow.skip(_GAP + 0.04)


def _place_tables(flow: Flow, tables: list[Table]) -> None:
    """Small tables side by side (one after the other when they do not fit)."""
    gap = 0.3
    lays, x = [], LEFT
    for t in tables:
        lay = _TableLayout(t, x0=x)
        lays.append(lay)
        x += lay.width + gap
    if x - gap > LEFT + WIDTH:
        for t in tables:
            _place_table(flow, t)
        return
    height = max(lay.height for lay in lays)

    def draw(fig, y):
        for lay in lays:
            yy = y
            for h, op in [lay.head, *lay.rows]:
                op(fig, yy)
                yy += h
            if lay.caption:
                lay.caption_op()[1](fig, yy + 0.04)

    flow.place(height, draw)
    flow.skip(_GAP + 0.06)


# --------------------------------------------------------------------------- figures


#: the resolution of the report's figures, in the PDF and in the HTML alike (one
#: PNG each: drawing a figure costs more than the rest of its page)
FIGURE_DPI = 150.0


def _pixels(png: bytes):
    import numpy as np
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


class FigurePiece:
    """A figure (its size in inches; its pixels from `drawing`) scaled to the page
    width, at most `share` of the page's height (all of it when `full`), with its
    caption below. On a page with less room it shrinks down to `shrink` of that size
    (and at least 3 inches). Placing it needs the size only: `drawing` (a
    `raster.Drawing`, or PNG bytes) is read when the page is drawn."""

    def __init__(self, size_inches, caption: str, *, full=False, shrink=0.75):
        self.shrink = shrink
        self.drawing = None
        self.fw, self.fh = size_inches
        self.cap = wrap(caption, WIDTH, SMALL) if caption else []
        self.cap_h = len(self.cap) * _line_h(SMALL) + 0.06
        page = END - TOP - self.cap_h - 0.05
        self.h = min(WIDTH * self.fh / self.fw, page if full else 0.6 * page)

    @property
    def smallest(self) -> float:
        return min(self.h, max(self.shrink * self.h, 3.0)) + self.cap_h

    def fits(self, flow: Flow) -> bool:
        return flow.room >= self.smallest or flow.at_top

    def place(self, flow: Flow) -> None:
        h = self.h
        if flow.room < h + self.cap_h:
            if self.fits(flow):
                h = flow.room - self.cap_h
            else:
                flow.new_page()
        w = h * self.fw / self.fh
        x0 = LEFT + (WIDTH - w) / 2
        cap = self.cap

        def draw(page, y):
            f = page.get_figure(root=True)
            fw = f.get_figwidth()
            ax = f.add_axes((x0 / fw, (PAGE_H - y - h) / PAGE_H, w / fw, h / PAGE_H))
            png = self.drawing if isinstance(self.drawing, bytes) else self.drawing.png()
            ax.imshow(_pixels(png), interpolation="none", aspect="auto")
            ax.set_axis_off()
            if cap:
                _, op = text_op(cap, SMALL, color="0.25", style="italic")
                op(page, y + h + 0.05)

        flow.place(h + self.cap_h, draw)
        flow.skip(_GAP)


def keep_height(b) -> float:
    """The inches a heading keeps with block `b` (a short table whole, else a start)."""
    if isinstance(b, Table):
        lay = _TableLayout(b)
        rows = [h for h, _ in lay.rows]
        return lay.head[0] + sum(rows if len(rows) <= 10 else rows[:3])
    return 1.0


def place_block(flow: Flow, b) -> None:
    """A paragraph, list, table or preformatted block."""
    if isinstance(b, Para):
        _place_para(flow, b)
    elif isinstance(b, Bullets):
        _place_bullets(flow, b)
    elif isinstance(b, Table):
        _place_table(flow, b)
    elif isinstance(b, Tables):
        _place_tables(flow, b.tables)
    elif isinstance(b, Pre):
        _place_pre(flow, b)
    else:
        raise TypeError(f"unknown report block {b!r}")
