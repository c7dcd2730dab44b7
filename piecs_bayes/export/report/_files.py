"""The job report: a [`JobResults`][piecs_bayes.jobs.JobResults] as one
self-contained HTML file and as a PDF.

Both are pure writers (`results -> str` / `results -> bytes`): they read the
bundle and never re-fit. The content is built once as a list of sections, each
a list of blocks (paragraphs, tables with pass/fail colours, lists, preformatted
text, figures), and rendered twice: to HTML (figures embedded as base64 PNG, no
external resource) and to PDF (matplotlib only, A4 landscape: text, tables and
figures flowed onto pages, `_pdf_flow`, `_pdf_blocks`). Sections, in order
(`SECTIONS`): the verdict (one page a quality manager can sign), decisions per
feature, profile and adjusted tool path, residuals, posterior diagnostics,
uncertainty budget, capability, adjusted part program, error specification and
tool offsets, inputs. Every length is stated as drawn (on the diameter for a
diameter, on Z for a face, along the normal for tapers and arcs), in µm for
deviations.

A section whose step was not run or could not be done is kept, with the reason.

Modules: `_report_model` (blocks), `_report_sections` (the sections, built in
`_report_verdict`, `_report_summary`, `_report_fit`, `_report_capability`,
`_report_machine`), `_report_html` and `_report_pdf` (the renderers); this one
draws both at once.
"""

from __future__ import annotations

from ..figures import RC
from ._html import html_report_text, png_bytes
from ._pdf import pdf_pages, pdf_report_bytes
from ._sections import report_sections


def report_files(res) -> tuple[str, bytes]:
    """`(html, pdf)` with every figure drawn once (what the CLI writes)."""
    from matplotlib import rc_context

    png: dict[str, bytes] = {}
    with rc_context(RC):
        sections = report_sections(res)

        def keep(name, fig):
            png[name] = png_bytes(fig)

        pdf = pdf_report_bytes(pdf_pages(res, sections, on_figure=keep), res)
        text = html_report_text(res, sections, png)
    return text, pdf
