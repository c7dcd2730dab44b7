"""The report as PDF (matplotlib `PdfPages`, A4 landscape: text pages for the
tables, one page per figure)."""

from __future__ import annotations

import io

from ._figures import RC
from ._report_model import _Fig, _is_num, _Para, _Pre, _Table
from ._report_sections import _sections
from ._text_pages import text_pages

__all__ = ["report_pdf"]


def _table_lines(t: _Table) -> list[str]:
    import textwrap

    headers = t.short or t.headers
    w = [len(h) for h in headers]
    for row in t.rows:
        w = [max(a, len(c)) for a, c in zip(w, row, strict=False)]
    w = [min(x, 66) for x in w]

    def fmt(cells):
        out = []
        for c, x in zip(cells, w, strict=False):
            c = c if len(c) <= x else c[: x - 1] + "…"
            out.append(c.rjust(x) if _is_num(c) else c.ljust(x))
        return "  ".join(out).rstrip()

    lines = textwrap.wrap(t.caption, 160) if t.caption else []
    lines += [fmt(headers), "  ".join("-" * x for x in w)]
    lines += [fmt(r) for r in t.rows]
    return lines


def _block_lines(b) -> list[str]:
    import textwrap

    if isinstance(b, _Para):
        prefix = "! " if b.kind == "warn" else ""
        return textwrap.wrap(prefix + b.text, 160) + [""]
    if isinstance(b, _Table):
        return _table_lines(b) + [""]
    if isinstance(b, _Pre):
        return ([b.caption + ":"] if b.caption else []) + list(b.lines) + [""]
    return []


def _pdf_pages(res, sections, on_figure=None):
    """Yield the PDF's pages as Figures (and call `on_figure(name, fig)` for figures)."""
    footer = f"piecs_bayes report · {res.study.name} · part {res.part or '–'} · {res.created}"
    for k, (sid, t, blocks) in enumerate(sections, start=1):
        head = f"{k}. {t}"
        lines: list[str] = []
        for b in blocks:
            lines += _block_lines(b)
        if lines:
            sub = f"{res.study.name}, part {res.part or '–'}" if sid == "summary" else ""
            yield from text_pages(head, lines, subtitle=sub, footer=footer)
        for b in blocks:
            if isinstance(b, _Fig):
                fig = b.make()
                if on_figure is not None:
                    on_figure(b.name, fig)
                old = fig.get_suptitle()
                fig.suptitle(f"{head}\n{old}" if old else head, fontsize=11)
                yield fig


def _pdf(pages, res) -> bytes:
    from matplotlib.backends.backend_pdf import PdfPages

    buf = io.BytesIO()
    meta = {
        "Title": f"piecs_bayes report: {res.study.name}",
        "Author": "piecs_bayes",
        "Subject": f"part {res.part}",
        "Creator": f"piecs_bayes {res.versions.get('piecs_bayes', '')}",
    }
    with PdfPages(buf, metadata=meta) as pdf:
        for fig in pages:
            pdf.savefig(fig)
    return buf.getvalue()


def report_pdf(res) -> bytes:
    """The report as PDF bytes (A4 landscape; text pages for tables, one page per figure)."""
    from matplotlib import rc_context

    with rc_context(RC):
        return _pdf(_pdf_pages(res, _sections(res)), res)
