"""The PDF report's page layout: text, tables and figures flowed onto A4 landscape
pages, drawn with matplotlib alone (no HTML engine, no system libraries).

A [`Flow`][] keeps a cursor on the current page; each block is cut into pieces that
fit (lines of a paragraph, rows of a table with its header repeated, a figure scaled
to the room left) so that a page is filled before the next begins and sections
follow each other on the same page. A figure that does not fit floats: the text goes
on, and the figure heads the next page (figures keep their order). Pages are lists
of draw operations in inches from the page's top-left corner; [`render_pages`][]
turns them into Figures with a footer ("page i of n"). Text widths are measured with
the fonts matplotlib embeds (`TextToPath`), so wrapped lines and table columns fit.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

PAGE_W, PAGE_H = 11.69, 8.27  # A4 landscape, inches
LEFT, RIGHT, TOP, BOTTOM = 0.6, 0.6, 0.45, 0.55
WIDTH = PAGE_W - LEFT - RIGHT
END = PAGE_H - BOTTOM  # the content ends here (inches from the top)

#: font sizes (points) and line height per point of size
BODY, SMALL, CELL, MONO, HEAD, TITLE = 8.6, 7.6, 7.3, 6.8, 12.5, 16.0
LEAD = 1.28
PT = 1.0 / 72.0


def _props(size: float, bold: bool, mono: bool):
    """The font a width is measured in: the one `PageInk` draws (`_font`)."""
    return _font(size, "bold" if bold else "normal", "normal", "monospace" if mono else None)


@functools.lru_cache(maxsize=65536)
def _word_pt(word: str, size: float, bold: bool, mono: bool) -> float:
    from matplotlib.textpath import TextToPath

    if not word:
        return 0.0
    w, _, _ = TextToPath().get_text_width_height_descent(
        word, _props(size, bold, mono), ismath=False
    )
    return float(w)


def _space_pt(size: float, bold: bool, mono: bool) -> float:
    return _word_pt("a a", size, bold, mono) - 2 * _word_pt("a", size, bold, mono)


def _words_pt(words: list[str], size: float, bold: bool, mono: bool) -> float:
    return sum(_word_pt(w, size, bold, mono) for w in words)


def text_width(text: str, size: float, *, bold=False, mono=False) -> float:
    """Width of `text` in inches (words measured, kerning between them ignored)."""
    words = text.split(" ")
    total = _words_pt(words, size, bold, mono) + _space_pt(size, bold, mono) * (len(words) - 1)
    return 1.03 * total * PT


def _break_word(word: str, width: float, size, bold, mono) -> list[str]:
    out, cur = [], ""
    for ch in word:
        if cur and text_width(cur + ch, size, bold=bold, mono=mono) > width:
            out.append(cur)
            cur = ""
        cur += ch
    return out + [cur]


class _Line:
    """A line being filled: its text and `text_width`'s sums, kept as words are added
    (the same sums in the same order: a column as wide as its widest cell still
    holds that cell)."""

    def __init__(self, text: str, size, bold, mono):
        self.key = (size, bold, mono)
        words = text.split(" ")
        self.text, self.words, self.n = text, _words_pt(words, *self.key), len(words)

    def width_with(self, word_pt: float) -> float:
        space = _space_pt(*self.key)
        return 1.03 * ((self.words + word_pt) + space * self.n) * PT

    def add(self, word: str, word_pt: float) -> None:
        self.text, self.words, self.n = f"{self.text} {word}", self.words + word_pt, self.n + 1

    @property
    def width(self) -> float:
        return 1.03 * (self.words + _space_pt(*self.key) * (self.n - 1)) * PT


def wrap(text: str, width: float, size: float, *, bold=False, mono=False, indent="") -> list[str]:
    """`text` wrapped greedily into lines of at most `width` inches (explicit newlines
    kept; continuation lines start with `indent`). A line's width is kept as it grows
    (`_Line`), not measured again for every word."""
    lines: list[str] = []
    for para in text.split("\n"):
        cur = None
        for word in para.split(" "):
            word_pt = _word_pt(word, size, bold, mono)
            if cur is None or not cur.text:
                cur = _Line(word, size, bold, mono)
            elif cur.width_with(word_pt) <= width:
                cur.add(word, word_pt)
            else:
                lines.append(cur.text)
                cur = _Line(indent + word, size, bold, mono)
            if cur.width > width:
                parts = _break_word(cur.text, width, size, bold, mono)
                lines += parts[:-1]
                cur = _Line(parts[-1], size, bold, mono)
        lines.append(cur.text if cur is not None else "")
    return lines


Draw = Callable[[object, float], None]  # (the page's `PageInk`, y of the piece's top, inches)


class Flow:
    """Pieces placed top to bottom on pages; a piece that does not fit starts a page."""

    def __init__(self):
        self.pages: list[list[tuple[float, Draw]]] = [[]]
        self.y = TOP
        self.floats: list = []  # figures waiting for the top of the next page
        self._flushing = False

    @property
    def room(self) -> float:
        return END - self.y

    @property
    def at_top(self) -> bool:
        return not self.pages[-1]

    def new_page(self) -> None:
        """Start a page; figures that waited for it go first."""
        if self.pages[-1]:
            self.pages.append([])
        self.y = TOP
        if not self._flushing:
            self._flushing = True
            while self.floats and self.floats[0].fits(self):
                self.floats.pop(0).place(self)
            self._flushing = False

    def flush(self) -> None:
        """Place every waiting figure (the document's end)."""
        while self.floats:
            piece = self.floats.pop(0)
            if not piece.fits(self):
                self.new_page()
            piece.place(self)

    def ensure(self, height: float) -> None:
        """Start a page unless `height` inches are left on this one (again when the
        figures that waited for the new page leave too little)."""
        while height > self.room and not self.at_top:
            self.new_page()

    def place(self, height: float, draw: Draw) -> None:
        self.ensure(height)
        self.pages[-1].append((self.y, draw))
        self.y += height

    def skip(self, height: float) -> None:
        """Vertical space (dropped at the top of a page)."""
        if not self.at_top:
            self.y = min(self.y + height, END)


def text_op(lines: list[str], size: float, **kw) -> tuple[float, Draw]:
    """Lines of text as one piece: `(height, draw)`; `kw` go to `Page.text` (`x`, `ha`,
    `color`, `weight`, `style`, `family`)."""
    height = len(lines) * size * LEAD * PT

    def draw(page, y):
        page.text(lines, size, y, **kw)

    return height, draw


def box_op(x: float, w: float, h: float, colour: str, edge: str | None = None) -> Draw:
    """A filled rectangle (a table cell, a highlighted paragraph) at the piece's top."""

    def draw(page, y):
        page.box(x, y, w, h, colour, edge or colour)

    return draw


def _page_ink_class():
    """`PageInk`, made on first use: matplotlib is imported by the report only."""
    from matplotlib.artist import Artist
    from matplotlib.colors import to_rgba
    from matplotlib.path import Path
    from matplotlib.transforms import Affine2D

    class PageInk(Artist):
        """The text and boxes of one page, drawn straight to the renderer in one
        artist. A `Text` and a `Rectangle` per table cell (1,100 artists for the demo)
        spent more time in matplotlib's per-artist work (properties, layout measured
        for alignment, the draw's bookkeeping) than in writing their glyphs; this
        draws the same glyphs with the same renderer calls: lines laid out as
        `Text` lays out a left- or right-aligned block under its top (the font's "lp"
        height, `LEAD` line spacing). Boxes are drawn first, then text (as their
        z-orders did)."""

        zorder = 3

        def __init__(self):
            super().__init__()
            self._boxes: list[tuple] = []
            self._texts: list[tuple] = []

        def text(self, lines, size, top, *, x=LEFT, ha="left", color="k", weight="normal",
                 style="normal", family=None, baseline=False):  # fmt: skip
            """`lines` at `size` points, the block's top `top` inches below the page's
            top (`baseline`: the first line's baseline there), from `x` inches (its
            right end when `ha="right"`)."""
            self._texts.append((list(lines), size, top, x, ha, color, weight, style,
                                family, baseline))  # fmt: skip

        def box(self, x, top, w, h, face, edge):
            """A `w` x `h` inch rectangle, its top-left corner at (`x`, `top`)."""
            self._boxes.append((x, top, w, h, face, edge))

        def draw(self, renderer):
            if not self.get_visible():
                return
            to_px = self.get_figure(root=True).dpi_scale_trans
            gc = renderer.new_gc()
            gc.set_linewidth(0.4)
            gc.set_joinstyle("miter")
            gc.set_capstyle("butt")
            unit = Path.unit_rectangle()
            for x, top, w, h, face, edge in self._boxes:
                where = Affine2D().scale(w, h).translate(x, PAGE_H - top - h) + to_px
                gc.set_foreground(edge)
                renderer.draw_path(gc, unit, where, to_rgba(face))
            metrics: dict = {}
            core = _pdf_core_fonts(renderer)
            try:
                for lines, size, top, x, ha, color, weight, style, family, base in self._texts:
                    prop = _font(size, weight, style, family)
                    if prop not in metrics:
                        core.use(False)  # the line grid of the font the layout measured
                        metrics[prop] = _line_metrics(renderer, prop)
                    first, step = metrics[prop]
                    px, py = to_px.transform((x, PAGE_H - top))
                    y = py if base else py - first
                    gc.set_foreground(color)
                    for line in lines:
                        drawn = core.font(line, prop, (size, weight, style, family))
                        lx = px
                        if ha == "right":
                            lx -= renderer.get_text_width_height_descent(line, drawn, False)[0]
                        if line:
                            renderer.draw_text(gc, lx, y, line, drawn, 0.0)
                        y -= step
            finally:
                core.restore()
            gc.restore()
            self.stale = False

    return PageInk


class _CoreFonts:
    """The PDF's standard fonts (Helvetica, Courier: in every reader, nothing embedded)
    for the lines they can show, the report's TrueType font for the others. matplotlib
    writes a standard-font line as one string; a TrueType line glyph by glyph through
    its text layout, ~1 ms a line (1,037 lines in the demo's report: 0.6 s of its
    ~5 s). Lines are measured (a right-aligned line's width) in the font they are
    drawn in; widths laid out with the TrueType font (`text_width`) leave the
    narrower Helvetica room. Only for the PDF renderer (`pdf` True): another draws
    every line in the TrueType font."""

    #: the standard font of each family `_font` is given (None: the sans-serif body)
    FAMILIES = {None: "Helvetica", "monospace": "Courier"}

    def __init__(self, pdf: bool):
        from matplotlib import rcParams

        self.pdf, self.rc = pdf, rcParams
        self.saved = rcParams["pdf.use14corefonts"]
        self.on = None

    def use(self, on: bool) -> None:
        if self.pdf and on is not self.on:
            self.rc["pdf.use14corefonts"] = self.on = on

    def font(self, line: str, prop, spec):
        """The font `line` is drawn in (and the renderer set for it): `prop`, made by
        `_font(*spec)`, or its standard font."""
        size, weight, style, family = spec
        ok = self.pdf and family in self.FAMILIES and _cp1252(line)
        self.use(ok)
        if not ok:
            return prop
        # the standard fonts' regular weight is "Medium": asked as such, found as such
        return _font(size, "medium" if weight == "normal" else weight, style,
                     self.FAMILIES[family])  # fmt: skip

    def restore(self) -> None:
        if self.pdf:
            self.rc["pdf.use14corefonts"] = self.saved


def _pdf_core_fonts(renderer) -> _CoreFonts:
    from matplotlib.backends.backend_pdf import RendererPdf

    return _CoreFonts(isinstance(getattr(renderer, "_vector_renderer", renderer), RendererPdf))


@functools.lru_cache(maxsize=4096)
def _cp1252(line: str) -> bool:
    """Whether the standard fonts show `line` (their encoding, WinAnsi, holds it)."""
    try:
        line.encode("cp1252")
    except UnicodeEncodeError:
        return False
    return True


def _line_metrics(renderer, prop) -> tuple[float, float]:
    """`(first, step)` in the renderer's pixels: the first baseline's depth below a
    block's top and the baseline-to-baseline step, as `Text` spaces lines at
    `linespacing=LEAD` (its line height `LEAD` x the font's ascender + descender,
    the leading shared above and below), for a line of the font's "lp" height: every
    line of a block on one baseline grid, whatever its glyphs."""
    from matplotlib.font_manager import findfont, get_font

    font = get_font(findfont(prop))
    os2 = font.get_sfnt_table("OS/2")
    em = font.get_sfnt_table("head")["unitsPerEm"]
    if os2 is not None:
        ascent, descent = os2["sTypoAscender"], -os2["sTypoDescender"]
    else:
        hhea = font.get_sfnt_table("hhea")
        ascent, descent = hhea["ascent"], -hhea["descent"]
    step = renderer.points_to_pixels(LEAD * (ascent + descent) / em * prop.get_size_in_points())
    _, h, d = renderer.get_text_width_height_descent("lp", prop, False)
    return (h - d) + (step - h) / 2, step


@functools.lru_cache(maxsize=64)
def _font(size: float, weight: str, style: str, family):
    from matplotlib.font_manager import FontProperties

    return FontProperties(size=size, weight=weight, style=style, family=family)


def render_pages(pages, footer: str):
    """Yield one Figure per page: its pieces drawn (on one `PageInk`), then the footer
    and page number."""
    from matplotlib.figure import Figure

    ink_class = _page_ink_class()
    n = len(pages)
    for i, page in enumerate(pages, start=1):
        fig = Figure(figsize=(PAGE_W, PAGE_H))
        fig.set_layout_engine("none")
        ink = ink_class()
        fig.add_artist(ink)
        for y, draw in page:
            draw(ink, y)
        foot = {"color": "0.4", "baseline": True}
        ink.text([footer], 7, PAGE_H - 0.28, **foot)
        ink.text([f"page {i} of {n}"], 7, PAGE_H - 0.28, x=PAGE_W - RIGHT, ha="right", **foot)
        yield fig
