"""Monospaced text as A4 landscape figure pages (the PDF report's tables and diffs)."""

from __future__ import annotations

from ._figures import _figure

__all__ = ["text_pages"]


def text_pages(
    title: str,
    lines,
    *,
    subtitle: str = "",
    footer: str = "",
    width: int = 165,
    lines_per_page: int = 50,
):
    """Monospaced text on A4 landscape pages (tables, diffs): a list of Figures.

    Lines longer than `width` characters wrap with an indent; `title` heads every
    page ("(continued)" after the first).
    """
    import textwrap

    wrapped: list[str] = []
    for line in lines:
        line = line.expandtabs(4).rstrip("\n")
        if len(line) <= width:
            wrapped.append(line)
        else:
            wrapped += textwrap.wrap(
                line, width, subsequent_indent="    ", break_long_words=True, drop_whitespace=False
            )
    pages = [wrapped[i : i + lines_per_page] for i in range(0, len(wrapped), lines_per_page)]
    pages = pages or [[]]
    figs = []
    for k, chunk in enumerate(pages):
        fig = _figure((11.69, 8.27))
        fig.set_layout_engine("none")
        fig.text(
            0.05,
            0.95,
            title + (" (continued)" if k else ""),
            fontsize=13,
            weight="bold",
            va="top",
        )
        if subtitle and not k:
            fig.text(0.05, 0.915, subtitle, fontsize=9, va="top", color="0.3")
        fig.text(
            0.05,
            0.885,
            "\n".join(chunk),
            family="monospace",
            fontsize=7.3,
            va="top",
            linespacing=1.3,
        )
        if footer:
            fig.text(0.05, 0.03, footer, fontsize=7.5, color="0.4")
        figs.append(fig)
    return figs
