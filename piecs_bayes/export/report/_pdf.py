"""The report as PDF: A4 landscape pages drawn with matplotlib (`_pdf_flow`). The
verdict fills the first page; then the sections follow each other, text, tables
(with pass/fail colours) and figures flowed so that no page is left nearly empty."""

from __future__ import annotations

import io
import itertools
from collections.abc import Callable

from ..figures import RC
from ..raster import Rasteriser
from ._pdf_blocks import FIGURE_DPI, FigurePiece, keep_height, place_block, place_heading
from ._pdf_flow import BODY, TITLE, Flow, render_pages, text_op
from ._sections import report_sections
from .model import Fig, PageBreak


def _place_section(flow: Flow, head: str, blocks, figs: Callable, numbers) -> None:
    """A section: its heading, then its blocks; a figure that does not fit the page
    (or comes after one that waits) floats to the top of the next page. Each figure
    is made here and handed to `figs(name, figure)`, which returns its drawing:
    placing it needs its size only, its pixels are read when its page is drawn."""
    figures = {}
    for i, b in enumerate(blocks):
        if isinstance(b, Fig):
            fig = b.make()
            n = next(numbers)
            caption = f"Figure {n} (section {head}). {b.caption}"
            figures[i] = FigurePiece(fig.get_size_inches(), caption, full=b.full, shrink=b.shrink)
            figures[i].drawing = figs(b.name, fig)
    text = [i for i, b in enumerate(blocks) if i not in figures and not isinstance(b, PageBreak)]
    keep = keep_height(blocks[text[0]]) if text else 1.0
    if figures and min(figures) < (text[0] if text else len(blocks)):
        keep = min(keep, figures[min(figures)].smallest)  # a figure first: it may float
    place_heading(flow, head, keep)
    for i, b in enumerate(blocks):
        if isinstance(b, PageBreak):
            flow.new_page()
        elif i in figures:
            if flow.floats or not figures[i].fits(flow):
                flow.floats.append(figures[i])
            else:
                figures[i].place(flow)
        else:
            place_block(flow, b)


def _layout(res, sections, on_figure=None) -> Flow:
    """Every section's blocks placed on pages. Each figure is queued for drawing as
    it is made, once, for the PDF and (`on_figure(name, drawing)`) the HTML: the
    helper process draws the newest while this process goes on, and the pages, drawn
    in order, draw here any figure the helper has not started (`export.raster`)."""
    from matplotlib import rcParams

    raster = Rasteriser(rcParams, FIGURE_DPI)  # the report's style (`RC`), as made

    def figs(name, fig):
        drawing = raster.draw(fig)
        if on_figure is not None:
            on_figure(name, drawing)
        return drawing

    flow = Flow()
    h, title = text_op([f"piecs_bayes report: {res.study.name}"], TITLE, weight="bold")
    flow.place(h + 0.04, title)
    h, sub = text_op(
        [f"part {res.part or '–'} · {res.created} · lengths in mm, deviations in µm"],
        BODY,
        color="0.35",
    )
    flow.place(h + 0.05, sub)
    numbers = itertools.count(1)
    for k, (_, t, blocks) in enumerate(sections, start=1):
        _place_section(flow, f"{k}. {t}", blocks, figs, numbers)
    flow.flush()
    return flow


def pdf_pages(res, sections, on_figure=None):
    """Yield the PDF's pages as Figures (and call `on_figure(name, drawing)` for
    figures: `drawing.png()` is its PNG)."""
    flow = _layout(res, sections, on_figure)
    footer = f"piecs_bayes report · {res.study.name} · part {res.part or '–'} · {res.created}"
    yield from render_pages(flow.pages, footer)


#: the report's TrueType fonts as Type 3 (matplotlib draws the glyphs used), each with
#: its ToUnicode map, so that its text is searched and extracted as with TrueType (Type
#: 42): fontTools subsetting seven TrueType fonts took 1.3-1.8 s of a 9 s report. Most
#: lines are in the standard fonts instead (`_pdf_flow._CoreFonts`); the figures' text
#: is in their images
REPORT_PDF_RC = {"pdf.fonttype": 3}


def pdf_report_bytes(pages, res) -> bytes:
    from matplotlib import rc_context
    from matplotlib.backends.backend_pdf import PdfPages

    buf = io.BytesIO()
    meta = {
        "Title": f"piecs_bayes report: {res.study.name}",
        "Author": "piecs_bayes",
        "Subject": f"part {res.part}",
        "Creator": f"piecs_bayes {res.versions.get('piecs_bayes', '')}",
    }
    with rc_context(REPORT_PDF_RC), PdfPages(buf, metadata=meta) as pdf:
        for fig in pages:
            pdf.savefig(fig)
    return buf.getvalue()


def report_pdf(res) -> bytes:
    """The report as PDF bytes (A4 landscape; the verdict first)."""
    from matplotlib import rc_context

    with rc_context(RC):
        return pdf_report_bytes(pdf_pages(res, report_sections(res)), res)
