"""The job report: a [`JobResults`][piecs_bayes.jobs.JobResults] as one self-contained
HTML file and as a PDF, drawn at once.

[`report_files`][] returns `(html, pdf)` from one list of sections (`_sections`), every
figure drawn once, as one PNG for both renderers (`report_html` and `report_pdf` give one
each). It is a pure writer: it reads the bundle and never re-fits. A section whose step
was not run or could not be done is kept, with the reason; every length is stated as
drawn, deviations in µm.

The sections and their rendering: docs/models/report.md.
"""

from __future__ import annotations

from ..figures import RC
from ..raster import start_helper
from ._html import html_report_text
from ._pdf import pdf_pages, pdf_report_bytes
from ._sections import report_sections


def report_files(res) -> tuple[str, bytes]:
    """`(html, pdf)` with every figure drawn once (what the CLI writes)."""
    from matplotlib import rc_context

    start_helper()  # it loads while the sections are built

    drawings: dict = {}
    with rc_context(RC):
        sections = report_sections(res)
        pdf = pdf_report_bytes(pdf_pages(res, sections, on_figure=drawings.__setitem__), res)
        text = html_report_text(res, sections, {k: d.png() for k, d in drawings.items()})
    return text, pdf
